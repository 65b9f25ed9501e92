"""An unloading stiffness that saturates at a plastic limit (C++: effects/saturating_unloading.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="saturating_unloading", param="contact.plastic_stiffness_ratio", unit="-", lo=1.05, hi=50.0,
    probe=4.0, log=True, off=1.0, stage="compaction",
    description="unloading stiffness rises with plastic flattening to a limit k_p: "
                "k2 + (k_p - k2) min(delta0 / (0.2 r*), 1) (Luding)",
    signature="relaxed pellets spring back too much: simulated relaxed density and coordination "
              "number below the measured, more so at the higher pressure but less than in "
              "proportion once the contacts saturate; the loading branch is untouched",
    fixed={"contact.plastic_overlap": 0.2})
