// What a world measures of itself: energies, momentum, the load walls' marker and force,
// coordination number, the contacts, and the sampled time series.
#include <algorithm>
#include <cmath>

#include "pelletdem/world.hpp"

namespace pelletdem {

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

void World::clear_samples() {
  samples_.clear();
  for (auto& ws : wall_samples_) ws.clear();
}

void World::record_sample() {
  long intact = 0;
  for (const Bond& b : bonds_) intact += b.mode == BondMode::Intact;
  samples_.push_back(Sample{time_, kinetic_energy(), coordination_number(), max_overlap_, load_marker(),
                            n_contacts_, intact, static_cast<long>(broken_.size())});
  for (int k = 0; k < wall_count(); ++k) {
    const Wall& w = walls_[k];
    wall_samples_[k].push_back(WallSample{time_, w.force, w.normal_force(), w.point, w.radius, w.travel});
  }
}

}  // namespace pelletdem
