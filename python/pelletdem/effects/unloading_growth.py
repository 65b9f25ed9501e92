"""An unloading stiffness that grows with plastic flattening (C++: effects/unloading_growth.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="unloading_growth", param="contact.unloading_growth", unit="-", lo=0.1, hi=500.0, probe=10.0,
    log=True, off=0.0, stage="compaction",
    description="unloading stiffness grows with plastic flattening: k2 (1 + g delta0/r*) (Luding)",
    signature="relaxed pellets spring back too much: simulated relaxed density (and coordination "
              "number) below the measured, more so at the higher pressure; the loading branch of "
              "the compaction curve is untouched")
