#pragma once
// A spread of bond strengths: each bond's sigma_c and tau_c are the law's times a Weibull
// variate of modulus m and mean 1, drawn from (strength_seed, i, j), so a bond's strength never
// depends on the thread count or the order bonds are made in. Weak bonds break early: the rise
// bends over before the peak, the peak is lower and rounder.
#include <cmath>
#include <cstdint>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_WeibullStrength(X)                                                     \
  X(double, weibull_modulus, 0.0, ZeroOrRange, 0.5, 100.0, "-", "bond weibull_modulus", true, \
    "Weibull modulus m of the bonds' strengths (mean kept); 0: every bond as strong")         \
  X(double, strength_seed, 0.0, WholeRange, 0.0, 9.0e15, "-", "bond strength_seed", true,     \
    "seed of the strengths' draw (a whole number)")

namespace pelletdem {

struct WeibullStrength : BondEffect {
  // splitmix64
  static std::uint64_t mix64(std::uint64_t z) {
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  // A Weibull variate of modulus m scaled to mean 1: (-ln(1 - u))^(1/m) / Gamma(1 + 1/m).
  static double unit_mean(double m, std::uint64_t seed, Index i, Index j) {
    const std::uint64_t h = mix64(mix64(seed) ^ mix64((static_cast<std::uint64_t>(i) << 32) | j));
    const double u = (static_cast<double>(h >> 11) + 0.5) * 0x1.0p-53;  // in (0, 1)
    return std::pow(-std::log1p(-u), 1.0 / m) / std::tgamma(1.0 + 1.0 / m);
  }
  template <class P>
  static double strength_factor(const P& p, Index i, Index j) {
    return p.weibull_modulus > 0.0
               ? unit_mean(p.weibull_modulus, static_cast<std::uint64_t>(p.strength_seed), i, j)
               : 1.0;
  }
};

}  // namespace pelletdem

PELLETDEM_BOND_EFFECT(WeibullStrength)
