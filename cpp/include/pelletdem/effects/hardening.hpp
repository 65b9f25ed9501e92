#pragma once
// Contact hardening: the loading branch stiffens at large overlap, k1 delta (1 + h (delta /
// r*)^n), for the paper's own residual (its linear law fits compaction only up to dh/h0 ~
// 0.75, above which the measured sigma_z rises more steeply).
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_Hardening(X)                                                           \
  X(double, hardening, 0.0, Range, 0.0, 1.0e4, "-", "hardening", true,                        \
    "contact hardening h: loading force k1 delta (1 + h (delta/r*)^n); 0 is the paper's law") \
  X(double, hardening_exponent, 1.0, Range, 0.5, 4.0, "-", "hardening_exponent", true,        \
    "exponent n of the contact hardening")

namespace pelletdem {

struct Hardening : ContactEffect {
  template <class P>
  static double loading_force(const P& p, double f, double delta, double r_eff) {
    if (p.hardening <= 0.0) return f;
    // n = 1 (the default) without std::pow, which costs more than the rest of a contact
    const double x = delta / r_eff;
    return f * (1.0 + p.hardening * (p.hardening_exponent == 1.0 ? x : std::pow(x, p.hardening_exponent)));
  }
  // d/d(delta) of k1 delta (1 + h x^n) = k1 (1 + h (n + 1) x^n), rising with x = delta / r*:
  // steepest at the largest overlap the run accepts.
  template <class P>
  static Spring steepest_loading(const P& p, Spring k1, double x_max) {
    if (p.hardening <= 0.0) return k1;
    const double n = p.hardening_exponent;
    return {k1.k * (1.0 + p.hardening * (n + 1.0) * std::pow(x_max, n)),
            k1.what + " x (1 + hardening (n + 1) (the largest overlap / r*)^n)"};
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(Hardening)
