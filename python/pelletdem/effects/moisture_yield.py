"""Moisture-dependent yield: k1 falls (or rises) with moisture content (C++:
effects/moisture_yield.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="moisture_yield", param="contact.moisture_yield", unit="1/%", lo=-0.1, hi=0.2, probe=0.03,
    log=False, off=0.0, stage="compaction",
    description="loading stiffness k1 (the particles' yield, eq. 7) scales as exp(-c (MC - 8 %))",
    signature="a trend of the relaxed density (and with it the strength) with moisture content at "
              "every pressure: wetter pellets denser than the model says (c > 0) or looser (c < 0); "
              "the compaction curve of the wetter pellets softer or stiffer from the start",
    needs="mc")
