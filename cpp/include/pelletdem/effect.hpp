#pragma once
// Candidate effects: optional parts of the contact and bond laws that the paper's model lacks,
// each off at its defaults so that the baseline is the paper's model exactly. An effect is one
// header in pelletdem/effects/ (docs/adding-an-effect.md):
//
//   #define PELLETDEM_ROWS_MyEffect(X) X(double, my_strength, 0.0, Range, 0.0, 10.0, "-", ...)
//   struct MyEffect : ContactEffect { ...the hooks it changes, as static functions... };
//   PELLETDEM_CONTACT_EFFECT(MyEffect)
//
// Its rows join the law's parameter table (params.hpp) and its hooks are called where the law
// has a hook point (below). The build finds the header by its registration line and lists it
// in the generated pelletdem/effects_list.hpp: no other file names it.
#include <algorithm>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>

#include "pelletdem/vec.hpp"

namespace pelletdem {

// One spring a law can produce: its largest stiffness and what sets it, in the parameters'
// names, for the time step guard and its messages (World::time_step_springs).
struct Spring {
  double k;          // N/m
  std::string what;  // e.g. "k_p = plastic_stiffness_ratio x k2"
};

// The contact law's hook points (HystereticLaw). Each receives the law's parameters `p` and
// the value the law has so far, and returns it unchanged unless the effect is switched on.
struct ContactEffect {
  // Loading-branch force of eq. 5 at overlap delta (m), given f = k1 delta (N); r_eff: r* (m).
  template <class P>
  static double loading_force(const P&, double f, double /*delta*/, double /*r_eff*/) {
    return f;
  }
  // Factor on k1 of every contact, constant for the law: evaluated once, when the law is made.
  template <class P>
  static double loading_stiffness_factor(const P&) {
    return 1.0;
  }
  // Factor on the particle-particle friction coefficient mu (eq. 9; walls keep mu_wall),
  // constant for the law: evaluated once, when the law is made.
  template <class P>
  static double friction_factor(const P&) {
    return 1.0;
  }
  // True when the effect makes the unloading stiffness depend on the contact's history (one
  // such effect at a time: its `residual` must solve for its own stiffness).
  template <class P>
  static bool shapes_unloading(const P&) {
    return false;
  }
  // Unloading stiffness (N/m) at residual overlap delta0 (m), given the law's k2.
  template <class P>
  static double unloading_stiffness(const P&, double k2, double /*delta0*/, double /*r_eff*/) {
    return k2;
  }
  // The residual overlap (m) that puts force f on the unloading line through delta; `plain`
  // is the answer for a constant k2, delta - f / k2.
  template <class P>
  static double residual(const P&, double plain, double /*delta*/, double /*f*/, double /*k2*/,
                         double /*r_eff*/) {
    return plain;
  }
  // True when the effect, as set, reads the moisture content.
  template <class P>
  static bool reads_moisture(const P&) {
    return false;
  }
  // True when the effect, as set, reads the intact wood's density (wood_density).
  template <class P>
  static bool reads_wood_density(const P&) {
    return false;
  }
  // Largest loading force (N) of a wall contact of a particle of radius r (m), given the cap
  // so far; `crushable`: the wall is one of the diametral plates (Wall::crushable).
  template <class P>
  static double wall_load_cap(const P&, double cap, double /*r*/, bool /*crushable*/) {
    return cap;
  }
  // The largest unloading stiffness (N/m) the effect can give a contact whose overlap stays
  // within x_max r*, given the law's so far (`k2`): the time step guard's stiffest spring. An
  // effect that shapes the unloading stiffness must report its largest here.
  template <class P>
  static Spring largest_unloading(const P&, Spring k2, double /*x_max*/) {
    return k2;
  }
  // The loading branch's steepest tangent dF/d(delta) (N/m) up to overlap x_max r*, given the
  // law's so far (`k1`, with the loading_stiffness_factor in it). An effect that shapes the
  // loading force must report its steepest here. The guard takes a loading tangent steeper
  // than the unloading stiffness to be followed at the latter: true on loading, and on
  // unloading where the loading branch is convex or capped (hardening, the crushing cap), so
  // that a contact that unloads never comes back onto it below its unloading line. A concave
  // loading branch must report itself as the normal spring instead.
  template <class P>
  static Spring steepest_loading(const P&, Spring k1, double /*x_max*/) {
    return k1;
  }
};

// The bond law's hook points: when a bond is made (World::create_bonds) and when it is
// loaded past its strength (the bond kernel).
struct BondEffect {
  // The bond's radius (m) given r_b, the pair's residual overlap delta0 (m) and r* (m).
  template <class P>
  static double radius(const P&, double r_b, double /*delta0*/, double /*r_eff*/) {
    return r_b;
  }
  // Factor on E_b (and so on k_n, k_t) of every bond.
  template <class P>
  static double stiffness_factor(const P&) {
    return 1.0;
  }
  // Factor on sigma_c and tau_c of the bond between particles i and j.
  template <class P>
  static double strength_factor(const P&, Index /*i*/, Index /*j*/) {
    return 1.0;
  }
  // Anything else the effect keeps in the bond record (a Bond), set when it is made.
  template <class P, class B>
  static void init(const P&, B&) {}
  // A bond (a Bond) loaded to q > 1 times the capacity it has left (`left`, a fraction of its
  // strength): the capacity left after this step, given `after` (0: it breaks, eq. 14).
  template <class B>
  static double capacity_after_overload(const B&, double after, double /*left*/, double /*q*/) {
    return after;
  }
};

// The effects of one law, each hook called on them in turn (in the order of their headers'
// names).
template <class... E>
struct EffectList {
  template <class P>
  static double loading_force(const P& p, double f, double delta, double r_eff) {
    ((f = E::loading_force(p, f, delta, r_eff)), ...);
    return f;
  }
  template <class P>
  static double loading_stiffness_factor(const P& p) {
    double f = 1.0;
    ((f *= E::loading_stiffness_factor(p)), ...);
    return f;
  }
  template <class P>
  static double friction_factor(const P& p) {
    double f = 1.0;
    ((f *= E::friction_factor(p)), ...);
    return f;
  }
  template <class P>
  static int unloading_shapers(const P& p) {
    return (0 + ... + static_cast<int>(E::shapes_unloading(p)));
  }
  template <class P>
  static bool reads_moisture(const P& p) {
    return (false || ... || E::reads_moisture(p));
  }
  template <class P>
  static bool reads_wood_density(const P& p) {
    return (false || ... || E::reads_wood_density(p));
  }
  template <class P>
  static double unloading_stiffness(const P& p, double k2, double delta0, double r_eff) {
    ((k2 = E::unloading_stiffness(p, k2, delta0, r_eff)), ...);
    return k2;
  }
  template <class P>
  static double residual(const P& p, double plain, double delta, double f, double k2, double r_eff) {
    double d0 = plain;
    ((d0 = E::residual(p, d0, delta, f, k2, r_eff)), ...);
    return d0;
  }
  template <class P>
  static double wall_load_cap(const P& p, double cap, double r, bool crushable) {
    ((cap = E::wall_load_cap(p, cap, r, crushable)), ...);
    return cap;
  }
  template <class P>
  static Spring largest_unloading(const P& p, Spring k2, double x_max) {
    ((k2 = E::largest_unloading(p, std::move(k2), x_max)), ...);
    return k2;
  }
  template <class P>
  static Spring steepest_loading(const P& p, Spring k1, double x_max) {
    ((k1 = E::steepest_loading(p, std::move(k1), x_max)), ...);
    return k1;
  }
  template <class P>
  static double radius(const P& p, double r_b, double delta0, double r_eff) {
    ((r_b = E::radius(p, r_b, delta0, r_eff)), ...);
    return r_b;
  }
  template <class P>
  static double stiffness_factor(const P& p) {
    double f = 1.0;
    ((f *= E::stiffness_factor(p)), ...);
    return f;
  }
  template <class P>
  static double strength_factor(const P& p, Index i, Index j) {
    double f = 1.0;
    ((f *= E::strength_factor(p, i, j)), ...);
    return f;
  }
  template <class P, class B>
  static void init(const P& p, B& b) {
    (E::init(p, b), ...);
  }
  template <class B>
  static double capacity_after_overload(const B& b, double left, double q) {
    double after = 0.0;
    ((after = E::capacity_after_overload(b, after, left, q)), ...);
    return after;
  }
};

}  // namespace pelletdem

// An effect's registration line, at the end of its header: the build lists the header's type
// under its law (CMakeLists.txt reads these lines).
#define PELLETDEM_CONTACT_EFFECT(Type) \
  static_assert(std::is_base_of_v<::pelletdem::ContactEffect, ::pelletdem::Type>);
#define PELLETDEM_BOND_EFFECT(Type) \
  static_assert(std::is_base_of_v<::pelletdem::BondEffect, ::pelletdem::Type>);
