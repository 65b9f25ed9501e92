// Stepping: the neighbour list kept valid, walls moved, a step (velocity Verlet) and runs
// until a stop condition fires, with the guards that stop a run that went wrong.
#include <omp.h>
#include <algorithm>
#include <cmath>

#include "pelletdem/errors.hpp"
#include "pelletdem/integrate.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

void World::build_wall_lists() {
  const double skin = effective_skin();
  for (Wall& w : walls_) {
    std::vector<WallContact> next;
    std::size_t a = 0;
    for (std::size_t i = 0; i < p_.size(); ++i) {
      Vec3 n_into;
      if (w.gap(p_.x[i], p_.r[i], n_into) >= skin) continue;
      WallContact wc{static_cast<Index>(i), ContactHistory{}};
      while (a < w.contacts.size() && w.contacts[a].i < wc.i) ++a;
      if (a < w.contacts.size() && w.contacts[a].i == wc.i) wc.h = w.contacts[a].h;
      next.push_back(wc);
    }
    w.contacts.swap(next);
    w.moved_since_build = 0.0;
  }
}

void World::rebuild() {
  nbr_.build(p_, params_.box, effective_skin(), r_max_, step_, team());
  build_wall_lists();
  std::copy(p_.x.begin(), p_.x.end(), x_build_.begin());
  list_valid_ = true;
  ++rebuilds_;
}

void World::ensure_forces() {
  if (!list_valid_) rebuild();
  if (!forces_valid_) {
    compute_forces(false);
    forces_valid_ = true;
  }
}

void World::move_walls() {
  const double dt = params_.dt;
  for (Wall& w : walls_) {
    if (!w.active) continue;
    if (w.servo && w.kind == WallKind::Plane) {
      const double err = w.servo_force - w.normal_force();
      const double speed = std::clamp(w.servo_gain * err, -w.servo_max_speed, w.servo_max_speed);
      w.velocity = speed * w.normal;
    }
    w.point += w.velocity * dt;
    double moved = w.velocity.norm() * dt;
    if (w.kind == WallKind::Cylinder) {
      w.radius += w.radius_rate * dt;
      if (!(w.radius > 0.0))
        throw SimulationError(cat("wall '", w.name, "': cylinder radius fell to ", w.radius, " m at step ",
                                  step_,
                                  "; likely cause: radius_rate too negative "
                                  "for the run's length"));
      moved += std::abs(w.radius_rate) * dt;
      w.travel -= w.radius_rate * dt;
    } else {
      w.travel += w.velocity.dot(w.normal) * dt;
    }
    w.moved_since_build += moved;
  }
}

bool World::needs_rebuild(double max_disp) const {
  const double skin = effective_skin();
  if (2.0 * max_disp > skin) return true;
  for (const Wall& w : walls_)
    if (w.active && max_disp + w.moved_since_build > skin) return true;
  return false;
}

void World::check_guards() {
  double worst = max_overlap_;
  Index who = max_overlap_i_;
  const char* where = "between two particles";
  for (const Wall& w : walls_) {
    if (w.max_overlap_ratio > worst) {
      worst = w.max_overlap_ratio;
      who = w.max_overlap_particle;
      where = "against a wall";
    }
  }
  if (worst > params_.max_overlap_ratio)
    throw OverlapError(cat("overlap / radius = ", worst, " ", where, " at particle ", who, ", step ", step_,
                           " (t = ", time_, " s) exceeds max_overlap_ratio = ", params_.max_overlap_ratio,
                           "; likely causes: loading speed too high, stiffness too low for the "
                           "target stress, or time step too large"));
}

void World::step() {
  if (guard_stale_) validate_time_step();
  advance(false);
}

void World::advance(bool defer) {
  const long n = static_cast<long>(p_.size());
  const double dt = params_.dt;
  ensure_forces();
  size_particle_scratch();
  const int nt = team();
  const bool rolling = params_.contact.rolling > 0.0;
  std::vector<DriftResult> drift_t(nt);
  const LoadSums sums = load_sums(kick_nt_);
  const LoadSums* pending = kick_pending_ ? &sums : nullptr;
#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    long lo, hi;
    static_share(n, nt, tid, lo, hi);
    drift_t[tid] = kick_drift_pack(lo, hi, dt, rolling, p_, x_build_.data(), loads_[0].data(), xr_.data(),
                                   mo_.data(), spin_inv_.data(), pending);
  }
  kick_pending_ = false;
  double max_disp2 = 0.0;
  long bad = -1;
  for (const DriftResult& d : drift_t) {
    max_disp2 = std::max(max_disp2, d.max_disp2);
    bad = std::max(bad, d.bad);
  }
  // The forces are zeroed now: should anything below throw, the next step recomputes them.
  forces_valid_ = false;
  if (bad >= 0)
    throw NonFiniteError(cat("particle ", bad, " has a non-finite position at step ", step_ + 1,
                             " (t = ", time_ + dt,
                             " s): its velocity or force became NaN or "
                             "infinite; likely causes: time step too large, loading speed too "
                             "high, or contact or bond parameters far outside their range"));
  move_walls();
  if (needs_rebuild(std::sqrt(max_disp2))) rebuild();
  time_ += dt;
  ++step_;
  prepared_ = true;
  compute_forces(true, defer ? Finish::Defer : Finish::ReduceKick);
  forces_valid_ = true;
  check_guards();
  if (load_peak_from_ != kInf) {
    // Running mean over ~load_smoothing_ steps: the plate force of a small pellet jumps at
    // every bond that breaks, and the break detection must not take a jump for the break.
    const double f = load_force();
    load_smoothed_ = load_smoothed_ == -kInf ? f : load_smoothed_ + (f - load_smoothed_) / load_smoothing_;
    if (load_marker() >= load_peak_from_) load_peak_ = std::max(load_peak_, load_smoothed_);
  }
  if (step_ % params_.sample_interval == 0) {
    finish_pending_kick();  // the sample's kinetic energy needs the step's velocities
    record_sample();
  }
}

void World::run(long steps) {
  require(steps >= 0, cat("steps = ", steps, " must be >= 0"));
  validate_time_step();
  try {
    for (long s = 0; s < steps; ++s) advance(true);
  } catch (...) {
    finish_pending_kick();
    throw;
  }
  finish_pending_kick();
}

RunOutcome World::run_until(const std::vector<StopCondition>& conds, long max_steps) {
  require(max_steps >= 0, cat("max_steps = ", max_steps, " must be >= 0"));
  for (const StopCondition& c : conds) {
    require(std::isfinite(c.value), "stop condition value must be finite");
    require(c.check_interval >= 1, "stop condition check_interval must be >= 1 step");
    const bool needs_wall = c.kind == StopKind::WallForceAbove || c.kind == StopKind::WallForceBelow ||
                            c.kind == StopKind::WallTravelAbove;
    if (needs_wall) require_range("stop condition wall", c.wall, 0, wall_count() - 1);
    if (c.kind == StopKind::LoadDropBelow) {
      require(c.value > 0.0 && c.value < 1.0,
              cat("load_drop_below = ", c.value,
                  " is out of range: allowed 0 < value < 1 (fraction of the peak)"));
      require(std::any_of(walls_.begin(), walls_.end(), [](const Wall& w) { return w.load_wall; }),
              "load_drop_below needs load walls (set_load_walls) and a tracked peak (track_load_peak)");
    }
  }
  validate_time_step();
  ensure_forces();
  try {
    const RunOutcome out = run_steps_until(conds, max_steps);
    finish_pending_kick();
    return out;
  } catch (...) {
    finish_pending_kick();
    throw;
  }
}

RunOutcome World::run_steps_until(const std::vector<StopCondition>& conds, long max_steps) {
  RunOutcome out;
  for (long s = 0; s < max_steps; ++s) {
    advance(true);
    ++out.steps;
    for (std::size_t k = 0; k < conds.size(); ++k) {
      const StopCondition& c = conds[k];
      // On the world's step count, not the call's: the Python binding runs a long call in
      // wall-clock-sized chunks, and a per-call count would make the test steps depend on
      // timing (non-deterministic stops) and skip the test in chunks shorter than the interval.
      if (step_ % c.check_interval != 0) continue;
      bool hit = false;
      switch (c.kind) {
        case StopKind::Time:
          hit = time_ >= c.value;
          break;
        case StopKind::Steps:
          hit = out.steps >= c.value;
          break;
        case StopKind::KineticEnergyBelow:
          finish_pending_kick();
          hit = kinetic_energy() < c.value;
          break;
        case StopKind::InternalKineticEnergyBelow:
          finish_pending_kick();
          hit = internal_kinetic_energy() < c.value;
          break;
        case StopKind::WallForceAbove:
          hit = walls_[c.wall].normal_force() >= c.value;
          break;
        case StopKind::WallForceBelow:
          hit = walls_[c.wall].normal_force() <= c.value;
          break;
        case StopKind::WallTravelAbove:
          hit = walls_[c.wall].travel >= c.value;
          break;
        case StopKind::LoadMarkerAbove:
          hit = load_marker() >= c.value;
          break;
        case StopKind::LoadDropBelow:
          hit = load_peak_ > 0.0 && load_smoothed_ <= c.value * load_peak_;
          break;
      }
      if (hit) {
        out.condition = static_cast<int>(k);
        return out;
      }
    }
  }
  return out;
}

}  // namespace pelletdem
