"""Bonds that soften before they break (C++: effects/bond_softening.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="bond_softening", param="bond.softening", unit="-", lo=0.05, hi=20.0, probe=1.5, log=True,
    off=0.0, stage="diametral",
    description="bonds soften before they break: capacity falls to zero at (1 + s) times the peak strain",
    signature="the curve keeps rising past the brittle model's peak: higher sigma_f at larger "
              "dL_f/D and a slow, ductile decline after the peak")
