"""Bonds whose stiffness and strength depend on moisture (C++: effects/moisture_bonds.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="moisture_bonds", param="bond.moisture_coefficient", unit="1/%", lo=-0.2, hi=0.2, probe=0.03,
    log=False, off=0.0, stage="diametral",
    description="bond stiffness and strength scale as exp(-c (MC - 8 %))",
    signature="a trend of the strength residual with moisture content (wetter pellets weaker or "
              "stronger than the model says), the same at every pressure",
    needs="mc")
