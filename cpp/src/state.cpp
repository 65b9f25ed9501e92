// A world's whole state saved and restored (World::save_state, World::load_state): a restored
// world takes the next step the saved one would have, bit for bit.
#include <algorithm>
#include <cstdint>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

WorldState World::save_state() const {
  WorldState s;
  s.time = time_;
  s.step = step_;
  s.ramp_start = ramp_start_;
  s.ramp_duration = ramp_duration_;
  s.max_overlap_seen = max_overlap_seen_;
  s.load_peak_from = load_peak_from_;
  s.load_peak = load_peak_;
  s.load_smoothing = load_smoothing_;
  s.load_smoothed = load_smoothed_;
  s.forces_valid = forces_valid_;
  s.x = p_.x;
  s.v = p_.v;
  s.w = p_.w;
  s.f = p_.f;
  s.t = p_.t;
  s.r = p_.r;
  s.m = p_.m;
  if (list_valid_) s.x_build = x_build_;
  for (std::size_t i = 0; i + 1 < nbr_.start.size(); ++i)
    for (Index k = nbr_.start[i]; k < nbr_.start[i + 1]; ++k) {
      const ContactHistory& h = nbr_.history[k];
      if (h.blank()) continue;
      s.ci.push_back(static_cast<Index>(i));
      s.cj.push_back(nbr_.j[k]);
      s.c_delta0.push_back(h.delta0);
      s.c_ft.push_back(h.ft);
    }
  s.walls = walls_;
  for (int k = 0; k < wall_count(); ++k)
    if (walls_[k].load_wall) s.load_walls.push_back(k);
  flush_slots();
  s.bonds = bonds_;
  s.broken = broken_;
  return s;
}

void World::load_state(const WorldState& s) {
  const std::size_t n = s.r.size();
  require(s.x.size() == n && s.v.size() == n && s.w.size() == n && s.f.size() == n && s.t.size() == n &&
              s.m.size() == n,
          "state: particle arrays must all have the same length");
  require(s.ci.size() == s.cj.size() && s.ci.size() == s.c_delta0.size() && s.ci.size() == s.c_ft.size(),
          "state: contact arrays must all have the same length");
  require(*views_ == 0, "cannot load a state while numpy views of the particle arrays are alive");
  for (std::size_t k = 0; k < n; ++k) {
    require(s.r[k] > 0.0 && s.m[k] > 0.0 && s.x[k].allFinite() && s.v[k].allFinite(),
            cat("state: particle ", k, " has a non-finite or non-positive value"));
    require(params_.box.contains(s.x[k]), cat("state: particle ", k, " lies outside the box"));
  }
  for (std::size_t k = 0; k < s.ci.size(); ++k)
    require(s.ci[k] < s.cj[k] && s.cj[k] < n, cat("state: contact ", k, " has bad indices"));
  for (const Bond& b : s.bonds) require(b.i < n && b.j < n, "state: a bond has bad indices");
  for (const Wall& w : s.walls) {
    w.validate();
    for (const WallContact& c : w.contacts) require(c.i < n, "state: a wall contact has bad indices");
  }
  Particles p;
  p.x = s.x;
  p.v = s.v;
  p.w = s.w;
  p.f = s.f;
  p.t = s.t;
  p.r = s.r;
  p.m = s.m;
  p.inv_m.resize(n);
  p.inv_i.resize(n);
  r_max_ = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    p.inv_m[k] = 1.0 / p.m[k];
    p.inv_i[k] = 1.0 / sphere_inertia(p.m[k], p.r[k]);
    r_max_ = std::max(r_max_, p.r[k]);
  }
  p_ = std::move(p);
  x_build_.assign(n, Vec3::Zero());
  walls_ = s.walls;
  wall_samples_.assign(walls_.size(), {});
  for (Wall& w : walls_) w.load_wall = false;
  for (int k : s.load_walls) {
    require(k >= 0 && k < wall_count(), "state: load wall index out of range");
    walls_[k].load_wall = true;
  }
  bonds_ = s.bonds;
  slots_live_ = false;  // the slots held the replaced bonds
  bond_map_generation_ = -1;
  // The bonds' increments were last taken at the saved step (a state dict does not carry it).
  broken_ = s.broken;
  time_ = s.time;
  step_ = s.step;
  ramp_start_ = s.ramp_start;
  ramp_duration_ = s.ramp_duration;
  max_overlap_seen_ = s.max_overlap_seen;
  load_peak_from_ = s.load_peak_from;
  load_peak_ = s.load_peak;
  load_smoothing_ = s.load_smoothing;
  load_smoothed_ = s.load_smoothed;
  guard_stale_ = true;  // masses and bonds are the state's: the time step is checked before a step
  samples_.clear();
  // A list built where the saved one was (or, without those positions, at the saved ones: it
  // then holds every pair in contact, but the bonded pairs' forces may add up in another
  // order); the pairs in contact get their history.
  nbr_ = NeighborList{};
  bool same_list = s.x_build.size() == n;
  for (std::size_t k = 0; same_list && k < n; ++k)
    same_list = s.x_build[k].allFinite() && params_.box.contains(s.x_build[k]);
  if (same_list) {
    std::vector<Vec3> x_now = s.x_build;
    p_.x.swap(x_now);
    rebuild();
    p_.x.swap(x_now);
  } else {
    rebuild();
  }
  for (std::size_t k = 0; k < s.ci.size(); ++k) {
    const Index i = s.ci[k], j = s.cj[k];
    const auto first = nbr_.j.begin() + nbr_.start[i], last = nbr_.j.begin() + nbr_.start[i + 1];
    const auto it = std::lower_bound(first, last, j);
    if (it == last || *it != j) continue;  // not within reach any more: its history was blank
    ContactHistory& h = nbr_.history[it - nbr_.j.begin()];
    h.delta0 = s.c_delta0[k];
    h.ft = s.c_ft[k];
  }
  nbr_.mark_live();
  // The saved forces belong to the saved history: recomputing them would advance the history.
  forces_valid_ = s.forces_valid;
}

}  // namespace pelletdem
