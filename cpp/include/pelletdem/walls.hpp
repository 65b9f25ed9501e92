#pragma once
// Analytic walls: an infinite plane, or the inside of a z-aligned cylinder. Analytic walls hold
// a particle at any overlap (the signed distance never flips sign the way a triangle mesh's
// side test can), which compaction to 120 MPa needs.
#include <string>
#include <vector>

#include "pelletdem/contact_law.hpp"
#include "pelletdem/vec.hpp"

namespace pelletdem {

enum class WallKind { Plane, Cylinder };

struct WallContact {
  Index i;
  ContactHistory h;
};

struct Wall {
  std::string name;
  WallKind kind = WallKind::Plane;
  Vec3 point = Vec3::Zero();     // plane: a point on it; cylinder: a point on the axis, m
  Vec3 normal = Vec3::UnitZ();   // plane: unit normal pointing into the particles' side
  double radius = 0.0;           // cylinder radius, m
  Vec3 velocity = Vec3::Zero();  // prescribed translation velocity, m/s
  double radius_rate = 0.0;      // cylinder: dR/dt, m/s
  bool active = true;

  // Servo (optional): move along the normal so that the normal force on the wall tends to
  // servo_force; speed = servo_gain * (servo_force - F_n), clipped to servo_max_speed.
  bool servo = false;
  double servo_force = 0.0;      // N, compressive force on the wall (> 0)
  double servo_gain = 0.0;       // m/(s N)
  double servo_max_speed = 0.0;  // m/s

  // Results of the last force evaluation.
  Vec3 force = Vec3::Zero();       // total force the particles exert on the wall, N
  Vec3 torque = Vec3::Zero();      // about `point`, N m
  double max_overlap_ratio = 0.0;  // largest delta / r among its contacts this step
  Index max_overlap_particle = 0;

  // Motion since the last neighbour rebuild, for the rebuild criterion.
  double moved_since_build = 0.0;
  double travel = 0.0;     // displacement along the normal since creation, m (> 0 into the particles)
  bool load_wall = false;  // counts in the world's load marker
  // Contacts with this wall obey the contact law's plate_yield_stress (the diametral plates).
  bool crushable = false;

  std::vector<WallContact> contacts;  // candidates within r + skin, sorted by particle

  // Signed gap between the particle surface and the wall: < 0 means overlap. Also returns
  // the unit normal pointing from the wall towards the particle centre.
  double gap(const Vec3& x, double r, Vec3& n_into) const {
    if (kind == WallKind::Plane) {
      n_into = normal;
      return (x - point).dot(normal) - r;
    }
    Vec3 d = x - point;
    d.z() = 0.0;
    const double rho = d.norm();
    n_into = (rho > 0.0) ? Vec3(-d / rho) : Vec3(-Vec3::UnitX());
    return radius - rho - r;
  }

  // Velocity of the wall's surface at point c (translation plus radial growth).
  Vec3 surface_velocity(const Vec3& n_into) const {
    if (kind == WallKind::Cylinder) return velocity - radius_rate * n_into;
    return velocity;
  }

  // Normal force component: compressive force on the wall along -normal (plane) or outward
  // (cylinder: the radial load is the sum of magnitudes, kept in `radial_force`).
  double normal_force() const { return kind == WallKind::Plane ? -force.dot(normal) : radial_force; }
  double radial_force = 0.0;  // cylinder: sum of the outward normal force magnitudes, N

  void validate() const;
};

}  // namespace pelletdem
