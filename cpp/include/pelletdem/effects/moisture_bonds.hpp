#pragma once
// Moisture-dependent bonds: E_b, sigma_c and tau_c times exp(-c (MC - MC_ref)), a trend of the
// strength with moisture content, the same at every pressure.
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_MoistureBonds(X)                                                            \
  X(double, moisture_content, 8.0, Range, 0.0, 100.0, "%", "bond moisture_content", true,          \
    "moisture content MC of the pellet's sawdust")                                                 \
  X(double, moisture_reference, 8.0, Range, 0.0, 100.0, "%", "bond moisture_reference", true,      \
    "moisture content at which the bonds have E_b, sigma_c, tau_c")                                \
  X(double, moisture_coefficient, 0.0, Range, -1.0, 1.0, "1/%", "bond moisture_coefficient", true, \
    "c in exp(-c (MC - MC_ref)) on E_b, sigma_c and tau_c; 0 off")

namespace pelletdem {

struct MoistureBonds : BondEffect {
  template <class P>
  static double factor(const P& p) {
    return std::exp(-p.moisture_coefficient * (p.moisture_content - p.moisture_reference));
  }
  template <class P>
  static double stiffness_factor(const P& p) {
    return factor(p);
  }
  template <class P>
  static double strength_factor(const P& p, Index, Index) {
    return factor(p);
  }
};

}  // namespace pelletdem

PELLETDEM_BOND_EFFECT(MoistureBonds)
