"""Contact hardening: the loading stiffness grows with overlap (C++: effects/hardening.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="hardening", param="contact.hardening", unit="-", lo=0.05, hi=200.0, probe=5.0, log=True,
    off=0.0, stage="compaction",
    description="loading stiffness grows with overlap: k1 (1 + h (delta/r*)^2)",
    signature="compaction curve too soft above dh/h0 ~ 0.75 (the paper's own residual): the "
              "simulated sigma_z falls below the measured at the end of compaction; relaxed "
              "density too high, the more so at the higher pressure",
    fixed={"contact.hardening_exponent": 2.0})
