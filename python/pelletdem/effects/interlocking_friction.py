"""The made pellet's contacts resist sliding more (C++: effects/interlocking_friction.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="interlocking_friction", param="contact.interlocking_friction", unit="-", lo=1.05, hi=10.0,
    probe=2.0, log=True, off=1.0, stage="diametral",
    description="compaction interlocks the sawdust's flattened fibres: from the bonding on, contacts "
                "slide at F mu f_n",
    signature="the pellet both deforms too far and breaks too weak for its bonds: simulated dL_f/D "
              "above the measured and sigma_f below it with the bonds' own measurements, most in the "
              "loosest pellets (60 MPa), so the fitted bonds come out stiffer than Table 5's; "
              "density and CN untouched")
