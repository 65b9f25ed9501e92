"""A bond radius growing with the contact's flattening (C++: effects/overlap_bond_radius.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="overlap_bond_radius", param="bond.overlap_radius_gain", unit="-", lo=0.05, hi=100.0, probe=3.0,
    log=True, off=0.0, stage="diametral",
    description="bond radius grows with the contact's plastic flattening: r_b (1 + g delta0/r*)",
    signature="strength rises with compaction pressure faster than the model's: simulated "
              "sigma_f too high at low sigma_z and too low at high sigma_z (a trend across "
              "pressures, invisible within one pressure)")
