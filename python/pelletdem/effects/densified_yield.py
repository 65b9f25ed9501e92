"""The made pellet's particles yield at a higher pressure (C++: effects/densified_yield.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="densified_yield", param="contact.densified_yield", unit="-", lo=1.05, hi=1.0e3, probe=10.0,
    log=True, off=1.0, stage="diametral",
    description="compaction densifies the porous sawdust: from the bonding on, contacts load along Y k1",
    signature="deformation at failure too large for the strength: simulated dL_f/D above the measured "
              "in every variant while sigma_f fits, so the fitted bonds come out stiffer than the "
              "bonds' own measurements (E_b several times Table 5's); density and CN untouched")
