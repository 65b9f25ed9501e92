#pragma once
// The paper's contact law (section 3.1.1) as one small type: parameters plus pure functions
// from (geometry, per-pair history, dt) to (force, new history). Walls and particle pairs use
// the same law; only the effective radius and mass differ.
#include <algorithm>
#include <cmath>

#include "pelletdem/errors.hpp"
#include "pelletdem/vec.hpp"

namespace pelletdem {

// Per-contact history, kept in the contact table and carried across neighbour-list rebuilds.
struct ContactHistory {
  double delta0 = 0.0;        // residual (plastic) overlap delta_{n,0} of eq. 5, m
  Vec3 ft = Vec3::Zero();     // stored tangential spring force on the second body, N (eq. 9)
  bool blank() const { return delta0 == 0.0 && ft.squaredNorm() == 0.0; }
};

struct ContactLawParams {
  double k1 = 1.0e5;    // loading (plastic) stiffness, N/m (Table 4 mean)
  double k2 = 4.0e5;    // unloading/reloading (elastic) stiffness, N/m
  double kc = 600.0;    // adhesion stiffness, N/m
  double kt_ratio = 1.0;  // k_t / k1: the paper sets k_t equal to the normal stiffness
  double mu = 0.5;        // particle-particle friction coefficient
  double mu_wall = 0.15;  // particle-wall friction coefficient
  double rolling = 0.01;  // rolling friction coefficient m_r of eq. 11
  // Adhesion against walls. The paper's adhesion keeps the pellet's particles glued together;
  // a steel mould or piston that pulled particles along as it withdrew would tear the pellet's
  // skin off, so walls do not adhere unless asked to.
  bool wall_adhesion = false;
  // Wall stiffness relative to a pair of equal spheres. Eq. 7 (k1 = 5 r* p_y) has r* = r/2 for
  // two equal spheres and r* = r against a flat rigid wall, so a steel wall is twice as stiff.
  double wall_stiffness_factor = 2.0;
  // Optional viscous normal damping as a fraction of critical damping on k2. The paper has
  // none (all normal dissipation is hysteretic); 0 keeps eq. 5 exact.
  double normal_damping_ratio = 0.0;
  // Stiffness scaling with size: when true, k1, k2, kc of a pair are the values above times
  // 2 r* / r_ref (r* = ri rj / (ri + rj); r* = ri against a wall), so two spheres of radius
  // r_ref get exactly k1, as eq. 7 makes stiffness proportional to radius. Off by default:
  // Table 4 gives one mean value.
  bool scale_with_radius = false;
  double r_ref = 2.0e-4;  // reference radius for the scaling, m
  // Hardening of the loading branch at large overlap (an optional effect for the residual
  // above dh/h0 ~ 0.75): k1(delta) = k1 (1 + hardening (delta / r*)^hardening_exponent) where
  // r* is the pair's equivalent radius. 0 switches it off.
  double hardening = 0.0;
  double hardening_exponent = 1.0;
  // Unloading stiffness that grows with plastic deformation (after Luding 2008, where k2 grows
  // with the largest overlap): k2(delta0) = k2 (1 + unloading_growth delta0 / r*), delta0 the
  // residual overlap, which on the loading line grows with the largest overlap. A flattened
  // contact springs back less; 0 is the paper's constant k2. Signature: less spring-back after
  // compaction (higher relaxed density, the more so at higher pressure), loading unchanged.
  double unloading_growth = 0.0;
  // Crushing where the diametral plates touch the pellet: on walls marked crushable (the
  // plates) the loading branch is capped at plate_yield_stress * pi r^2, so a particle under a
  // plate flattens at constant force instead of stiffening. 0 switches it off. Signature: a
  // longer toe of sigma_1(dL/D), failure at larger dL/D, little change of the peak.
  double plate_yield_stress = 0.0;

  double restitution() const { return std::sqrt(k1 / k2); }  // eq. 8

  void validate() const {
    require_positive("k1", k1, "N/m");
    require_positive("k2", k2, "N/m");
    if (k2 < k1)
      throw ParameterError(cat("k2 = ", k2, " N/m is below k1 = ", k1,
                               " N/m: the unloading stiffness must satisfy k2 >= k1 (e = sqrt(k1/k2) <= 1)"));
    require_nonnegative("kc", kc, "N/m");
    require_range("kt_ratio", kt_ratio, 0.0, 10.0);
    require_range("mu", mu, 0.0, 10.0);
    require_range("mu_wall", mu_wall, 0.0, 10.0);
    require_range("rolling", rolling, 0.0, 1.0);
    require_range("wall_stiffness_factor", wall_stiffness_factor, 0.01, 100.0);
    require_range("normal_damping_ratio", normal_damping_ratio, 0.0, 1.0);
    require_positive("r_ref", r_ref, "m");
    require_range("hardening", hardening, 0.0, 1.0e4);
    require_range("hardening_exponent", hardening_exponent, 0.5, 4.0);
    require_range("unloading_growth", unloading_growth, 0.0, 1.0e4);
    require_range("plate_yield_stress", plate_yield_stress, 0.0, 1.0e12, "Pa");
  }
};

// Geometry and kinematics of one contact as the law sees it.
struct ContactKinematics {
  double delta;      // normal overlap, m (> 0 in contact)
  double vn;         // relative normal velocity, m/s (> 0 separating)
  Vec3 vt;           // relative tangential velocity of the second body, m/s
  Vec3 n;            // unit normal from the first body to the second
  double r_eff;      // equivalent radius r*, m
  double m_eff;      // equivalent mass m*, kg
  bool wall = false; // the first body is a wall
  double load_cap = kHuge;  // largest loading-branch force (crushing), N
};

struct ContactForce {
  double fn;         // normal force on the second body along n, N (> 0 repulsive)
  Vec3 ft;           // tangential force on the second body, N
};

// Linear hysteretic spring with linear adhesion (eq. 5-8), incremental Coulomb friction with a
// viscous term (eq. 9-10). Rolling friction (eq. 11) needs the bodies' spins, so the caller
// applies it from fn.
class HystereticLaw {
 public:
  explicit HystereticLaw(const ContactLawParams& p) : p_(p) {
    const double lne = std::log(p.restitution());
    // eq. 10's damping factor sqrt(4 / (1 + (pi / ln e)^2)); e = 1 means no damping.
    damping_factor_ = (lne < 0.0) ? std::sqrt(4.0 / (1.0 + (kPi / lne) * (kPi / lne))) : 0.0;
  }

  const ContactLawParams& params() const { return p_; }
  double damping_factor() const { return damping_factor_; }
  // True when pairs see the paper's law alone (no size scaling, hardening, growing k2 or
  // normal damping): the pair loop's four-lane kernel covers exactly that case.
  bool plain_pairs() const {
    return !p_.scale_with_radius && p_.hardening == 0.0 && p_.unloading_growth == 0.0 &&
           p_.normal_damping_ratio == 0.0;
  }

  // Factor on k1, k2, kc for one contact. Against a wall r_eff is the particle radius.
  PELLETDEM_INLINE double stiffness_scale(double r_eff, bool wall) const {
    if (wall) return p_.wall_stiffness_factor * (p_.scale_with_radius ? r_eff / p_.r_ref : 1.0);
    return p_.scale_with_radius ? 2.0 * r_eff / p_.r_ref : 1.0;
  }

  // Loading branch force at overlap delta (eq. 5 first line, with optional hardening).
  PELLETDEM_INLINE double loading_force(double delta, double k1, double r_eff) const {
    if (p_.hardening > 0.0)
      return k1 * delta * (1.0 + p_.hardening * std::pow(delta / r_eff, p_.hardening_exponent));
    return k1 * delta;
  }

  // Unloading stiffness at residual overlap delta0 (constant unless unloading_growth > 0).
  PELLETDEM_INLINE double unloading_stiffness(double k2, double delta0, double r_eff) const {
    return k2 * (1.0 + p_.unloading_growth * std::max(delta0, 0.0) / r_eff);
  }

  // Residual overlap that puts force f on the unloading line through delta:
  // k2 (1 + a delta0) (delta - delta0) = f with a = unloading_growth / r*, solved for the
  // root that tends to delta - f / k2 as a -> 0 (written so it does not cancel).
  PELLETDEM_INLINE double residual_for(double delta, double f, double k2, double r_eff) const {
    // f times 1/k2, not f / k2: the pair kernel hoists the reciprocal of its constant k2.
    const double c = delta - f * (1.0 / k2);
    if (p_.unloading_growth <= 0.0) return c;
    const double a = p_.unloading_growth / r_eff;
    const double b = 1.0 - a * delta;
    // a x^2 + b x - c = 0 has one positive root (c >= 0 as f <= k1 delta <= k2 delta)
    const double root = std::sqrt(std::max(b * b + 4.0 * a * c, 0.0));
    return (b > 0.0) ? 2.0 * c / (b + root) : (root - b) / (2.0 * a);
  }

  // Normal force of eq. 5; updates the residual overlap delta0 so the unloading line moves
  // with the history (Walton-Braun with Luding's adhesive branch).
  PELLETDEM_INLINE double normal_force(double delta, double& delta0, double r_eff, double adhesion_scale,
                      bool wall = false, double load_cap = kHuge) const {
    const double s = stiffness_scale(r_eff, wall);
    const double k1 = s * p_.k1, k2 = s * p_.k2, kc = s * p_.kc * adhesion_scale;
    const double k2e = unloading_stiffness(k2, delta0, r_eff);
    const double f_elastic = k2e * (delta - delta0);
    const double f_load = std::min(loading_force(delta, k1, r_eff), load_cap);
    if (f_elastic >= f_load) {
      delta0 = residual_for(delta, f_load, k2, r_eff);
      return f_load;
    }
    if (f_elastic <= -kc * delta) {
      // k2 of the step before: adhesion (kc << k2) moves delta0 too little to matter
      delta0 = delta * (1.0 + kc / k2e);
      return -kc * delta;
    }
    return f_elastic;
  }

  PELLETDEM_INLINE ContactForce evaluate(const ContactKinematics& c, ContactHistory& h, double dt, double mu,
                        double adhesion_scale) const {
    const double s = stiffness_scale(c.r_eff, c.wall);
    double fn = normal_force(c.delta, h.delta0, c.r_eff, adhesion_scale, c.wall, c.load_cap);
    if (p_.normal_damping_ratio > 0.0)
      fn -= p_.normal_damping_ratio * 2.0 * std::sqrt(c.m_eff * s * p_.k2) * c.vn;
    const double kt = s * p_.kt_ratio * p_.k1;
    // Keep the stored spring in the current tangent plane at its old length, so a rotating
    // pair neither loses nor gains spring force. Squared lengths, one root: the pair kernel's
    // throughput is bound by its roots and divisions.
    const double old2 = h.ft.squaredNorm();
    h.ft -= h.ft.dot(c.n) * c.n;
    const double new2 = h.ft.squaredNorm();
    if (new2 > 0.0) h.ft *= std::sqrt(old2 / new2);
    h.ft -= kt * dt * c.vt;  // eq. 9, incremental spring
    const double gamma_t = damping_factor_ * std::sqrt(c.m_eff * kt);  // eq. 10
    Vec3 ft = h.ft - gamma_t * c.vt;
    const double limit = mu * std::max(fn, 0.0);
    const double ft2 = ft.squaredNorm();
    if (ft2 > limit * limit) {  // Coulomb: slide, keep the spring at the limit
      ft = (ft2 > 0.0) ? Vec3(ft * (limit / std::sqrt(ft2))) : Vec3::Zero();
      h.ft = ft;
    }
    return {fn, ft};
  }

  // Elastic energy held by a contact, J: what it would give back if unloaded to zero force.
  double stored_energy(double delta, const ContactHistory& h, double r_eff,
                       bool wall = false) const {
    const double s = stiffness_scale(r_eff, wall);
    const double k2 = unloading_stiffness(s * p_.k2, h.delta0, r_eff);
    const double f = k2 * (delta - h.delta0);
    double e = (f > 0.0) ? 0.5 * f * f / k2 : 0.0;
    const double kt = s * p_.kt_ratio * p_.k1;
    if (kt > 0.0) e += 0.5 * h.ft.squaredNorm() / kt;
    return e;
  }

 private:
  ContactLawParams p_;
  double damping_factor_ = 0.0;
};

}  // namespace pelletdem
