// The walls' share of the force pass: each thread's wall contacts (the contact law of eq. 5-11
// with the wall as the first body) into its Load buffer and its part of each wall's force, and
// the parts added up in thread order.
#include <algorithm>
#include <cmath>

#include "contact_kernel.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

int World::start_walls(int nt) {
  long listed = 0;
  for (Wall& w : walls_) {
    w.force.setZero();
    w.torque.setZero();
    w.radial_force = 0.0;
    w.max_overlap_ratio = 0.0;
    if (w.active) listed += static_cast<long>(w.contacts.size());
  }
  // Below kWallParallelMin listed contacts in all, one thread is faster than a team.
  constexpr long kWallParallelMin = 512;
  const int nt_walls = listed >= kWallParallelMin ? nt : 1;
  const std::size_t slots = walls_.size() * static_cast<std::size_t>(nt_walls);
  wall_part_.assign(slots, WallPart{});
  return nt_walls;
}

void World::wall_share(int tid, int nt_walls, long p_lo, long p_hi, double dt_inc, Load* A) {
  const ContactLawParams& cp = law_.params();
  const double adh = cp.wall_adhesion ? adhesion_scale() : 0.0;
  const int nw = wall_count();
  for (int wk = 0; wk < nw; ++wk) {
    Wall& w = walls_[wk];
    if (!w.active) continue;
    // The contacts are in particle order: those of particles [p_lo, p_hi).
    auto first_of = [&](long i) {
      return std::lower_bound(w.contacts.begin(), w.contacts.end(), i,
                              [](const WallContact& c, long v) { return c.i < v; }) -
             w.contacts.begin();
    };
    const long lo = first_of(p_lo), hi = first_of(p_hi);
    WallPart& part = wall_part_[static_cast<std::size_t>(wk) * nt_walls + tid];
    for (long k = lo; k < hi; ++k) {
      WallContact& wc = w.contacts[k];
      const Index i = wc.i;
      Vec3 n_into;
      const double gap = w.gap(p_.x[i], p_.r[i], n_into);
      if (gap >= 0.0) {
        if (!wc.h.blank()) wc.h = ContactHistory{};
        continue;
      }
      const double delta = -gap;
      const double a = p_.r[i] - delta;  // lever arm to the contact point on the wall
      const Vec3 v_rel = mo_[i].v() - a * mo_[i].w().cross(n_into) - w.surface_velocity(n_into);
      const double vn = v_rel.dot(n_into);
      ContactKinematics c{delta,
                          vn,
                          v_rel - vn * n_into,
                          n_into,
                          p_.r[i],
                          p_.m[i],
                          true,
                          law_.wall_load_cap(p_.r[i], w.crushable)};
      const ContactForce cf = law_.evaluate(c, wc.h, dt_inc, cp.mu_wall, adh);
      const Vec3 fp = cf.fn * n_into + cf.ft;
      A[i].f += fp;
      A[i].t += -a * n_into.cross(cf.ft);
      A[i].roll += rolling_moment(cp.rolling, cf.fn, p_.r[i]);
      const Vec3 contact_point = p_.x[i] - a * n_into;
      part.force -= fp;
      part.torque += (contact_point - w.point).cross(-fp);
      part.radial += cf.fn;
      const double ratio = delta / p_.r[i];
      if (ratio > part.max_ov) {
        part.max_ov = ratio;
        part.max_ov_i = i;
      }
    }
  }
}

void World::finish_walls(int nt_walls) {
  // Thread sums in a fixed order: the same thread count gives the same bits.
  for (int wk = 0; wk < wall_count(); ++wk) {
    Wall& w = walls_[wk];
    if (!w.active) continue;
    for (int k = 0; k < nt_walls; ++k) {
      const WallPart& part = wall_part_[static_cast<std::size_t>(wk) * nt_walls + k];
      w.force += part.force;
      w.torque += part.torque;
      w.radial_force += part.radial;
      if (part.max_ov > w.max_overlap_ratio) {
        w.max_overlap_ratio = part.max_ov;
        w.max_overlap_particle = part.max_ov_i;
      }
    }
    max_overlap_seen_ = std::max(max_overlap_seen_, w.max_overlap_ratio);
  }
}

}  // namespace pelletdem
