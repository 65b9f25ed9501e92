// Building a world: its parameters checked, particles and walls added, its settings changed.
#include "pelletdem/world.hpp"

#include <omp.h>
#include <algorithm>
#include <cmath>

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

World::World(const WorldParams& params) : r_max_(0.0), params_(params), law_(params.contact) {
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
  const double old = params_.max_overlap_ratio;
  params_.max_overlap_ratio = ratio;  // the overlaps it accepts bound the stiffest springs
  try {
    validate_time_step();
  } catch (...) {
    params_.max_overlap_ratio = old;
    throw;
  }
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
  require(x.size() == r.size(),
          cat("positions (", x.size(), ") and radii (", r.size(), ") must have the same length"));
  require(*views_ == 0,
          "cannot add particles while numpy views of the particle arrays are alive: delete "
          "them (or copy them) first, adding particles moves the arrays");
  require(bonds_.empty(), "cannot add particles after bonds were created");
  for (std::size_t k = 0; k < x.size(); ++k) {
    if (!(r[k] > 0.0) || !std::isfinite(r[k]))
      throw ParameterError(cat("radius[", k, "] = ", r[k], " m: radii must be finite and > 0"));
    if (!x[k].allFinite()) throw ParameterError(cat("position[", k, "] is not finite"));
    if (!params_.box.contains(x[k])) {
      // Name the allowed range: the box, coordinate by coordinate.
      const Box& b = params_.box;
      throw ParameterError(cat("position[", k, "] = (", x[k].x(), ", ", x[k].y(), ", ", x[k].z(),
                               ") m lies outside the domain box: allowed [", b.lo.x(), ", ", b.hi.x(),
                               "] x [", b.lo.y(), ", ", b.hi.y(), "] x [", b.lo.z(), ", ", b.hi.z(), "] m"));
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

double World::effective_skin() const { return params_.skin > 0.0 ? params_.skin : 0.1 * r_max_; }

}  // namespace pelletdem
