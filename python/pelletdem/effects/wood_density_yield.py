"""Wood-density-dependent yield: k1 scales as a power of the wood's bulk density (C++:
effects/wood_density_yield.hpp)."""
from .base import Effect

EFFECT = Effect(
    name="wood_density_yield", param="contact.wood_density_yield", unit="-", lo=0.1, hi=5.0, probe=1.5,
    log=True, off=0.0, stage="compaction",
    description="loading stiffness k1 (the particles' yield, eq. 7) scales as (BD_w / 680 kg/m^3)^n, "
                "BD_w the intact wood's bulk density (cellular solids: Gibson-Ashby)",
    signature="a trend of the relaxed solid fraction BD_p / BD_w with the wood's density at every "
              "pressure and moisture: the lighter woods' pellets denser than the model says, the "
              "heavier ones' looser; one wood alone shows nothing",
    needs="material")
