// The force kernels: particle pairs, bonds and walls. Everything per step that touches every
// contact is here, so this file is the one to read for speed.
#include <algorithm>
#include <cmath>
#include <omp.h>

#include "pelletdem/world.hpp"

namespace pelletdem {

namespace {

// Rolling friction of eq. 11 on one body: -m_r f_n r w/|w|, capped so that one step's torque
// cannot reverse the spin (otherwise a resting sphere chatters about w = 0).
PELLETDEM_INLINE Vec3 rolling_torque(double m_r, double fn, double r, const Vec3& w, double inv_i,
                           double dt) {
  const double wl = w.norm();
  if (m_r <= 0.0 || fn <= 0.0 || wl == 0.0) return Vec3::Zero();
  const double cap = wl / (dt * inv_i);
  return -std::min(m_r * fn * r, cap) * (w / wl);
}

struct BondResult {
  Vec3 f_on_j, t_on_i, t_on_j;
  bool broke = false;
};

// Sine and cosine of a step's twist angle: a short series for the tiny angles of a time step
// (error < 1e-15 below 0.01 rad), the library functions otherwise.
PELLETDEM_INLINE void small_angle_sin_cos(double phi, double& s, double& c) {
  if (std::abs(phi) < 1e-2) {
    const double p2 = phi * phi;
    constexpr double k6 = 1.0 / 6.0, k20 = 1.0 / 20.0, k42 = 1.0 / 42.0;
    constexpr double k12 = 1.0 / 12.0, k30 = 1.0 / 30.0;
    s = phi * (1.0 - p2 * k6 * (1.0 - p2 * k20 * (1.0 - p2 * k42)));
    c = 1.0 - 0.5 * p2 * (1.0 - p2 * k12 * (1.0 - p2 * k30));
  } else {
    s = std::sin(phi);
    c = std::cos(phi);
  }
}

// Parallel bond update, eq. 12, and breakage test, eq. 14. `dt` is the increment: zero when
// forces are recomputed in place (compute_forces' `advance`), like the contacts' springs.
// A softening bond whose capacity has fallen below this fraction of its strength is broken.
constexpr double kSofteningGone = 0.01;

PELLETDEM_INLINE BondResult update_bond(Bond& b, const Particles& p, double dt) {
  BondResult out{Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), false};
  const Index i = b.i, j = b.j;
  const Vec3 d = p.x[j] - p.x[i];
  const double dist = d.norm();
  const Vec3 n = d * (1.0 / dist);
  // Turn the stored shear force and bending moment with the pair: first the tilt of the
  // normal (the smallest rotation taking n_prev to n, R v = c v + u x v + u (u.v) / (1 + c)
  // with u = n_prev x n, c = n_prev.n: exact, no square root), then the mean spin about n.
  // A rigid rotation of the pair then leaves them as they were in the bond's own frame.
  Vec3 ft = b.ft, mt = b.mt;
  const Vec3 u = b.n_prev.cross(n);
  const double c = b.n_prev.dot(n);
  if (u.squaredNorm() > 1e-28 && c > -0.5) {  // (a reversal in one step never happens)
    const double k = 1.0 / (1.0 + c);
    ft = c * ft + u.cross(ft) + (k * u.dot(ft)) * u;
    mt = c * mt + u.cross(mt) + (k * u.dot(mt)) * u;
  }
  const double phi = 0.5 * (p.w[i] + p.w[j]).dot(n) * dt;
  if (phi != 0.0) {
    double s, cs;
    small_angle_sin_cos(phi, s, cs);
    // Rotation about n; the component along n is projected out below.
    ft = cs * ft + s * n.cross(ft);
    mt = cs * mt + s * n.cross(mt);
  }
  b.n_prev = n;

  const double half_gap = 0.5 * (dist - p.r[i] - p.r[j]);
  const double ai = p.r[i] + half_gap, aj = p.r[j] + half_gap;
  const Vec3 v_rel = p.v[j] - p.v[i] - (ai * p.w[i] + aj * p.w[j]).cross(n);
  const Vec3 w_rel = p.w[j] - p.w[i];
  const double area = b.area(), jpolar = b.polar_moment();
  const double kna = b.kn * area * dt, kta = b.kt * area * dt;
  const double ktj = b.kt * jpolar * dt, kni = b.kn * 0.5 * jpolar * dt;
  b.fn -= kna * v_rel.dot(n);
  b.mn -= ktj * w_rel.dot(n);
  // Shear and bending increments from the full relative velocities; projecting onto the plane
  // normal to n keeps their tangential parts (and removes the round-off of the rotations).
  ft -= kta * v_rel;
  mt -= kni * w_rel;
  ft -= ft.dot(n) * n;
  mt -= mt.dot(n) * n;
  b.ft = ft;
  b.mt = mt;

  // Eq. 14 times A: sigma A = -F_n + 4 |M_t| / r_b, tau A = |F_t| + 2 |M_n| / r_b. The 1-norm
  // bounds the 2-norm from above, so most bonds pass without a square root.
  const double inv_r = 1.0 / b.radius;
  const double left = 1.0 - b.damage;  // capacity left (softening bonds), 1 for brittle ones
  const double fs = left * b.sigma_c * area, ts = left * b.tau_c * area;
  const double sig_bound = -b.fn + 4.0 * inv_r * b.mt.cwiseAbs().sum();
  const double tau_bound = b.ft.cwiseAbs().sum() + 2.0 * inv_r * std::abs(b.mn);
  if (sig_bound > fs || tau_bound > ts) {
    const double sigma = b.sigma_max(), tau = b.tau_max();
    const double q = std::max(sigma / (left * b.sigma_c), tau / (left * b.tau_c));
    if (q > 1.0) {
      // Softening: the stress is returned to the shrinking capacity. Eq. 14's stresses are
      // homogeneous of degree 1 in (F_n, M_t) and (F_t, M_n), so scaling all four by
      // left_new / (left q) puts the governing one on it. This step's stretch beyond the
      // capacity, (q - 1) left sigma_c / E_b, lowers it by (q - 1) left sigma_c / s: slope
      // -E_b / s, zero at (1 + s) times the strain at the peak.
      const double left_new = (b.softening > 0.0) ? left * (1.0 - (q - 1.0) / b.softening) : 0.0;
      if (left_new < kSofteningGone) {
        b.mode = (sigma / b.sigma_c >= tau / b.tau_c) ? BondMode::Tension : BondMode::Shear;
        out.broke = true;
        return out;
      }
      const double scale = left_new / (left * q);
      b.fn *= scale;
      b.mn *= scale;
      b.ft *= scale;
      b.mt *= scale;
      b.damage = 1.0 - left_new;
    }
  }
  ft = b.ft;
  mt = b.mt;
  out.f_on_j = b.fn * n + ft;
  const Vec3 moment = b.mn * n + mt;
  const Vec3 nxft = n.cross(ft);
  out.t_on_j = -aj * nxft + moment;
  out.t_on_i = -ai * nxft - moment;
  return out;
}

}  // namespace

double World::adhesion_scale() const {
  if (ramp_duration_ < 0.0 || time_ < ramp_start_) return 1.0;
  if (ramp_duration_ == 0.0) return 0.0;
  return std::max(0.0, 1.0 - (time_ - ramp_start_) / ramp_duration_);
}

void World::compute_forces(bool advance) {
  const long n = static_cast<long>(p_.size());
  const int nt = team();
  if (static_cast<int>(buf_f_.size()) != nt - 1) {
    buf_f_.assign(nt - 1, {});
    buf_t_.assign(nt - 1, {});
  }
  for (int k = 0; k < nt - 1; ++k) {
    buf_f_[k].resize(n);
    buf_t_[k].resize(n);
  }
  const double dt = params_.dt;
  // Incremental springs advance by v dt only when the particles moved since the last force
  // evaluation; a recomputation in place (after set_velocities, a new wall, a restored state)
  // must not stretch them again.
  const double dt_inc = advance ? dt : 0.0;
  const double adh = adhesion_scale();
  const ContactLawParams& cp = law_.params();
  const Vec3 g = params_.gravity / params_.density_scale;
  const long nbonds = static_cast<long>(bonds_.size());
  std::vector<long> contacts_t(nt, 0);
  std::vector<double> maxov_t(nt, 0.0);
  std::vector<Index> maxov_i_t(nt, 0);
  std::vector<std::vector<long>> broke_t(nt);

#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    Vec3* F = tid == 0 ? p_.f.data() : buf_f_[tid - 1].data();
    Vec3* T = tid == 0 ? p_.t.data() : buf_t_[tid - 1].data();
    if (tid > 0) {
      std::fill(buf_f_[tid - 1].begin(), buf_f_[tid - 1].end(), Vec3::Zero());
      std::fill(buf_t_[tid - 1].begin(), buf_t_[tid - 1].end(), Vec3::Zero());
    }
#pragma omp for schedule(static)
    for (long i = 0; i < n; ++i) {
      p_.f[i].setZero();
      p_.t[i].setZero();
    }
    long n_contacts = 0;
    double max_ov = 0.0;
    Index max_ov_i = 0;
#pragma omp for schedule(static)
    for (long i = 0; i < n; ++i) {
      const Vec3 xi = p_.x[i];
      const double ri = p_.r[i];
      for (Index k = nbr_.start[i]; k < nbr_.start[i + 1]; ++k) {
        const Index j = nbr_.j[k];
        ContactHistory& h = nbr_.history[k];
        const Vec3 d = p_.x[j] - xi;
        const double rsum = ri + p_.r[j];
        const double dist2 = d.squaredNorm();
        if (dist2 >= rsum * rsum) {
          if (h.delta0 != 0.0 || h.ft.squaredNorm() != 0.0) h = ContactHistory{};
          continue;
        }
        const double dist = std::sqrt(dist2);
        const double delta = rsum - dist;
        const Vec3 nv = d / dist;
        const double ai = ri - 0.5 * delta, aj = p_.r[j] - 0.5 * delta;
        const Vec3 v_rel = p_.v[j] - p_.v[i] - (ai * p_.w[i] + aj * p_.w[j]).cross(nv);
        const double vn = v_rel.dot(nv);
        ContactKinematics c{delta, vn, v_rel - vn * nv, nv, ri * p_.r[j] / rsum,
                            p_.m[i] * p_.m[j] / (p_.m[i] + p_.m[j])};
        const ContactForce cf = law_.evaluate(c, h, dt_inc, cp.mu, adh);
        const Vec3 fj = cf.fn * nv + cf.ft;
        F[j] += fj;
        F[i] -= fj;
        const Vec3 nxft = nv.cross(cf.ft);
        T[i] += -ai * nxft + rolling_torque(cp.rolling, cf.fn, ri, p_.w[i], p_.inv_i[i], dt);
        T[j] += -aj * nxft + rolling_torque(cp.rolling, cf.fn, p_.r[j], p_.w[j], p_.inv_i[j], dt);
        ++n_contacts;
        const double ov = delta / std::min(ri, p_.r[j]);
        if (ov > max_ov) {
          max_ov = ov;
          max_ov_i = static_cast<Index>(ri <= p_.r[j] ? i : j);
        }
      }
    }
    if (nbonds > 0) {
#pragma omp for schedule(static)
      for (long b = 0; b < nbonds; ++b) {
        Bond& bond = bonds_[b];
        if (bond.mode != BondMode::Intact) continue;
        const BondResult r = update_bond(bond, p_, dt_inc);
        if (r.broke) {
          broke_t[tid].push_back(b);
          continue;
        }
        F[bond.j] += r.f_on_j;
        F[bond.i] -= r.f_on_j;
        T[bond.i] += r.t_on_i;
        T[bond.j] += r.t_on_j;
      }
    }
    contacts_t[tid] = n_contacts;
    maxov_t[tid] = max_ov;
    maxov_i_t[tid] = max_ov_i;
    // Reduce the thread buffers in a fixed order: the same thread count gives the same bits.
#pragma omp for schedule(static)
    for (long i = 0; i < n; ++i) {
      for (int k = 0; k < nt - 1; ++k) {
        p_.f[i] += buf_f_[k][i];
        p_.t[i] += buf_t_[k][i];
      }
      p_.f[i] += p_.m[i] * g;
    }
  }
  n_contacts_ = 0;
  max_overlap_ = 0.0;
  for (int k = 0; k < nt; ++k) {
    n_contacts_ += contacts_t[k];
    if (maxov_t[k] > max_overlap_) {
      max_overlap_ = maxov_t[k];
      max_overlap_i_ = maxov_i_t[k];
    }
  }
  // Broken bonds in bond order, whatever the thread count.
  std::vector<long> broke;
  for (int k = 0; k < nt; ++k) broke.insert(broke.end(), broke_t[k].begin(), broke_t[k].end());
  std::sort(broke.begin(), broke.end());
  const double marker = load_marker();
  for (long b : broke) {
    Bond& bond = bonds_[b];
    const Vec3 d = p_.x[bond.j] - p_.x[bond.i];
    const double dist = d.norm();
    const double half_gap = 0.5 * (dist - p_.r[bond.i] - p_.r[bond.j]);
    const Vec3 centre = p_.x[bond.i] + (p_.r[bond.i] + half_gap) * d / dist;
    // compute_forces runs after step() advanced time_ and step_: they are the breakage time.
    broken_.push_back(BrokenBond{time_, step_, bond.i, bond.j, centre, bond.mode,
                                 bond.sigma_max(), bond.tau_max(), marker});
    bond.fn = 0.0;
    bond.ft.setZero();
    bond.mn = 0.0;
    bond.mt.setZero();
  }
  wall_forces(advance);
  max_overlap_seen_ = std::max(max_overlap_seen_, max_overlap_);
}

void World::wall_forces(bool advance) {
  const double dt = params_.dt;
  const double dt_inc = advance ? dt : 0.0;
  const ContactLawParams& cp = law_.params();
  const double adh = cp.wall_adhesion ? adhesion_scale() : 0.0;
  const int nt = team();
  for (Wall& w : walls_) {
    w.force.setZero();
    w.torque.setZero();
    w.radial_force = 0.0;
    w.max_overlap_ratio = 0.0;
    if (!w.active) continue;
    const long nc = static_cast<long>(w.contacts.size());
    // Crushing caps the loading force at p_y,plate pi r^2 (kHuge / r^2 stays finite).
    const double cap_scale = (w.crushable && cp.plate_yield_stress > 0.0) ? kPi * cp.plate_yield_stress : kHuge;
    std::vector<Vec3> f_t(nt, Vec3::Zero()), tq_t(nt, Vec3::Zero());
    std::vector<double> rad_t(nt, 0.0), ov_t(nt, 0.0);
    std::vector<Index> ovi_t(nt, 0);
    // Walls see a small share of the particles; a team pays off only for long contact lists.
#pragma omp parallel num_threads(nc >= static_cast<long>(kParallelMin) ? nt : 1)
    {
      const int tid = omp_get_thread_num();
      Vec3 fsum = Vec3::Zero(), tsum = Vec3::Zero();
      double rad = 0.0, ov = 0.0;
      Index ovi = 0;
#pragma omp for schedule(static)
      for (long k = 0; k < nc; ++k) {
        WallContact& wc = w.contacts[k];
        const Index i = wc.i;
        Vec3 n_into;
        const double gap = w.gap(p_.x[i], p_.r[i], n_into);
        if (gap >= 0.0) {
          if (wc.h.delta0 != 0.0 || wc.h.ft.squaredNorm() != 0.0) wc.h = ContactHistory{};
          continue;
        }
        const double delta = -gap;
        const double a = p_.r[i] - delta;  // lever arm to the contact point on the wall
        const Vec3 v_rel = p_.v[i] - a * p_.w[i].cross(n_into) - w.surface_velocity(n_into);
        const double vn = v_rel.dot(n_into);
        ContactKinematics c{delta, vn, v_rel - vn * n_into, n_into, p_.r[i], p_.m[i], true, cap_scale * p_.r[i] * p_.r[i]};
        const ContactForce cf = law_.evaluate(c, wc.h, dt_inc, cp.mu_wall, adh);
        const Vec3 fp = cf.fn * n_into + cf.ft;
        p_.f[i] += fp;
        p_.t[i] += -a * n_into.cross(cf.ft) +
                   rolling_torque(cp.rolling, cf.fn, p_.r[i], p_.w[i], p_.inv_i[i], dt);
        const Vec3 contact_point = p_.x[i] - a * n_into;
        fsum -= fp;
        tsum += (contact_point - w.point).cross(-fp);
        rad += cf.fn;
        const double ratio = delta / p_.r[i];
        if (ratio > ov) {
          ov = ratio;
          ovi = i;
        }
      }
      f_t[tid] = fsum;
      tq_t[tid] = tsum;
      rad_t[tid] = rad;
      ov_t[tid] = ov;
      ovi_t[tid] = ovi;
    }
    for (int k = 0; k < nt; ++k) {
      w.force += f_t[k];
      w.torque += tq_t[k];
      w.radial_force += rad_t[k];
      if (ov_t[k] > w.max_overlap_ratio) {
        w.max_overlap_ratio = ov_t[k];
        w.max_overlap_particle = ovi_t[k];
      }
    }
    max_overlap_seen_ = std::max(max_overlap_seen_, w.max_overlap_ratio);
  }
}

}  // namespace pelletdem
