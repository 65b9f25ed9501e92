#pragma once
// Moisture-dependent bonds: E_b, sigma_c and tau_c times exp(-c (MC - MC_ref)) (MC and MC_ref: the
// contact law's moisture_content and moisture_reference, copied at bonding), a trend of the
// strength with moisture content, the same at every pressure.
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_MoistureBonds(X)                                                            \
  X(double, moisture_coefficient, 0.0, Range, -1.0, 1.0, "1/%", "bond moisture_coefficient", true, \
    "c in exp(-c (MC - MC_ref)) on E_b, sigma_c and tau_c (MC: the contact law's); 0 off")

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
