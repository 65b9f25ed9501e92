#pragma once
// The kinematics of a particle pair that its contact and its bond share, how a pair's loads
// are added to its particles, and the pair loop's statistics: one pair at a time and four.
#include "lanes.hpp"
#include "pelletdem/particles.hpp"

namespace pelletdem {

// What the pair loop reports besides the forces.
struct PairStats {
  long contacts = 0;
  double max_ov = 0.0;  // largest delta / min(r_i, r_j)
  Index max_ov_i = 0;   // the smaller particle of that pair
};

namespace {

// The kinematics of pair (i, j) that its contact and its bond share.
struct PairGeometry {
  Vec3 n;         // unit normal from i to j
  double delta;   // overlap r_i + r_j - |x_j - x_i|, m (< 0: a gap)
  double ai, aj;  // lever arms from the centres to the contact point, m
  Vec3 wi, wj;    // spins, rad/s
  Vec3 v_rel;     // velocity of j relative to i at the contact point, m/s
  double vn;      // its normal part v_rel . n, m/s
  Vec3 vt;        // its tangential part, m/s
};

PELLETDEM_INLINE PairGeometry pair_geometry(Index i, Index j, const Particles& p, const Motion* mo) {
  PairGeometry g;
  const Vec3 d = p.x[j] - p.x[i];
  const double dist = std::sqrt(d.squaredNorm());
  g.delta = (p.r[i] + p.r[j]) - dist;
  g.n = d * (1.0 / dist);
  g.ai = p.r[i] - 0.5 * g.delta;
  g.aj = p.r[j] - 0.5 * g.delta;
  g.wi = mo[i].w();
  g.wj = mo[j].w();
  g.v_rel = mo[j].v() - mo[i].v() - (g.ai * g.wi + g.aj * g.wj).cross(g.n);
  g.vn = g.v_rel.dot(g.n);
  g.vt = g.v_rel - g.vn * g.n;
  return g;
}

// A bond's loads on j: force fn n + ft and moment `moment` (the pair loop adds its contact's
// force to fn and ft before it turns them into forces and torques).
struct BondLoad {
  double fn;
  Vec3 ft, moment;
};

// Force fn n + ft on j and -(that) on i, with the torques of ft at the contact point (lever
// arms ai, aj) and the moment on j (and -moment on i), added to A.
PELLETDEM_INLINE void add_pair_load(Index i, Index j, const PairGeometry& g, double fn, const Vec3& ft,
                                    const Vec3& moment, Load* A) {
  const Vec3 f = fn * g.n + ft;
  const Vec3 nxft = g.n.cross(ft);
  A[j].f += f;
  A[i].f -= f;
  A[i].t += -g.ai * nxft - moment;
  A[j].t += -g.aj * nxft + moment;
}

#ifdef PELLETDEM_LANES
// pair_geometry of four pairs, lane by lane, with the particle values the contact law needs
// besides (masses).
struct PairLanes {
  Lane ri, rj, delta, ai, aj, mi, mj, vn;
  L3 n, wi, wj, v_rel, vt;
  LaneMask touch;  // the pair loop's touch test, to the bit
};

PELLETDEM_INLINE PairLanes pair_lanes(const Index* gi, const Index* gj, const PosRad* xr, const Motion* mo) {
  PairLanes q;
  const L4 pi = load_posrad(xr, gi), pj = load_posrad(xr, gj);
  q.ri = pi.c3;
  q.rj = pj.c3;
  const L3 d{pj.c0 - pi.c0, pj.c1 - pi.c1, pj.c2 - pi.c2};
  const Lane rsum = q.ri + q.rj;
  const Lane dist2 = lane_dot(d, d);
  q.touch = dist2 < rsum * rsum;
  Lane dist;
  for (int k = 0; k < kLanes; ++k) dist[k] = std::sqrt(dist2[k]);
  q.delta = rsum - dist;
  const Lane inv_dist = 1.0 / dist;
  q.n = {d.x * inv_dist, d.y * inv_dist, d.z * inv_dist};
  q.ai = q.ri - 0.5 * q.delta;
  q.aj = q.rj - 0.5 * q.delta;
  const L4 spin_i = load_motion(mo, gi, kRunSpin), spin_j = load_motion(mo, gj, kRunSpin);
  q.wi = {spin_i.c0, spin_i.c1, spin_i.c2};
  q.wj = {spin_j.c0, spin_j.c1, spin_j.c2};
  const L3 lever{q.ai * q.wi.x + q.aj * q.wj.x, q.ai * q.wi.y + q.aj * q.wj.y, q.ai * q.wi.z + q.aj * q.wj.z};
  const L3 lxn = lane_cross(lever, q.n);
  const L4 vel_i = load_motion(mo, gi, kRunVel), vel_j = load_motion(mo, gj, kRunVel);
  q.mi = vel_i.c3;
  q.mj = vel_j.c3;
  q.v_rel = {(vel_j.c0 - vel_i.c0) - lxn.x, (vel_j.c1 - vel_i.c1) - lxn.y, (vel_j.c2 - vel_i.c2) - lxn.z};
  q.vn = lane_dot(q.v_rel, q.n);
  q.vt = {q.v_rel.x - q.vn * q.n.x, q.v_rel.y - q.vn * q.n.y, q.v_rel.z - q.vn * q.n.z};
  return q;
}

// add_pair_load of four pairs q.
PELLETDEM_INLINE void add_pair_loads(Load* A, const Index* gi, const Index* gj, const PairLanes& q, Lane fn,
                                     const L3& ft, const L3& moment, Lane roll_i = Lane{},
                                     Lane roll_j = Lane{}) {
  const L3& n = q.n;
  const L3 f{fn * n.x + ft.x, fn * n.y + ft.y, fn * n.z + ft.z};
  const L3 nxft = lane_cross(n, ft);
  const Lane mai = -q.ai, maj = -q.aj;
  const L3 ti{mai * nxft.x - moment.x, mai * nxft.y - moment.y, mai * nxft.z - moment.z};
  const L3 tj{maj * nxft.x + moment.x, maj * nxft.y + moment.y, maj * nxft.z + moment.z};
  add_loads(A, gi, gj, f, ti, tj, roll_i, roll_j);
}

// The largest delta / min(r_i, r_j) into out, as contact_force keeps it: the division only for
// a group that may hold a new one (the bound is below max_ov by far more than the rounding, so
// none is missed).
PELLETDEM_INLINE void note_overlap(PairStats& out, Lane delta, Lane ri, Lane rj, const Index* gi,
                                   const Index* gj) {
  const Lane r_min = lane_select(rj < ri, rj, ri);
  if (lane_any(delta > (out.max_ov * (1.0 - 1e-12)) * r_min)) {
    const Lane ov = delta / r_min;
    for (int k = 0; k < kLanes; ++k)
      if (ov[k] > out.max_ov) {
        out.max_ov = ov[k];
        out.max_ov_i = ri[k] <= rj[k] ? gi[k] : gj[k];
      }
  }
}
#endif

}  // namespace
}  // namespace pelletdem
