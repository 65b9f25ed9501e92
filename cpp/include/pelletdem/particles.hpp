#pragma once
// Particle state as structure-of-arrays: each array is contiguous, so the bindings can hand
// numpy an (N, 3) view and the force loops stream through memory.
#include <vector>

#include "pelletdem/vec.hpp"

namespace pelletdem {

// A particle's position and radius in one 32-byte record. The pair loop reads both for every
// listed pair, mostly in random order; one aligned load then fetches them from one cache line
// where the x and r arrays cost two. compute_forces refreshes the records from x and r.
struct alignas(32) PosRad {
  double x, y, z, r;
};
static_assert(sizeof(PosRad) == 32, "PosRad is four packed doubles");

// What the contact kernels read of a particle besides (x, r), packed as two runs of four
// doubles in one cache line: velocity and mass, angular velocity and the cap |w| I / dt on the
// body's summed rolling-friction moment (eq. 11, see sum_loads). compute_forces (or step's drift pass) writes
// it from the particle arrays before the pairs. Inside run() it is the working copy of v and w: the drift
// pass updates them here in place and Particles::v and w are written when the run pauses
// (World::finish_pending_kick), which spares the pass two streams over the particles.
struct alignas(64) Motion {
  double vx, vy, vz, m;
  double wx, wy, wz, roll_cap;
  Vec3 v() const { return Vec3(vx, vy, vz); }
  Vec3 w() const { return Vec3(wx, wy, wz); }
  void set_v(const Vec3& a) {
    vx = a.x();
    vy = a.y();
    vz = a.z();
  }
  void set_w(const Vec3& a) {
    wx = a.x();
    wy = a.y();
    wz = a.z();
  }
};
static_assert(sizeof(Motion) == 64, "Motion is two runs of four doubles");

// A thread's sum of the contact and bond forces and torques on one particle, in one 64-byte
// record: the kernels add a pair's four results with one 32-byte load, add and store each
// (a Vec3 took three of each, after taking the lanes apart one double at a time), and a
// particle's force and torque share a cache line. compute_forces adds the threads' records
// into Particles::f and t.
// Rolling friction (eq. 11) turns every contact's moment against the body's own spin, along
// -w/|w|: the kernels add only its magnitude, `roll`, in the torque row's fourth double, and
// compute_forces turns the sum into a torque once per particle (the direction's three doubles
// per particle then never pass through the pair kernels).
struct alignas(64) Load {
  Vec3 f = Vec3::Zero();
  double unused_f = 0.0;  // stays 0: the kernels add 0 to it
  Vec3 t = Vec3::Zero();
  double roll = 0.0;  // sum of m_r f_n r over the contacts (eq. 11), N m
};
static_assert(sizeof(Load) == 64, "Load is two runs of four doubles");

// Moment of inertia of a solid sphere of mass m (kg) and radius r (m), kg m^2.
inline double sphere_inertia(double m, double r) { return 0.4 * m * r * r; }

struct Particles {
  std::vector<Vec3> x;    // position, m
  std::vector<Vec3> v;    // velocity, m/s
  std::vector<Vec3> w;    // angular velocity, rad/s
  std::vector<Vec3> f;    // force, N
  std::vector<Vec3> t;    // torque, N m
  std::vector<double> r;  // radius, m
  std::vector<double> m;  // mass (density-scaled), kg
  std::vector<double> inv_m;
  std::vector<double> inv_i;  // 1 / moment of inertia (solid sphere, 2/5 m r^2), 1/(kg m^2)

  std::size_t size() const { return r.size(); }

  void push(const Vec3& xi, double ri, double mi) {
    x.push_back(xi);
    v.push_back(Vec3::Zero());
    w.push_back(Vec3::Zero());
    f.push_back(Vec3::Zero());
    t.push_back(Vec3::Zero());
    r.push_back(ri);
    m.push_back(mi);
    inv_m.push_back(1.0 / mi);
    inv_i.push_back(1.0 / sphere_inertia(mi, ri));
  }

  double moment_of_inertia(std::size_t i) const { return 1.0 / inv_i[i]; }
};

}  // namespace pelletdem
