"""Particles crushing under the diametral plates (C++: effects/plate_crushing.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="plate_crushing", param="contact.plate_yield_stress", unit="Pa", lo=2.0e4, hi=5.0e7, probe=3.0e5,
    log=True, off=0.0, stage="diametral",
    description="particles crush where the plates touch the pellet: plate contact force capped at p pi r^2",
    signature="toe of sigma_1(dL/D): simulated stress too high at small dL/D, the rise starts "
              "late in the data; failure at larger dL_f/D with nearly the same peak",
    stronger="lower")
