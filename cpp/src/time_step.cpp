// The time step guard: the stiffest spring the laws can reach, over the range they allow, and
// the stability limit it sets. Velocity Verlet is stable for omega dt < 2 (sqrt(1 + zeta^2) -
// zeta) on a spring of frequency omega and damping ratio zeta; the stiffest spring on the
// lightest particle sets the limit, and the guard allows kTimeStepSafety of it.
#include <algorithm>
#include <cmath>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {
namespace {

// Velocity Verlet's limit for a spring k_eff on mass m with damping ratio zeta, s.
double verlet_limit(double k_eff, double m, double zeta) {
  if (!(k_eff > 0.0)) return HUGE_VAL;
  return 2.0 / std::sqrt(k_eff / m) * (std::sqrt(1.0 + zeta * zeta) - zeta);
}

// A spring's description with its stiffness: "<what> = <k> N/m".
std::string valued(const std::string& what, double k) { return cat(what, " = ", k, " N/m"); }

}  // namespace

std::vector<TimeStepSpring> World::time_step_springs() const {
  std::vector<TimeStepSpring> out;
  if (p_.size() == 0) return out;
  double m_min = HUGE_VAL, r_min = HUGE_VAL;
  for (std::size_t i = 0; i < p_.size(); ++i) {
    m_min = std::min(m_min, p_.m[i]);
    r_min = std::min(r_min, p_.r[i]);
  }
  const ContactLawParams& c = params_.contact;
  // Overlaps stay within max_overlap_ratio of the smaller radius (check_guards), so within
  // twice that of r* between two particles (r* >= r_min / 2): the range over which the
  // effects report their stiffest springs.
  const double x_max = 2.0 * params_.max_overlap_ratio;
  const Spring unload = ContactEffects::largest_unloading(c, {c.k2, "k2"}, x_max);
  const double factor = ContactEffects::loading_stiffness_factor(c);
  Spring load = ContactEffects::steepest_loading(
      c,
      {c.k1 * factor,
       factor == 1.0 ? std::string("k1") : cat("k1 x ", factor, " (the effects' factor on k1)")},
      x_max);
  // Eq. 5 follows the loading branch only while it lies below the unloading line through the
  // contact's state (HystereticLaw::normal_force): a steeper loading tangent is followed at
  // the unloading stiffness of that state, so the normal spring is never stiffer than the
  // largest unloading stiffness, however steep the loading branch is.
  if (load.k > unload.k) load = {unload.k, load.what + ", followed at the unloading stiffness"};
  const Spring tangential{c.kt_ratio * c.k1, "k_t = kt_ratio x k1"};
  // Eq. 7's size scaling: at most r_max / r_ref (a pair's 2 r* and a wall contact's r are
  // both <= r_max).
  const double s_r = c.scale_with_radius ? r_max_ / c.r_ref : 1.0;
  const double s_w = c.wall_stiffness_factor * s_r;
  // Normal damping is a fraction of critical on k2 (HystereticLaw::evaluate), so a fraction
  // sqrt(k2 / k) on a spring k; the tangential dashpot of eq. 10 is damping_factor sqrt(m* k_t),
  // against the spin-coupled mass m* / 3.5.
  const auto zeta_n = [&](double k) { return c.normal_damping_ratio * std::sqrt(c.k2 / k); };
  // (from the law's own restitution, so that a law being set is checked with its own)
  const double zeta_t = HystereticLaw(c).damping_factor() * std::sqrt(3.5) / 2.0;
  const auto add = [&](const std::string& what, double k, double k_eff, double zeta) {
    out.push_back({what, k, k_eff, zeta, verlet_limit(k_eff, m_min, zeta)});
  };
  // Two free spheres are twice as stiff per unit mass as one sphere on a wall of the same
  // stiffness (reduced mass m* >= m_min / 2); a tangential spring drives the spin too, which
  // raises its effective stiffness by 1 + m r^2 / I = 3.5 for a solid sphere.
  const Spring* normal[] = {&unload, &load};
  for (const Spring* n : normal) {
    const std::string kind = n == &unload ? "normal unloading stiffness " : "normal loading tangent ";
    add(valued("between two particles: " + kind + n->what, s_r * n->k), s_r * n->k, 2.0 * s_r * n->k,
        zeta_n(n->k));
    add(valued("at a wall: " + kind + "wall_stiffness_factor x " + n->what, s_w * n->k), s_w * n->k,
        s_w * n->k, zeta_n(n->k));
  }
  add(valued("between two particles: tangential " + tangential.what, s_r * tangential.k), s_r * tangential.k,
      2.0 * 3.5 * s_r * tangential.k, zeta_t);
  add(valued("at a wall: tangential wall_stiffness_factor x " + tangential.what, s_w * tangential.k),
      s_w * tangential.k, 3.5 * s_w * tangential.k, zeta_t);
  // A bond acts beside its pair's contact, so its springs add to the contact's. Its bending
  // and twisting springs turn the two spheres against each other: omega^2 = 2 K / I with
  // I >= 0.4 m_min r_min^2, i.e. a stiffness 5 K / r_min^2 on m_min.
  double axial = 0.0, shear = 0.0, turn = 0.0;
  for (const Bond& b : bonds_) {
    if (b.mode != BondMode::Intact) continue;
    axial = std::max(axial, b.kn * b.area());
    shear = std::max(shear, b.kt * b.area());
    turn = std::max({turn, 0.5 * b.kn * b.polar_moment(), b.kt * b.polar_moment()});
  }
  if (axial > 0.0 || shear > 0.0) {
    add(valued("a bond with its contact: axial E_b A / (r_i + r_j) + the normal " + unload.what,
               axial + s_r * unload.k),
        axial + s_r * unload.k, 2.0 * (axial + s_r * unload.k), zeta_n(unload.k));
    // the contact's tangential dashpot acts beside the bond: its ratio on the sum
    const double k_shear = shear + s_r * tangential.k;
    add(valued("a bond with its contact: shear kt_ratio E_b A / (r_i + r_j) + the contact's k_t", k_shear),
        k_shear, 2.0 * 3.5 * k_shear, zeta_t * std::sqrt(s_r * tangential.k / k_shear));
    add(cat("a bond: bending and twisting, 5 K / r_min^2 with K = ", turn, " N m"),
        5.0 * turn / (r_min * r_min), 5.0 * turn / (r_min * r_min), 0.0);
  }
  return out;
}

const TimeStepSpring* World::stiffest(const std::vector<TimeStepSpring>& springs) {
  const TimeStepSpring* out = nullptr;
  for (const TimeStepSpring& s : springs)
    if (!out || s.dt_limit < out->dt_limit) out = &s;
  return out;
}

double World::critical_time_step() const {
  const std::vector<TimeStepSpring> springs = time_step_springs();
  const TimeStepSpring* s = stiffest(springs);
  return s ? s->dt_limit : HUGE_VAL;
}

void World::validate_time_step() const {
  const std::vector<TimeStepSpring> springs = time_step_springs();
  const TimeStepSpring* s = stiffest(springs);
  if (s && params_.dt > kTimeStepSafety * s->dt_limit)
    throw ParameterError(
        cat("dt = ", params_.dt, " s is above the stable time step: allowed 0 < dt <= ",
            kTimeStepSafety * s->dt_limit, " s, ", kTimeStepSafety, " of the stability limit ", s->dt_limit,
            " s of the stiffest spring the laws can reach, ", s->what,
            " (on the lightest particle; see World.time_step_springs()). Lower dt, or soften "
            "that spring (one that grows with overlap also by a lower max_overlap_ratio), or "
            "raise density_scale"));
  guard_stale_ = false;
}

}  // namespace pelletdem
