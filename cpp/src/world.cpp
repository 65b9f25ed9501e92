#include "pelletdem/world.hpp"

#include <algorithm>
#include <cmath>
#include <omp.h>

#include "pelletdem/errors.hpp"
#include "pelletdem/integrate.hpp"

namespace pelletdem {

void WorldParams::validate() const {
  require_positive("dt", dt, "s");
  require(gravity.allFinite(), "gravity must be finite (m/s^2)");
  require_range("density", density, 1e-3, 1e8, "kg/m^3");
  require_range("density_scale", density_scale, 1e-3, 1e12);
  require_nonnegative("skin", skin, "m");
  require(box.lo.allFinite() && box.hi.allFinite(), "box corners must be finite (m)");
  require((box.hi - box.lo).minCoeff() > 0.0,
          cat("box: every extent must be > 0 m (got ", (box.hi - box.lo).transpose(), ")"));
  require_range("threads", threads, 1, 1024);
  require_range("max_overlap_ratio", max_overlap_ratio, 1e-3, 10.0);
  require_range("sample_interval", static_cast<double>(sample_interval), 1, 1e12, "steps");
  contact.validate();
}

World::World(const WorldParams& params)
    : r_max_(0.0), params_(params), law_(params.contact) {
  params_.validate();
}

void World::set_contact_params(const ContactLawParams& c) {
  c.validate();
  ContactLawParams old = params_.contact;
  params_.contact = c;
  try {
    validate_time_step();
  } catch (...) {
    params_.contact = old;
    throw;
  }
  law_ = HystereticLaw(c);
}

void World::set_dt(double dt) {
  require_positive("dt", dt, "s");
  const double old = params_.dt;
  params_.dt = dt;
  try {
    validate_time_step();
  } catch (...) {
    params_.dt = old;
    throw;
  }
}

void World::set_threads(int threads) {
  require_range("threads", threads, 1, 1024);
  params_.threads = threads;
}

void World::set_gravity(const Vec3& g) {
  require(g.allFinite(), "gravity must be finite (m/s^2)");
  params_.gravity = g;
  forces_valid_ = false;
}

void World::set_max_overlap_ratio(double ratio) {
  require_range("max_overlap_ratio", ratio, 1e-3, 10.0);
  params_.max_overlap_ratio = ratio;
}

void World::set_load_walls(const std::vector<int>& ws) {
  for (int k : ws) require_range("load wall index", k, 0, wall_count() - 1);
  for (Wall& w : walls_) w.load_wall = false;
  for (int k : ws) walls_[k].load_wall = true;
}

void World::set_adhesion_ramp(double t_start, double duration) {
  require(std::isfinite(t_start), "adhesion ramp start must be finite (s)");
  require_nonnegative("adhesion ramp duration", duration, "s");
  ramp_start_ = t_start;
  ramp_duration_ = duration;
}

void World::set_sample_interval(long n) {
  require_range("sample_interval", static_cast<double>(n), 1, 1e12, "steps");
  params_.sample_interval = n;
}

void World::add_particles(const std::vector<Vec3>& x, const std::vector<double>& r) {
  require(x.size() == r.size(), cat("positions (", x.size(), ") and radii (", r.size(),
                                    ") must have the same length"));
  require(*views_ == 0,
          "cannot add particles while numpy views of the particle arrays are alive: delete "
          "them (or copy them) first, adding particles moves the arrays");
  require(bonds_.empty(), "cannot add particles after bonds were created");
  for (std::size_t k = 0; k < x.size(); ++k) {
    if (!(r[k] > 0.0) || !std::isfinite(r[k]))
      throw ParameterError(cat("radius[", k, "] = ", r[k], " m: radii must be finite and > 0"));
    if (!x[k].allFinite())
      throw ParameterError(cat("position[", k, "] is not finite"));
    if (!params_.box.contains(x[k])) {
      // Name the allowed range: the box, coordinate by coordinate.
      const Box& b = params_.box;
      throw ParameterError(cat("position[", k, "] = (", x[k].x(), ", ", x[k].y(), ", ", x[k].z(),
                               ") m lies outside the domain box: allowed [", b.lo.x(), ", ",
                               b.hi.x(), "] x [", b.lo.y(), ", ", b.hi.y(), "] x [", b.lo.z(),
                               ", ", b.hi.z(), "] m"));
    }
  }
  const double rho = params_.density * params_.density_scale;
  const std::size_t n_before = p_.size();
  const double r_max_before = r_max_;
  for (std::size_t k = 0; k < x.size(); ++k) {
    p_.push(x[k], r[k], rho * 4.0 / 3.0 * kPi * r[k] * r[k] * r[k]);
    r_max_ = std::max(r_max_, r[k]);
  }
  x_build_.resize(p_.size());
  list_valid_ = false;
  forces_valid_ = false;
  try {
    validate_time_step();
  } catch (...) {
    // Refused input leaves the world as it was, not holding particles it cannot step.
    for (auto* a : {&p_.x, &p_.v, &p_.w, &p_.f, &p_.t}) a->resize(n_before);
    for (auto* a : {&p_.r, &p_.m, &p_.inv_m, &p_.inv_i}) a->resize(n_before);
    x_build_.resize(n_before);
    r_max_ = r_max_before;
    throw;
  }
}

int World::add_plane(const std::string& name, const Vec3& point, const Vec3& normal) {
  Wall w;
  w.name = name;
  w.kind = WallKind::Plane;
  w.point = point;
  const double len = normal.norm();
  require(normal.allFinite() && len > 0.0, cat("wall '", name, "': normal must be non-zero"));
  w.normal = normal / len;
  w.validate();
  walls_.push_back(w);
  wall_samples_.emplace_back();
  list_valid_ = false;
  forces_valid_ = false;
  validate_time_step();
  return wall_count() - 1;
}

int World::add_cylinder(const std::string& name, const Vec3& axis_point, double radius) {
  Wall w;
  w.name = name;
  w.kind = WallKind::Cylinder;
  w.point = axis_point;
  w.radius = radius;
  w.validate();
  walls_.push_back(w);
  wall_samples_.emplace_back();
  list_valid_ = false;
  forces_valid_ = false;
  return wall_count() - 1;
}

Wall& World::wall(int k) {
  require_range("wall index", k, 0, wall_count() - 1);
  return walls_[k];
}
const Wall& World::wall(int k) const {
  require_range("wall index", k, 0, wall_count() - 1);
  return walls_[k];
}

double World::critical_time_step() const {
  if (p_.size() == 0) return HUGE_VAL;
  // Stiffest single contact against the lightest body: a linear oscillator is stable for
  // dt < 2 / omega. Tangential springs couple to rotation, which raises their effective
  // stiffness by 1 + m r^2 / I = 3.5 for a solid sphere.
  double m_min = HUGE_VAL, r_min = HUGE_VAL;
  for (std::size_t i = 0; i < p_.size(); ++i) {
    m_min = std::min(m_min, p_.m[i]);
    r_min = std::min(r_min, p_.r[i]);
  }
  const ContactLawParams& c = params_.contact;
  const double s_r = c.scale_with_radius ? r_max_ / c.r_ref : 1.0;
  // A wall contact is stiffness wall_stiffness_factor * s_r * k on one particle (m >= m_min).
  // A particle pair is at most s_r * k (2 r* / r_ref <= r_max / r_ref when scaled) on the
  // reduced mass m* = m_i m_j / (m_i + m_j) >= m_min / 2, i.e. like 2 s_r k on m_min: two
  // free spheres are twice as stiff per unit mass as one sphere on a wall of the same
  // stiffness. (Without the pair term a wall_stiffness_factor below 2 gave a limit sqrt(2)
  // too large or more, and a bound pair oscillating at dt just under it blew up.)
  const double s_eff = std::max(c.wall_stiffness_factor, 2.0) * s_r;
  const double k_eff = s_eff * std::max(c.k2, 3.5 * c.kt_ratio * c.k1);
  return 2.0 * std::sqrt(m_min / k_eff);
}

void World::validate_time_step() const {
  const double dtc = critical_time_step();
  if (params_.dt > dtc)
    throw ParameterError(cat("dt = ", params_.dt, " s is above the stability limit of the "
                             "stiffest contact: allowed 0 < dt <= ", dtc,
                             " s (2 sqrt(m_min / k_max)); the paper uses about 0.1 of it"));
}

double World::effective_skin() const {
  return params_.skin > 0.0 ? params_.skin : 0.1 * r_max_;
}

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
      const double speed =
          std::clamp(w.servo_gain * err, -w.servo_max_speed, w.servo_max_speed);
      w.velocity = speed * w.normal;
    }
    w.point += w.velocity * dt;
    double moved = w.velocity.norm() * dt;
    if (w.kind == WallKind::Cylinder) {
      w.radius += w.radius_rate * dt;
      if (!(w.radius > 0.0))
        throw SimulationError(cat("wall '", w.name, "': cylinder radius fell to ", w.radius,
                                  " m at step ", step_, "; likely cause: radius_rate too negative "
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
    throw OverlapError(cat("overlap / radius = ", worst, " ", where, " at particle ", who,
                           ", step ", step_, " (t = ", time_, " s) exceeds max_overlap_ratio = ",
                           params_.max_overlap_ratio,
                           "; likely causes: loading speed too high, stiffness too low for the "
                           "target stress, or time step too large"));
}

void World::step() { advance(false); }

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
    drift_t[tid] = kick_drift_pack(lo, hi, dt, rolling, p_, x_build_.data(), loads_[0].data(),
                                   xr_.data(), mo_.data(), spin_inv_.data(), pending);
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
                             " (t = ", time_ + dt, " s): its velocity or force became NaN or "
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
    const bool needs_wall = c.kind == StopKind::WallForceAbove ||
                            c.kind == StopKind::WallForceBelow ||
                            c.kind == StopKind::WallTravelAbove;
    if (needs_wall) require_range("stop condition wall", c.wall, 0, wall_count() - 1);
    if (c.kind == StopKind::LoadDropBelow) {
      require(c.value > 0.0 && c.value < 1.0,
              cat("load_drop_below = ", c.value, " is out of range: allowed 0 < value < 1 (fraction of the peak)"));
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
        case StopKind::Time: hit = time_ >= c.value; break;
        case StopKind::Steps: hit = out.steps >= c.value; break;
        case StopKind::KineticEnergyBelow:
          finish_pending_kick();
          hit = kinetic_energy() < c.value;
          break;
        case StopKind::InternalKineticEnergyBelow:
          finish_pending_kick();
          hit = internal_kinetic_energy() < c.value;
          break;
        case StopKind::WallForceAbove: hit = walls_[c.wall].normal_force() >= c.value; break;
        case StopKind::WallForceBelow: hit = walls_[c.wall].normal_force() <= c.value; break;
        case StopKind::WallTravelAbove: hit = walls_[c.wall].travel >= c.value; break;
        case StopKind::LoadMarkerAbove: hit = load_marker() >= c.value; break;
        case StopKind::LoadDropBelow: hit = load_peak_ > 0.0 && load_smoothed_ <= c.value * load_peak_; break;
      }
      if (hit) {
        out.condition = static_cast<int>(k);
        return out;
      }
    }
  }
  return out;
}

double World::load_force() const {
  double f = 0.0;
  int n = 0;
  for (const Wall& w : walls_)
    if (w.load_wall) {
      f += w.normal_force();
      ++n;
    }
  return n ? f / n : 0.0;
}

void World::track_load_peak(double from_marker, double smoothing_steps) {
  require(!std::isnan(from_marker), "track_load_peak: from_marker must not be NaN (m)");
  require_range("track_load_peak smoothing_steps", smoothing_steps, 1.0, 1e9);
  load_peak_from_ = from_marker;
  load_smoothing_ = smoothing_steps;
  load_smoothed_ = -kInf;
  load_peak_ = 0.0;
}

double World::load_marker() const {
  double m = 0.0;
  for (const Wall& w : walls_)
    if (w.load_wall) m += w.travel;
  return m;
}

double World::kinetic_energy() const {
  const long n = static_cast<long>(p_.size());
  const int nt = team();
  std::vector<double> part(nt, 0.0);
#pragma omp parallel num_threads(nt)
  {
    double e = 0.0;
#pragma omp for schedule(static)
    for (long i = 0; i < n; ++i)
      e += 0.5 * p_.m[i] * p_.v[i].squaredNorm() + 0.5 / p_.inv_i[i] * p_.w[i].squaredNorm();
    part[omp_get_thread_num()] = e;
  }
  double e = 0.0;
  for (double x : part) e += x;  // fixed order: reproducible for a given thread count
  return e;
}

namespace {
// Total momentum and mass of the particles.
double momentum(const Particles& p, Vec3& mom) {
  mom.setZero();
  double mass = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    mom += p.m[i] * p.v[i];
    mass += p.m[i];
  }
  return mass;
}
}  // namespace

Vec3 World::mean_velocity() const {
  Vec3 mom;
  const double mass = momentum(p_, mom);
  return mass > 0.0 ? Vec3(mom / mass) : Vec3::Zero();
}

double World::internal_kinetic_energy() const {
  // E - |P|^2 / (2 M): the translation of the whole assembly removed.
  Vec3 mom;
  const double mass = momentum(p_, mom);
  const double e = kinetic_energy() - (mass > 0.0 ? 0.5 * mom.squaredNorm() / mass : 0.0);
  return std::max(e, 0.0);
}

void World::remove_mean_velocity() {
  const Vec3 vm = mean_velocity();
  for (auto& v : p_.v) v -= vm;
}

double World::potential_energy() const {
  double e = 0.0;
  const Vec3 g = params_.gravity / params_.density_scale;
  for (std::size_t i = 0; i < p_.size(); ++i) e -= p_.m[i] * g.dot(p_.x[i]);
  for (std::size_t i = 0; i + 1 < nbr_.start.size(); ++i)
    for (Index k = nbr_.start[i]; k < nbr_.start[i + 1]; ++k) {
      const Index j = nbr_.j[k];
      const double rsum = p_.r[i] + p_.r[j];
      const double delta = rsum - (p_.x[j] - p_.x[i]).norm();
      if (delta > 0.0) e += law_.stored_energy(delta, nbr_.history[k], p_.r[i] * p_.r[j] / rsum);
    }
  for (const Wall& w : walls_) {
    if (!w.active) continue;
    for (const WallContact& wc : w.contacts) {
      Vec3 n_into;
      const double gap = w.gap(p_.x[wc.i], p_.r[wc.i], n_into);
      if (gap < 0.0) e += law_.stored_energy(-gap, wc.h, p_.r[wc.i], true);
    }
  }
  for (const Bond& b : bonds()) {  // flushed: the slots hold their state
    if (b.mode != BondMode::Intact) continue;
    const double a = b.area(), jp = b.polar_moment();
    e += 0.5 * b.fn * b.fn / (b.kn * a);
    if (b.kt > 0.0) e += 0.5 * b.ft.squaredNorm() / (b.kt * a) + 0.5 * b.mn * b.mn / (b.kt * jp);
    e += 0.5 * b.mt.squaredNorm() / (b.kn * 0.5 * jp);
  }
  return e;
}

double World::coordination_number() const {
  return p_.size() ? 2.0 * static_cast<double>(n_contacts_) / p_.size() : 0.0;
}

long World::intact_bond_count() const {
  long c = 0;
  for (const Bond& b : bonds_) c += b.mode == BondMode::Intact;
  return c;
}

void World::contacts(std::vector<Index>& ci, std::vector<Index>& cj, std::vector<double>& ov,
                     std::vector<double>& fn) const {
  const double adh = adhesion_scale();
  for (std::size_t i = 0; i + 1 < nbr_.start.size(); ++i)
    for (Index k = nbr_.start[i]; k < nbr_.start[i + 1]; ++k) {
      const Index j = nbr_.j[k];
      const double rsum = p_.r[i] + p_.r[j];
      const double delta = rsum - (p_.x[j] - p_.x[i]).norm();
      if (delta <= 0.0) continue;
      double d0 = nbr_.history[k].delta0;
      ci.push_back(static_cast<Index>(i));
      cj.push_back(j);
      ov.push_back(delta);
      fn.push_back(law_.normal_force(delta, d0, p_.r[i] * p_.r[j] / rsum, adh));
    }
}

namespace {

// splitmix64: a bond's strength depends only on (seed, i, j), never on the thread count or
// the order bonds are made in.
std::uint64_t mix64(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// A Weibull variate of modulus m scaled to mean 1: (-ln(1 - u))^(1/m) / Gamma(1 + 1/m).
double weibull_unit_mean(double m, std::uint64_t seed, Index i, Index j) {
  const std::uint64_t h = mix64(mix64(seed) ^ mix64((static_cast<std::uint64_t>(i) << 32) | j));
  const double u = (static_cast<double>(h >> 11) + 0.5) * 0x1.0p-53;  // in (0, 1)
  return std::pow(-std::log1p(-u), 1.0 / m) / std::tgamma(1.0 + 1.0 / m);
}

}  // namespace

long World::create_bonds(const BondParams& bp) {
  bp.validate();
  require(bp.gap_tolerance <= effective_skin(),
          cat("bond gap_tolerance = ", bp.gap_tolerance, " m must not exceed the neighbour skin ",
              effective_skin(), " m (raise skin)"));
  require(bonds_.empty(), "bonds were already created; a world is bonded once");
  ensure_forces();
  rebuild();
  const double moisture = bp.moisture_factor();
  long created = 0;
  for (std::size_t i = 0; i + 1 < nbr_.start.size(); ++i)
    for (Index k = nbr_.start[i]; k < nbr_.start[i + 1]; ++k) {
      const Index j = nbr_.j[k];
      const Vec3 d = p_.x[j] - p_.x[i];
      const double dist = d.norm();
      const double rsum = p_.r[i] + p_.r[j];
      if (!(dist < rsum + bp.gap_tolerance)) continue;  // touching, or within the gap
      Bond b;
      b.i = static_cast<Index>(i);
      b.j = j;
      b.n_prev = d / dist;
      const double r_star = p_.r[i] * p_.r[j] / rsum;
      b.radius = bp.radius * (1.0 + bp.overlap_radius_gain * std::max(nbr_.history[k].delta0, 0.0) / r_star);
      b.kn = moisture * bp.youngs_modulus / rsum;  // eq. 13
      b.kt = bp.kt_ratio * b.kn;
      const double spread = bp.weibull_modulus > 0.0
          ? weibull_unit_mean(bp.weibull_modulus, static_cast<std::uint64_t>(bp.strength_seed), b.i, j)
          : 1.0;
      b.sigma_c = moisture * spread * bp.sigma_c;
      b.tau_c = moisture * spread * bp.tau_c;
      b.softening = bp.softening;
      bonds_.push_back(b);
      ++created;
    }
  forces_valid_ = false;
  bond_map_generation_ = -1;
  return created;
}

void World::flush_slots() const {
  if (!slots_live_) return;
  for (std::size_t s = 0; s < slot_bond_.size(); ++s) {
    if (slot_bond_[s] == kNoBond) continue;
    Bond& b = bonds_[slot_bond_[s]];
    if (b.mode == BondMode::Intact) load_slot(slots_.data(), s, b);
  }
}

void World::map_bonds() {
  flush_slots();
  pair_slot_.assign(nbr_.pair_count(), 0);
  orphans_.clear();
  bonds_soften_ = false;
  std::uint8_t* live = nbr_.live.data();
  for (std::size_t k = 0; k < nbr_.pair_count(); ++k)
    live[k] &= static_cast<std::uint8_t>(~NeighborList::kLiveBond);
  for (std::size_t b = 0; b < bonds_.size(); ++b) {
    const Bond& bond = bonds_[b];
    if (bond.mode != BondMode::Intact) continue;
    if (bond.softening > 0.0 || bond.damage != 0.0) bonds_soften_ = true;
    // The pair loop's normal points from the pair's first particle (the lower index) to its
    // second, as a bond's does from i to j when i < j.
    bool listed = false;
    if (bond.i < bond.j) {
      const auto first = nbr_.j.begin() + nbr_.start[bond.i], last = nbr_.j.begin() + nbr_.start[bond.i + 1];
      const auto it = std::lower_bound(first, last, bond.j);
      if (it != last && *it == bond.j) {
        const std::size_t k = static_cast<std::size_t>(it - nbr_.j.begin());
        live[k] |= NeighborList::kLiveBonded;
        pair_slot_[k] = static_cast<Index>(b);  // the bond for now; its slot below
        listed = true;
      }
    }
    if (!listed) orphans_.push_back(static_cast<Index>(b));
  }
  // Slots in list order, so that the pair loop meets them four by four: first the pairs that
  // touched when the list was built (the pair loop's test, to the bit), then, from the next
  // block on, those apart, which go through the pair loop in a queue of their own and skip
  // the contact law while all four of a group stay apart. The grouping sets the order in which
  // the pairs' loads add up, so it is taken at the list's positions, which a saved state
  // carries, not at the positions of whenever the map is made: a restored world then groups
  // its bonds as the saved one did and resumes bit for bit.
  std::vector<Index> runs[2];  // listed bonded pairs touching at the list build, and apart
  for (std::size_t k = 0; k < nbr_.pair_count(); ++k) {
    if (!(live[k] & NeighborList::kLiveBonded)) continue;
    const Vec3 d = x_build_[nbr_.j[k]] - x_build_[nbr_.first[k]];
    const bool touch = NeighborList::touching(d.x(), d.y(), d.z(), p_.r[nbr_.first[k]] + p_.r[nbr_.j[k]]);
    runs[touch ? 0 : 1].push_back(static_cast<Index>(k));
    if (!touch) live[k] ^= NeighborList::kLiveBond;  // kLiveBonded -> kLiveBondApart
  }
  slot_bond_.clear();
  for (const std::vector<Index>& run : runs) {
    while (slot_bond_.size() % 4) slot_bond_.push_back(kNoBond);
    for (Index k : run) {
      slot_bond_.push_back(pair_slot_[k]);
      pair_slot_[k] = static_cast<Index>(slot_bond_.size() - 1);
    }
  }
  slots_.assign((slot_bond_.size() + 3) / 4, BondBlock{});
  for (std::size_t s = 0; s < slot_bond_.size(); ++s)
    if (slot_bond_[s] != kNoBond) store_slot(slots_.data(), s, bonds_[slot_bond_[s]]);
  slots_live_ = true;
  bond_map_generation_ = nbr_.generation;
}

void World::clear_samples() {
  samples_.clear();
  for (auto& ws : wall_samples_) ws.clear();
}

void World::record_sample() {
  long intact = 0;
  for (const Bond& b : bonds_) intact += b.mode == BondMode::Intact;
  samples_.push_back(Sample{time_, kinetic_energy(), coordination_number(), max_overlap_,
                            load_marker(), n_contacts_, intact,
                            static_cast<long>(broken_.size())});
  for (int k = 0; k < wall_count(); ++k) {
    const Wall& w = walls_[k];
    wall_samples_[k].push_back(
        WallSample{time_, w.force, w.normal_force(), w.point, w.radius, w.travel});
  }
}

}  // namespace pelletdem
