#pragma once
// The paper's contact law (section 3.1.1) as one small type: parameters plus pure functions
// from (geometry, per-pair history, dt) to (force, new history). Walls and particle pairs use
// the same law; only the effective radius and mass differ.
#include <algorithm>
#include <cmath>
#include <vector>

#include "pelletdem/effects_list.hpp"
#include "pelletdem/errors.hpp"
#include "pelletdem/params.hpp"
#include "pelletdem/vec.hpp"

namespace pelletdem {

// Per-contact history, kept in the contact table and carried across neighbour-list rebuilds.
struct ContactHistory {
  double delta0 = 0.0;     // residual (plastic) overlap delta_{n,0} of eq. 5, m
  Vec3 ft = Vec3::Zero();  // stored tangential spring force on the second body, N (eq. 9)
  bool blank() const { return delta0 == 0.0 && ft.squaredNorm() == 0.0; }
};

// The paper's contact law, one row per parameter (params.hpp); the candidate effects' rows
// (effects/*.hpp) follow them in ContactLawParams.
#define PELLETDEM_CONTACT_ROWS(X)                                                                            \
  X(double, k1, 1.0e5, Positive, 0.0, kHuge, "N/m", "k1", true,                                              \
    "loading (plastic) stiffness, eq. 5: Table 4 (from p_y = 100 MPa by eq. 7 with r = 0.2 mm)")             \
  X(double, k2, 4.0e5, Positive, 0.0, kHuge, "N/m", "k2", true,                                              \
    "unloading and reloading (elastic) stiffness, eq. 5: Table 4 (e = sqrt(k1/k2) = 0.5, eq. 8)")            \
  X(double, kc, 600.0, NonNegative, 0.0, kHuge, "N/m", "kc", true,                                           \
    "adhesion stiffness, eq. 5: Table 4 (ramped to 0 at bonding)")                                           \
  X(double, kt_ratio, 1.0, Range, 0.0, 10.0, "-", "kt_ratio", true,                                          \
    "tangential stiffness k_t over k1: the paper (section 3.1.1, k_t equal to the normal stiffness)")        \
  X(double, mu, 0.5, Range, 0.0, 10.0, "-", "mu", true,                                                      \
    "particle-particle friction coefficient mu_pp, eq. 9: Table 4")                                          \
  X(double, mu_wall, 0.15, Range, 0.0, 10.0, "-", "mu_wall", true,                                           \
    "particle-wall friction coefficient mu_pw: Table 4")                                                     \
  X(double, rolling, 0.01, Range, 0.0, 1.0, "-", "rolling", true,                                            \
    "rolling friction coefficient m_r, eq. 11: Table 4")                                                     \
  X(bool, wall_adhesion, false, None, 0.0, 1.0, "-", "wall_adhesion", true,                                  \
    "walls adhere too; ours: off, a withdrawing steel mould must not drag the pellet's skin along")          \
  X(double, wall_stiffness_factor, 2.0, Range, 0.01, 100.0, "-", "wall_stiffness_factor", true,              \
    "wall contact stiffness over a pair's; ours: eq. 7 with r* = r at a flat wall, r/2 between equal "       \
    "spheres")                                                                                               \
  X(double, normal_damping_ratio, 0.0, Range, 0.0, 1.0, "-", "normal_damping_ratio", false,                  \
    "viscous normal damping, fraction of critical on k2: the paper has none (dissipation is hysteretic)")    \
  X(bool, scale_with_radius, false, None, 0.0, 1.0, "-", "scale_with_radius", false,                         \
    "k1, k2, kc of a pair scaled by 2 r*/r_ref (eq. 7: stiffness proportional to size); ours: off, Table 4 " \
    "gives one mean")                                                                                        \
  X(double, r_ref, 2.0e-4, Positive, 0.0, kHuge, "m", "r_ref", true,                                         \
    "reference radius of that scaling: Table 4's mean radius")                                               \
  X(double, moisture_content, 8.0, Range, 0.0, 100.0, "%", "moisture_content", true,                         \
    "moisture content MC of the sawdust (the condition's); the bonds made in it take it too. Only the "      \
    "moisture effects read it")                                                                              \
  X(double, moisture_reference, 8.0, Range, 0.0, 100.0, "%", "moisture_reference", true,                     \
    "MC at which k1 and the bonds' E_b, sigma_c, tau_c hold: Tables 4-5 (oak, MC 8 %)")

#define PELLETDEM_CONTACT_ALL_ROWS(X) PELLETDEM_CONTACT_ROWS(X) PELLETDEM_CONTACT_EFFECT_ROWS(X)

struct ContactLawParams {
  PELLETDEM_CONTACT_ALL_ROWS(PELLETDEM_PARAM_FIELD)

  double restitution() const { return std::sqrt(k1 / k2); }  // eq. 8

  void validate() const {
    PELLETDEM_CONTACT_ALL_ROWS(PELLETDEM_PARAM_CHECK)
    if (k2 < k1)
      throw ParameterError(cat("k2 = ", k2, " N/m is below k1 = ", k1,
                               " N/m: the unloading stiffness must satisfy k2 >= k1 (e = sqrt(k1/k2) <= 1)"));
    require(ContactEffects::unloading_shapers(*this) <= 1,
            "two effects that shape the unloading stiffness are on at once: switch one off");
  }
  // True when pairs see only what the four-lane pair kernel implements: every row it lacks
  // keeps its default (no size scaling or normal damping; the contact effects' hooks it calls).
  bool plain_pairs() const { return true PELLETDEM_CONTACT_ALL_ROWS(PELLETDEM_PARAM_LANES); }
  // True when an effect on makes compaction depend on the moisture content (the relaxed
  // pellet then differs between moisture contents).
  bool moisture_acts() const { return ContactEffects::reads_moisture(*this); }
  // True when an effect on makes compaction depend on the wood's density (each material then
  // relaxes its own pellet).
  bool wood_density_acts() const { return ContactEffects::reads_wood_density(*this); }
  // True when every effect's row keeps its default: the law is the paper's.
  bool effects_off() const { return true PELLETDEM_CONTACT_EFFECT_ROWS(PELLETDEM_PARAM_AT_DEFAULT); }
  static std::vector<ParamRow> rows() { return {PELLETDEM_CONTACT_ALL_ROWS(PELLETDEM_PARAM_ROW)}; }
};

// Geometry and kinematics of one contact as the law sees it.
struct ContactKinematics {
  double delta;             // normal overlap, m (> 0 in contact)
  double vn;                // relative normal velocity, m/s (> 0 separating)
  Vec3 vt;                  // relative tangential velocity of the second body, m/s
  Vec3 n;                   // unit normal from the first body to the second
  double r_eff;             // equivalent radius r*, m
  double m_eff;             // equivalent mass m*, kg
  bool wall = false;        // the first body is a wall
  double load_cap = kHuge;  // largest loading-branch force (crushing), N
};

// Overlap / radius up to which a crushing contact's loading force stays at its cap (-).
inline constexpr double kCrushedDepth = 0.5;

struct ContactForce {
  double fn;  // normal force on the second body along n, N (> 0 repulsive)
  Vec3 ft;    // tangential force on the second body, N
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
    // With every effect's rows at their defaults (the paper's law) the hooks are skipped: they
    // would give back what they are given, at a few branches per contact.
    effects_ = !p.effects_off();
    k1_factor_ = effects_ ? ContactEffects::loading_stiffness_factor(p) : 1.0;
    mu_ = p.mu * (effects_ ? ContactEffects::friction_factor(p) : 1.0);
  }

  const ContactLawParams& params() const { return p_; }
  double damping_factor() const { return damping_factor_; }
  // The particle-particle friction coefficient of eq. 9 in force: mu times the effects' factor.
  double mu() const { return mu_; }
  // True when the pair loop's four-lane kernel covers the pairs' law: unit stiffness scale and
  // no normal damping; the effects' hooks it calls lane by lane (effects_on).
  bool plain_pairs() const { return p_.plain_pairs(); }
  // True when some effect's row is off its default, so the hooks are called.
  bool effects_on() const { return effects_; }

  // Factor on k1, k2, kc for one contact. Against a wall r_eff is the particle radius.
  PELLETDEM_INLINE double stiffness_scale(double r_eff, bool wall) const {
    if (wall) return p_.wall_stiffness_factor * (p_.scale_with_radius ? r_eff / p_.r_ref : 1.0);
    return p_.scale_with_radius ? 2.0 * r_eff / p_.r_ref : 1.0;
  }

  // Loading branch force at overlap delta (eq. 5 first line, and the effects').
  PELLETDEM_INLINE double loading_force(double delta, double k1, double r_eff) const {
    return effects_ ? ContactEffects::loading_force(p_, k1 * delta, delta, r_eff) : k1 * delta;
  }

  // Unloading stiffness at residual overlap delta0 (k2 unless an effect shapes it).
  PELLETDEM_INLINE double unloading_stiffness(double k2, double delta0, double r_eff) const {
    return effects_ ? ContactEffects::unloading_stiffness(p_, k2, delta0, r_eff) : k2;
  }

  // Residual overlap that puts force f on the unloading line through delta.
  PELLETDEM_INLINE double residual_for(double delta, double f, double k2, double r_eff) const {
    // f times 1/k2, not f / k2: the pair kernel hoists the reciprocal of its constant k2.
    const double plain = delta - f * (1.0 / k2);
    return effects_ ? ContactEffects::residual(p_, plain, delta, f, k2, r_eff) : plain;
  }

  // Largest loading force of a wall contact of a particle of radius r, N (kHuge: none).
  PELLETDEM_INLINE double wall_load_cap(double r, bool crushable) const {
    return effects_ ? ContactEffects::wall_load_cap(p_, kHuge, r, crushable) : kHuge;
  }

  // Normal force of eq. 5; updates the residual overlap delta0 so the unloading line moves
  // with the history (Walton-Braun with Luding's adhesive branch).
  PELLETDEM_INLINE double normal_force(double delta, double& delta0, double r_eff, double adhesion_scale,
                                       bool wall = false, double load_cap = kHuge) const {
    const double s = stiffness_scale(r_eff, wall);
    const double k1 = s * p_.k1 * k1_factor_, k2 = s * p_.k2, kc = s * p_.kc * adhesion_scale;
    const double k2e = unloading_stiffness(k2, delta0, r_eff);
    const double f_elastic = k2e * (delta - delta0);
    // a capped (crushing) loading branch stiffens again once the particle is crushed to
    // kCrushedDepth of its radius: the debris under the plate is compacted, and a plate that
    // met constant force forever would pass through the particle
    const double cap =
        load_cap < kHuge ? load_cap + k1 * std::max(0.0, delta - kCrushedDepth * r_eff) : kHuge;
    const double f_load = std::min(loading_force(delta, k1, r_eff), cap);
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
    h.ft -= kt * dt * c.vt;                                            // eq. 9, incremental spring
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
  double stored_energy(double delta, const ContactHistory& h, double r_eff, bool wall = false) const {
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
  bool effects_ = false;    // some effect's row is off its default
  double k1_factor_ = 1.0;  // the effects' factor on k1 (loading_stiffness_factor)
  double mu_ = 0.0;         // mu times the effects' factor on it (friction_factor)
};

}  // namespace pelletdem
