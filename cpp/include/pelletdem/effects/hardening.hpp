#pragma once
// Contact hardening: the loading branch stiffens at large overlap, k1 delta (1 + h (delta /
// r*)^n), for the paper's own residual (its linear law fits compaction only up to dh/h0 ~
// 0.75, above which the measured sigma_z rises more steeply).
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_Hardening(X)                                                           \
  X(double, hardening, 0.0, Range, 0.0, 1.0e4, "-", "hardening", false,                       \
    "contact hardening h: loading force k1 delta (1 + h (delta/r*)^n); 0 is the paper's law") \
  X(double, hardening_exponent, 1.0, Range, 0.5, 4.0, "-", "hardening_exponent", true,        \
    "exponent n of the contact hardening")

namespace pelletdem {

struct Hardening : ContactEffect {
  template <class P>
  static double loading_force(const P& p, double f, double delta, double r_eff) {
    return p.hardening > 0.0 ? f * (1.0 + p.hardening * std::pow(delta / r_eff, p.hardening_exponent)) : f;
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(Hardening)
