// Particles renumbered in Morton order of their neighbour cells (World::sort_particles), so
// that particles in contact sit near each other in memory.
#include <algorithm>
#include <cstdint>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

namespace {
// The bits of v spread to every third bit: one coordinate of a 3-D Morton key.
std::uint64_t spread3(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}
}  // namespace

std::vector<Index> World::sort_particles() {
  require(bonds_.empty() && broken_.empty(),
          "sort_particles renumbers the particles: call it before bonds are created");
  require(*views_ == 0,
          "cannot sort the particles while numpy views of the particle arrays are alive: delete "
          "them (or copy them) first");
  // load_state below rebuilds the neighbour list; a box it refuses is refused here, before
  // anything has moved.
  if (!list_valid_) rebuild();
  const std::size_t n = p_.size();
  // Morton order of the neighbour cells: particles that touch are near in memory, in cells
  // small enough that a cell's particles share cache lines and large enough to hold a few.
  const double cell = 2.0 * r_max_ + effective_skin();
  std::vector<std::uint64_t> key(n);
  // Cell coordinates clamped to the key's 21 bits per axis (a huge box must not overflow
  // the conversion; beyond 2^21 cells the order is merely coarser).
  auto coord = [&](double v) {
    return static_cast<std::uint64_t>(std::min(std::max(v / cell, 0.0), 2097151.0));
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 d = p_.x[i] - params_.box.lo;
    key[i] = spread3(coord(d.x())) | spread3(coord(d.y())) << 1 | spread3(coord(d.z())) << 2;
  }
  std::vector<Index> order(n);  // order[new] = old
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<Index>(i);
  std::stable_sort(order.begin(), order.end(), [&](Index a, Index b) { return key[a] < key[b]; });
  std::vector<Index> renum(n);  // renum[old] = new
  for (std::size_t k = 0; k < n; ++k) renum[order[k]] = static_cast<Index>(k);

  WorldState s = save_state();
  auto permute = [&](auto& a) {
    auto old = a;
    for (std::size_t k = 0; k < n; ++k) a[k] = old[order[k]];
  };
  permute(s.x), permute(s.v), permute(s.w), permute(s.f), permute(s.t), permute(s.r), permute(s.m);
  if (!s.x_build.empty()) permute(s.x_build);
  // A pair keeps i < j; where renumbering swaps its ends, the tangential spring, stored as the
  // force on the second body, changes sign.
  for (std::size_t k = 0; k < s.ci.size(); ++k) {
    Index a = renum[s.ci[k]], b = renum[s.cj[k]];
    if (a > b) {
      std::swap(a, b);
      s.c_ft[k] = -s.c_ft[k];
    }
    s.ci[k] = a;
    s.cj[k] = b;
  }
  for (Wall& w : s.walls) {
    for (WallContact& c : w.contacts) c.i = renum[c.i];
    std::sort(w.contacts.begin(), w.contacts.end(),
              [](const WallContact& a, const WallContact& b) { return a.i < b.i; });
  }
  // load_state starts new time series; this is the same run, so they are kept.
  auto samples = std::move(samples_);
  auto wall_samples = std::move(wall_samples_);
  load_state(s);
  samples_ = std::move(samples);
  wall_samples_ = std::move(wall_samples);
  return order;
}

}  // namespace pelletdem
