#pragma once
// Unloading stiffness that grows with plastic flattening (after Luding 2008, where k2 grows
// with the largest overlap): k2(delta0) = k2 (1 + g delta0 / r*), delta0 the residual overlap,
// which on the loading line grows with the largest overlap. A flattened contact springs back
// less: higher relaxed density, the more so at higher pressure; loading unchanged.
#include <algorithm>
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_UnloadingGrowth(X)                                            \
  X(double, unloading_growth, 0.0, Range, 0.0, 1.0e4, "-", "unloading_growth", true, \
    "growth g of the unloading stiffness with plastic flattening, k2 (1 + g delta0/r*); 0 off")

namespace pelletdem {

struct UnloadingGrowth : ContactEffect {
  template <class P>
  static bool shapes_unloading(const P& p) {
    return p.unloading_growth > 0.0;
  }
  template <class P>
  static double unloading_stiffness(const P& p, double k2, double delta0, double r_eff) {
    return k2 * (1.0 + p.unloading_growth * std::max(delta0, 0.0) / r_eff);
  }
  // k2 (1 + a delta0) (delta - delta0) = f with a = g / r*, solved for the root that tends to
  // plain = delta - f / k2 as a -> 0 (written so it does not cancel).
  template <class P>
  static double residual(const P& p, double plain, double delta, double /*f*/, double /*k2*/, double r_eff) {
    if (p.unloading_growth <= 0.0) return plain;
    const double a = p.unloading_growth / r_eff;
    const double b = 1.0 - a * delta;
    // a x^2 + b x - c = 0 has one positive root (c >= 0 as f <= k1 delta <= k2 delta)
    const double root = std::sqrt(std::max(b * b + 4.0 * a * plain, 0.0));
    return (b > 0.0) ? 2.0 * plain / (b + root) : (root - b) / (2.0 * a);
  }
  // Unbounded in delta0, so at the largest residual overlap the run accepts (delta0 <= delta).
  template <class P>
  static Spring largest_unloading(const P& p, Spring k2, double x_max) {
    if (p.unloading_growth <= 0.0) return k2;
    return {k2.k * (1.0 + p.unloading_growth * x_max),
            k2.what + " x (1 + unloading_growth x the largest overlap / r*)"};
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(UnloadingGrowth)
