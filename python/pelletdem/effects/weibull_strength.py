"""A Weibull spread of the bonds' strengths (C++: effects/weibull_strength.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="weibull_strength", param="bond.weibull_modulus", unit="-", lo=1.0, hi=30.0, probe=2.5, log=True,
    off=0.0, stage="diametral",
    description="bond strengths spread as a Weibull distribution of modulus m (mean kept)",
    signature="weak bonds break early: the rise bends over before the peak, the peak is lower "
              "and rounder, and the fall after it gentler; small m is a wide spread",
    stronger="lower")
