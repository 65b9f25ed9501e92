#pragma once
// Bonds that soften before they break: past its strength a bond's capacity falls linearly with
// further stretching and reaches zero at (1 + s) times the strain at its peak (slope -E_b / s);
// 0 is the paper's brittle eq. 14. The curve keeps rising past the brittle model's peak and
// declines slowly after it.
#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_BondSoftening(X)                                     \
  X(double, softening, 0.0, Range, 0.0, 100.0, "-", "bond softening", true, \
    "bond softening s: capacity falls to zero at (1 + s) times the peak strain; 0 brittle")

namespace pelletdem {

struct BondSoftening : BondEffect {
  template <class P, class B>
  static void init(const P& p, B& b) {
    b.softening = p.softening;
  }
  // The stress is returned to the shrinking capacity: this step's stretch beyond the capacity,
  // (q - 1) left sigma_c / E_b, lowers it by (q - 1) left sigma_c / s.
  template <class B>
  static double capacity_after_overload(const B& b, double after, double left, double q) {
    return b.softening > 0.0 ? left * (1.0 - (q - 1.0) / b.softening) : after;
  }
};

}  // namespace pelletdem

PELLETDEM_BOND_EFFECT(BondSoftening)
