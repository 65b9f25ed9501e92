// Particle generation: polydisperse radii and random non-overlapping placement (the paper's
// "particles generated randomly in the mould", section 3.1.2).
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <unordered_map>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

namespace {
// Our own normal deviate (Box-Muller) so a seed gives the same radii with any standard library.
double std_normal(std::mt19937_64& rng) {
  constexpr double two_pi = 2.0 * kPi;
  const double u1 = (static_cast<double>(rng() >> 11) + 0.5) * 0x1.0p-53;
  const double u2 = static_cast<double>(rng() >> 11) * 0x1.0p-53;
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(two_pi * u2);
}
double uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }
}  // namespace

std::vector<double> truncated_normal_radii(long n, double mean, double sd, double r_min, double r_max,
                                           std::uint64_t seed) {
  require_range("n", static_cast<double>(n), 0, 1e8, "particles");
  require_positive("radius mean", mean, "m");
  require_nonnegative("radius sd", sd, "m");
  require_positive("radius min", r_min, "m");
  require(r_max >= r_min, cat("radius max = ", r_max, " m must be >= radius min = ", r_min, " m"));
  require(mean >= r_min && mean <= r_max,
          cat("radius mean = ", mean, " m must lie in [r_min, r_max] = [", r_min, ", ", r_max, "] m"));
  std::mt19937_64 rng(seed);
  std::vector<double> r;
  r.reserve(n);
  while (static_cast<long>(r.size()) < n) {
    const double x = mean + sd * std_normal(rng);
    if (x >= r_min && x <= r_max) r.push_back(x);
  }
  return r;
}

std::vector<Vec3> random_pack_cylinder(std::vector<double>& radii, double cx, double cy, double radius,
                                       double z_lo, double z_hi, std::uint64_t seed, long max_attempts) {
  require_positive("fill radius", radius, "m");
  require(z_hi > z_lo, cat("fill region: z_hi = ", z_hi, " m must be > z_lo = ", z_lo, " m"));
  require_range("max_attempts", static_cast<double>(max_attempts), 1, 1e9);
  double r_max = 0.0, solid = 0.0;
  for (double r : radii) {
    require(r > 0.0 && std::isfinite(r), "radii must be finite and > 0 m");
    r_max = std::max(r_max, r);
    solid += 4.0 / 3.0 * kPi * r * r * r;
  }
  require(r_max < radius,
          cat("largest radius ", r_max, " m does not fit the cylinder of radius ", radius, " m"));
  const double volume = kPi * radius * radius * (z_hi - z_lo);
  // Random sequential addition jams near a solid fraction of 0.38; beyond ~0.3 it crawls.
  if (solid / volume > 0.30)
    throw ParameterError(cat("particles do not fit their container: solid fraction ", solid / volume,
                             " of the fill region exceeds 0.30 (random "
                             "placement jams near 0.38); allowed fill height >= ",
                             solid / (0.30 * kPi * radius * radius), " m"));
  // Place large spheres first: they are the hardest to fit.
  std::vector<std::size_t> order(radii.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return radii[a] > radii[b]; });
  std::mt19937_64 rng(seed);
  const double cell = 2.0 * r_max;
  auto key = [&](int a, int b, int c) { return (static_cast<long long>(a) * 100003LL + b) * 100019LL + c; };
  std::unordered_map<long long, std::vector<std::size_t>> grid;
  std::vector<Vec3> pos(radii.size());
  std::vector<double> placed_r(radii.size());
  std::size_t placed = 0;
  for (std::size_t o : order) {
    const double r = radii[o];
    bool ok = false;
    for (long attempt = 0; attempt < max_attempts && !ok; ++attempt) {
      const double rho = (radius - r) * std::sqrt(uniform(rng));
      const double th = 2.0 * kPi * uniform(rng);
      const Vec3 x(cx + rho * std::cos(th), cy + rho * std::sin(th),
                   z_lo + r + (z_hi - z_lo - 2.0 * r) * uniform(rng));
      const int gx = static_cast<int>(std::floor(x.x() / cell));
      const int gy = static_cast<int>(std::floor(x.y() / cell));
      const int gz = static_cast<int>(std::floor(x.z() / cell));
      ok = true;
      for (int a = -1; a <= 1 && ok; ++a)
        for (int b = -1; b <= 1 && ok; ++b)
          for (int c = -1; c <= 1 && ok; ++c) {
            auto it = grid.find(key(gx + a, gy + b, gz + c));
            if (it == grid.end()) continue;
            for (std::size_t q : it->second) {
              const double s = r + placed_r[q];
              if ((pos[q] - x).squaredNorm() < s * s) {
                ok = false;
                break;
              }
            }
          }
      if (ok) {
        pos[placed] = x;
        placed_r[placed] = r;
        grid[key(gx, gy, gz)].push_back(placed);
        ++placed;
      }
    }
    if (!ok)
      throw ParameterError(cat("particles do not fit their container: placed ", placed, " of ", radii.size(),
                               " after ", max_attempts,
                               " attempts for one particle; make the fill region taller"));
  }
  // Sort along z so that neighbours in space are neighbours in memory.
  std::vector<std::size_t> idx(placed);
  std::iota(idx.begin(), idx.end(), 0);
  std::stable_sort(idx.begin(), idx.end(),
                   [&](std::size_t a, std::size_t b) { return pos[a].z() < pos[b].z(); });
  std::vector<Vec3> out(placed);
  for (std::size_t k = 0; k < placed; ++k) {
    out[k] = pos[idx[k]];
    radii[k] = placed_r[idx[k]];
  }
  return out;
}

}  // namespace pelletdem
