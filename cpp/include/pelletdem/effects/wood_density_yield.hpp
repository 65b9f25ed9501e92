#pragma once
// Wood-density-dependent yield: the loading (plastic) stiffness k1, which eq. 7 ties to the
// particles' yield strength (k1 = 5 r* p_y), times (rho_w / rho_ref)^n, rho_w the bulk density
// of the intact wood the sawdust is cut from (Table 2's BD_w). Wood is a cellular solid: its
// cell walls collapse plastically at a stress that grows as a power of its relative density
// (Gibson and Ashby: n = 1.5 for open cells, about 2 across woods), so sawdust of a lighter
// wood flattens further under one pressure. The unloading stiffness k2 is unchanged; a
// loading line made steeper than k2 is followed at k2 (eq. 5's first case). The relaxed
// solid fraction BD_p / BD_w then falls with the wood's density at every pressure.
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_WoodDensityYield(X)                                                                \
  X(double, wood_density_yield, 0.0, Range, -10.0, 10.0, "-", "wood_density_yield", true,                 \
    "n in k1 (rho_w / rho_ref)^n on the loading branch (rho_w, rho_ref: wood_density, "                   \
    "wood_density_reference); 0 off")                                                                     \
  X(double, wood_density, 680.0, Range, 50.0, 1500.0, "kg/m^3", "wood_density", true,                     \
    "bulk density BD_w of the intact wood the particles are cut from (the condition's material, "         \
    "Table 2); only wood_density_yield reads it")                                                         \
  X(double, wood_density_reference, 680.0, Range, 50.0, 1500.0, "kg/m^3", "wood_density_reference", true, \
    "BD_w at which k1 holds: Table 4's particle density (oak)")

namespace pelletdem {

struct WoodDensityYield : ContactEffect {
  template <class P>
  static bool reads_wood_density(const P& p) {
    return p.wood_density_yield != 0.0;
  }
  // A factor on k1, made once per law, like moisture_yield's.
  template <class P>
  static double loading_stiffness_factor(const P& p) {
    if (p.wood_density_yield == 0.0) return 1.0;
    return std::pow(p.wood_density / p.wood_density_reference, p.wood_density_yield);
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(WoodDensityYield)
