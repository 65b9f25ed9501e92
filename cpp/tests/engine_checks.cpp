// The engine alone, without Python: a few laws checked against closed forms. Built and run by
// ctest (scripts/ctest.sh; CI runs it): `cmake -S . -B build/ctest -DPELLETDEM_PYTHON=OFF
// -DPELLETDEM_CPP_TESTS=ON && cmake --build build/ctest && ctest --test-dir build/ctest`.
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "pelletdem/world.hpp"

using namespace pelletdem;

namespace {

int failures = 0;

void expect(bool ok, const std::string& what) {
  std::printf("%s  %s\n", ok ? "ok  " : "FAIL", what.c_str());
  if (!ok) ++failures;
}

bool close(double a, double b, double rel, double abs_tol = 0.0) {
  return std::abs(a - b) <= rel * std::abs(b) + abs_tol;
}

constexpr double kR = 2.0e-4;  // sphere radius, m

// The normal force of eq. 5 along a loading-unloading-adhesion path, one contact.
void hysteretic_law_follows_eq5() {
  ContactLawParams p;  // k1 1e5, k2 4e5, kc 600 N/m (Table 4)
  const HystereticLaw law(p);
  const double r_eff = 0.5 * kR;
  double delta0 = 0.0;
  const double d_max = 1e-6;
  for (int k = 1; k <= 10; ++k) {  // loading: f = k1 delta
    const double d = d_max * k / 10.0;
    const double f = law.normal_force(d, delta0, r_eff, 1.0);
    if (k == 10) expect(close(f, p.k1 * d, 1e-12), "loading branch: f = k1 delta");
  }
  const double d0 = d_max * (1.0 - p.k1 / p.k2);  // residual overlap where k2 (d - d0) = k1 d_max
  expect(close(delta0, d0, 1e-12), "residual overlap delta0 = delta_max (1 - k1/k2)");
  const double d = 0.9 * d_max;  // unloading: f = k2 (delta - delta0)
  expect(close(law.normal_force(d, delta0, r_eff, 1.0), p.k2 * (d - d0), 1e-12),
         "unloading branch: f = k2 (delta - delta0)");
  // Adhesion: below delta0 k2 / (k2 + kc) the unloading line falls under -kc delta, and the
  // force follows -kc delta.
  const double da = 0.99 * d0 * p.k2 / (p.k2 + p.kc);
  const double fa = law.normal_force(da, delta0, r_eff, 1.0);
  expect(close(fa, -p.kc * da, 1e-12), "adhesive branch: f = -kc delta");
  expect(std::abs(p.restitution() - 0.5) < 1e-15, "e = sqrt(k1/k2) = 0.5 (eq. 8)");
}

World make_world(const ContactLawParams& law, double dt = 1e-7) {
  WorldParams wp;
  wp.dt = dt;
  wp.gravity = Vec3::Zero();
  wp.box = Box{Vec3(-3e-3, -3e-3, -3e-3), Vec3(3e-3, 3e-3, 3e-3)};
  wp.contact = law;
  return World(wp);
}

// Two equal spheres collide head on without friction or adhesion: they leave with e = sqrt(k1/k2).
void collision_restitution() {
  ContactLawParams p;
  p.kc = 0.0;
  p.mu = 0.0;
  p.rolling = 0.0;
  World w = make_world(p);
  w.add_particles({Vec3(-kR - 1e-6, 0, 0), Vec3(kR + 1e-6, 0, 0)}, {kR, kR});
  const double v0 = 0.05;
  w.particles().v[0] = Vec3(v0, 0, 0);
  w.particles().v[1] = Vec3(-v0, 0, 0);
  w.invalidate();
  w.run(40000);
  const double e = (w.particles().v[1].x() - w.particles().v[0].x()) / (2.0 * v0);
  expect(close(e, 0.5, 1e-2), "head-on collision: restitution sqrt(k1/k2) = 0.5, got " + std::to_string(e));
}

// A sphere held by three walls 120 degrees apart, spinning: eq. 11's moments, summed over the
// body, stop it at the rate 3 m_r f_n r / I and never reverse it.
void rolling_friction_stops_a_held_spin() {
  ContactLawParams p;
  p.mu = p.mu_wall = 0.0;
  p.kc = 0.0;
  p.wall_stiffness_factor = 1.0;
  World w = make_world(p, 2e-6);
  w.add_particles({Vec3::Zero()}, {kR});
  const double delta = 1e-6;
  for (int k = 0; k < 3; ++k) {
    const double a = 2.0 * kPi * k / 3.0;
    const Vec3 n(std::cos(a), std::sin(a), 0.0);
    w.add_plane("wall" + std::to_string(k), n * (kR - delta), -n);
  }
  const double w0 = 100.0;
  w.particles().w[0] = Vec3(0, 0, w0);
  w.invalidate();
  const double inertia = w.particles().moment_of_inertia(0);
  const double rate = 3.0 * p.rolling * (p.k1 * delta) * kR / inertia;
  const long steps = static_cast<long>(0.5 * w0 / rate / w.params().dt);
  w.run(steps);
  expect(close(w.particles().w[0].z(), w0 - rate * w.time(), 1e-9),
         "held sphere spins down at 3 m_r f r / I");
  w.run(2 * steps);
  expect(std::abs(w.particles().w[0].z()) < 1e-12 * w0 && w.particles().w[0].z() >= -1e-12 * w0,
         "held sphere stops and stays stopped");
}

// A bonded pair pulled apart slowly: the bond's axial force is k_n A stretch with
// k_n = E_b / (r_i + r_j) (eq. 12-13).
void bond_axial_stiffness() {
  ContactLawParams p;
  p.kc = 0.0;
  World w = make_world(p, 1e-7);
  const double gap = 1e-6;
  w.add_particles({Vec3(-kR - 0.5 * gap, 0, 0), Vec3(kR + 0.5 * gap, 0, 0)}, {kR, kR});
  BondParams b;
  b.gap_tolerance = 2.0 * gap;
  b.sigma_c = b.tau_c = 1e12;  // unbreakable here
  w.set_dt(1e-7);
  expect(w.create_bonds(b) == 1, "one bond across the gap");
  const double v = 1e-3;  // m/s apart, each side half
  w.particles().v[0] = Vec3(-0.5 * v, 0, 0);
  w.particles().v[1] = Vec3(0.5 * v, 0, 0);
  w.invalidate();
  w.run(100);
  const double stretch = (w.particles().x[1] - w.particles().x[0]).norm() - (2.0 * kR + gap);
  const double area = kPi * b.radius * b.radius;
  const double kn = b.youngs_modulus / (2.0 * kR);
  const double fn = w.bonds()[0].fn;
  expect(close(-fn, kn * area * stretch, 2e-2), "bond axial force = k_n A stretch (eq. 12-13)");
}

// Contact hardening (an effect): the loading line is k1 delta (1 + h (delta / r*)^n).
void hardening_effect() {
  ContactLawParams p;
  p.hardening = 5.0;
  p.hardening_exponent = 2.0;
  p.validate();
  const HystereticLaw law(p);
  const double r_eff = 0.5 * kR, d = 0.2 * r_eff;
  double delta0 = 0.0;
  const double f = law.normal_force(d, delta0, r_eff, 1.0);
  expect(close(f, p.k1 * d * (1.0 + 5.0 * 0.04), 1e-12), "hardening: k1 delta (1 + h (delta/r*)^2)");
  expect(p.plain_pairs(), "the four-lane kernel takes hardening's pairs (its hooks lane by lane)");
}

// Bad parameters are refused with a message naming the parameter.
void bad_parameters_are_named() {
  ContactLawParams p;
  p.mu = -1.0;
  std::string msg;
  try {
    p.validate();
  } catch (const ParameterError& e) {
    msg = e.what();
  }
  expect(msg.find("mu = -1") != std::string::npos && msg.find("allowed 0 <= mu <= 10") != std::string::npos,
         "mu = -1 refused: " + msg);
  BondParams b;
  b.radius = 0.0;
  msg.clear();
  try {
    b.validate();
  } catch (const ParameterError& e) {
    msg = e.what();
  }
  expect(msg.find("bond radius r_b = 0 m must be a finite number > 0") != std::string::npos,
         "r_b = 0 refused: " + msg);
}

}  // namespace

int main() {
  const std::vector<std::function<void()>> checks = {
      hysteretic_law_follows_eq5, collision_restitution, rolling_friction_stops_a_held_spin,
      bond_axial_stiffness,       hardening_effect,      bad_parameters_are_named};
  for (const auto& check : checks) check();
  std::printf("%d failure(s)\n", failures);
  return failures == 0 ? 0 : 1;
}
