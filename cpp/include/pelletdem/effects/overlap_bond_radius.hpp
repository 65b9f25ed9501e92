#pragma once
// A bond radius that grows with the contact's plastic flattening at bonding, so with the
// compaction pressure: r_b,ij = r_b (1 + g delta0_ij / r*_ij). Strength then rises with pressure
// faster than the paper's fixed r_b gives.
#include <algorithm>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_OverlapBondRadius(X)                                                     \
  X(double, overlap_radius_gain, 0.0, Range, 0.0, 1.0e3, "-", "bond overlap_radius_gain", true, \
    "bond radius r_b (1 + g delta0/r*) from the contact's residual overlap at bonding; 0 off")

namespace pelletdem {

struct OverlapBondRadius : BondEffect {
  template <class P>
  static double radius(const P& p, double r_b, double delta0, double r_eff) {
    return r_b * (1.0 + p.overlap_radius_gain * std::max(delta0, 0.0) / r_eff);
  }
};

}  // namespace pelletdem

PELLETDEM_BOND_EFFECT(OverlapBondRadius)
