#pragma once
// An unloading stiffness that rises with plastic flattening and saturates at a plastic limit
// (Luding 2008: k2 grows with the largest overlap up to k_p): k2(delta0) = k2 + (k_p - k2)
// min(delta0 / (phi r*), 1), delta0 the residual overlap, which on the loading line grows with
// the largest overlap. Deeply flattened contacts spring back at most as stiffly as k_p: less
// spring-back after compaction, the more so at higher pressure, then no more once saturated.
#include <algorithm>
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_SaturatingUnloading(X)                                                       \
  X(double, plastic_stiffness_ratio, 1.0, Range, 1.0, 1.0e3, "-", "plastic_stiffness_ratio", true,  \
    "k_p / k2: the unloading stiffness of a fully flattened contact; 1 is the paper's constant k2") \
  X(double, plastic_overlap, 0.2, Range, 1.0e-3, 10.0, "-", "plastic_overlap", true,                \
    "phi: the residual overlap delta0 / r* at which the unloading stiffness reaches k_p")

namespace pelletdem {

struct SaturatingUnloading : ContactEffect {
  template <class P>
  static bool shapes_unloading(const P& p) {
    return p.plastic_stiffness_ratio > 1.0;
  }
  template <class P>
  static double unloading_stiffness(const P& p, double k2, double delta0, double r_eff) {
    if (p.plastic_stiffness_ratio <= 1.0) return k2;
    const double reach = std::min(std::max(delta0, 0.0) / (p.plastic_overlap * r_eff), 1.0);
    return k2 * (1.0 + (p.plastic_stiffness_ratio - 1.0) * reach);
  }
  // k2 (1 + a delta0) (delta - delta0) = f below saturation (a = (ratio - 1) / (phi r*)): the
  // root that tends to plain = delta - f / k2 as a -> 0; past saturation delta - f / k_p.
  template <class P>
  static double residual(const P& p, double plain, double delta, double f, double k2, double r_eff) {
    if (p.plastic_stiffness_ratio <= 1.0) return plain;
    const double d_sat = p.plastic_overlap * r_eff;
    const double a = (p.plastic_stiffness_ratio - 1.0) / d_sat;
    const double b = 1.0 - a * delta;
    const double root = std::sqrt(std::max(b * b + 4.0 * a * plain, 0.0));
    const double d0 = (b > 0.0) ? 2.0 * plain / (b + root) : (root - b) / (2.0 * a);
    return d0 < d_sat ? d0 : delta - f / (p.plastic_stiffness_ratio * k2);
  }
  // k_p, reached once delta0 = phi r*: a compaction to 60-120 MPa flattens contacts that far.
  template <class P>
  static Spring largest_unloading(const P& p, Spring k2, double /*x_max*/) {
    if (p.plastic_stiffness_ratio <= 1.0) return k2;
    return {p.plastic_stiffness_ratio * k2.k, "k_p = plastic_stiffness_ratio x " + k2.what};
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(SaturatingUnloading)
