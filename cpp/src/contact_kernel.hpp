#pragma once
// The contact kernel of eq. 5-11, one pair at a time and four at a time on lanes (the same
// bits either way), and a bonded pair's contact and bond together.
#include <algorithm>
#include <cmath>

#include "bond_kernel.hpp"
#include "lanes.hpp"
#include "pair_kinematics.hpp"
#include "pelletdem/contact_law.hpp"

namespace pelletdem {
namespace {

// Magnitude of one contact's rolling-friction moment on one body, eq. 11: m_r f_n r for a
// compressive contact. The moments of all of a body's contacts are summed and turned along
// -w/|w| once per body, where the sum is capped (sum_loads).
PELLETDEM_INLINE double rolling_moment(double m_r, double fn, double r) {
  return (m_r > 0.0 && fn > 0.0) ? m_r * fn * r : 0.0;
}

// The contact force of eq. 5-10 of the touching pair (i, j) with kinematics g and history h;
// the pair counts in the loop's statistics.
PELLETDEM_INLINE ContactForce contact_force(Index i, Index j, ContactHistory& h, const PairGeometry& g,
                                            const Particles& p, const HystereticLaw& law, double dt_inc,
                                            double adh, PairStats& out) {
  const double ri = p.r[i], rj = p.r[j];
  ContactKinematics c{g.delta, g.vn, g.vt, g.n, ri * rj / (ri + rj), p.m[i] * p.m[j] / (p.m[i] + p.m[j])};
  const ContactForce cf = law.evaluate(c, h, dt_inc, law.mu(), adh);
  ++out.contacts;
  const double ov = g.delta / std::min(ri, rj);
  if (ov > out.max_ov) {
    out.max_ov = ov;
    out.max_ov_i = static_cast<Index>(ri <= rj ? i : j);
  }
  return cf;
}

// One touching pair (i, j) with its history h: the contact force of eq. 5-11 added to A.
PELLETDEM_INLINE void contact_one(Index i, Index j, ContactHistory& h, const Particles& p,
                                  const HystereticLaw& law, const ContactLawParams& cp, double dt_inc,
                                  double adh, const Motion* mo, Load* A, PairStats& out) {
  const PairGeometry g = pair_geometry(i, j, p, mo);
  const ContactForce cf = contact_force(i, j, h, g, p, law, dt_inc, adh, out);
  const Vec3 fj = cf.fn * g.n + cf.ft;
  A[j].f += fj;
  A[i].f -= fj;
  const Vec3 nxft = g.n.cross(cf.ft);
  A[i].t += -g.ai * nxft;
  A[i].roll += rolling_moment(cp.rolling, cf.fn, p.r[i]);
  A[j].t += -g.aj * nxft;
  A[j].roll += rolling_moment(cp.rolling, cf.fn, p.r[j]);
}

// A bonded pair (i, j): its contact force where it touches (`on`) and its bond b, added to A
// together. Returns true when the bond broke (its share is then left out).
PELLETDEM_INLINE bool bonded_one(Index i, Index j, bool on, ContactHistory& h, Bond& b, const Particles& p,
                                 const HystereticLaw& law, const ContactLawParams& cp, double dt_inc,
                                 double adh, const Motion* mo, Load* A, PairStats& out) {
  const PairGeometry g = pair_geometry(i, j, p, mo);
  const ContactForce cf =
      on ? contact_force(i, j, h, g, p, law, dt_inc, adh, out) : ContactForce{0.0, Vec3::Zero()};
  BondLoad bl;
  const bool broke = bond_one(b, g, dt_inc, bl);
  if (broke) bl = BondLoad{0.0, Vec3::Zero(), Vec3::Zero()};
  // The contact's and the bond's normal and tangential forces act at the same point.
  add_pair_load(i, j, g, cf.fn + bl.fn, cf.ft + bl.ft, bl.moment, A);
  A[i].roll += rolling_moment(cp.rolling, cf.fn, p.r[i]);
  A[j].roll += rolling_moment(cp.rolling, cf.fn, p.r[j]);
  return broke;
}

#ifdef PELLETDEM_LANES
// Eq. 5 and 9-10 on four pairs q with histories hist, one per lane: contact_force's operations
// in the same order (Eigen's expressions written out component by component), with its
// branches as selects, for pairs of unit stiffness scale without normal damping
// (HystereticLaw::plain_pairs); with an effect on, the normal force of eq. 5 is the scalar
// law's, lane by lane. Out: the normal force fn, the tangential
// force ft and the new history (delta0, hft).
PELLETDEM_INLINE void contact_law_lanes(const PairLanes& q, const L4& hist, const HystereticLaw& law,
                                        double dt_inc, double adh, Lane& fn, L3& ft, Lane& delta0, L3& hft) {
  const L3& nv = q.n;
  const Lane delta = q.delta;
  const L3& vt = q.vt;
  const Lane m_eff = q.mi * q.mj / (q.mi + q.mj);

  delta0 = hist.c0;
  hft = {hist.c1, hist.c2, hist.c3};
  const ContactLawParams& lp = law.params();
  const double s = 1.0;
  if (law.effects_on()) {
    // Eq. 5 with the effects' hooks: the law's own normal force, lane by lane (the hooks
    // branch on the history and take powers and roots, which selects would all evaluate). A
    // lane apart (in a bonded group: the pair loop's touch test, to the bit) keeps its
    // history; its force is discarded by the caller.
    for (int l = 0; l < kLanes; ++l) {
      if (!q.touch[l]) {
        fn[l] = 0.0;
        continue;
      }
      double d0 = delta0[l];
      fn[l] = law.normal_force(delta[l], d0, q.ri[l] * q.rj[l] / (q.ri[l] + q.rj[l]), adh);
      delta0[l] = d0;
    }
  } else {
    // Eq. 5 (HystereticLaw::normal_force with scale 1 and constant k2).
    const double k1 = s * lp.k1, k2 = s * lp.k2, kc = s * lp.kc * adh;
    const Lane f_elastic = k2 * (delta - delta0);
    const Lane kd = k1 * delta;
    const Lane f_load = lane_select(kHuge < kd, Lane{} + kHuge, kd);  // std::min(k1 delta, kHuge)
    const LaneMask loading = f_elastic >= f_load;
    const LaneMask sticking = ~loading & (f_elastic <= -kc * delta);
    fn = lane_select(loading, f_load, lane_select(sticking, -kc * delta, f_elastic));
    delta0 = lane_select(loading, delta - f_load * (1.0 / k2),
                         lane_select(sticking, delta * (1.0 + kc / k2), delta0));
  }

  // Eq. 9-10 (HystereticLaw::evaluate).
  const double kt = s * lp.kt_ratio * lp.k1;
  const Lane old2 = lane_dot(hft, hft);
  const Lane along = lane_dot(hft, nv);
  hft = {hft.x - along * nv.x, hft.y - along * nv.y, hft.z - along * nv.z};
  const Lane new2 = lane_dot(hft, hft);
  const LaneMask keep = new2 > 0.0;
  const Lane ratio = old2 / lane_select(keep, new2, Lane{} + 1.0);
  Lane r_keep;
  for (int k = 0; k < kLanes; ++k) r_keep[k] = std::sqrt(ratio[k]);
  hft = lane_select(keep, L3{hft.x * r_keep, hft.y * r_keep, hft.z * r_keep}, hft);
  const double ktdt = kt * dt_inc;
  hft = {hft.x - ktdt * vt.x, hft.y - ktdt * vt.y, hft.z - ktdt * vt.z};
  const Lane mk = m_eff * kt;
  Lane root;
  for (int k = 0; k < kLanes; ++k) root[k] = std::sqrt(mk[k]);
  const Lane gamma_t = law.damping_factor() * root;
  ft = {hft.x - gamma_t * vt.x, hft.y - gamma_t * vt.y, hft.z - gamma_t * vt.z};
  const Lane limit = law.mu() * lane_select(fn < 0.0, Lane{}, fn);  // mu std::max(fn, 0)
  const Lane ft2 = lane_dot(ft, ft);
  const LaneMask slide = ft2 > limit * limit;
  if (lane_any(slide)) {
    Lane ft_len;
    for (int k = 0; k < kLanes; ++k) ft_len[k] = std::sqrt(ft2[k]);
    const LaneMask some = ft2 > 0.0;
    const Lane r = limit / lane_select(some, ft_len, Lane{} + 1.0);
    const L3 capped = lane_select(some, L3{ft.x * r, ft.y * r, ft.z * r}, L3{Lane{}, Lane{}, Lane{}});
    ft = lane_select(slide, capped, ft);
    hft = lane_select(slide, capped, hft);
  }
}

// Eq. 11's moment on each body of four contacts (rolling_moment): zero where it does not apply.
PELLETDEM_INLINE Lane roll_lanes(const ContactLawParams& cp, Lane fn, Lane r) {
  const LaneMask on = (cp.rolling > 0.0 ? ~LaneMask{} : LaneMask{}) & (fn > 0.0);
  return lane_select(on, cp.rolling * fn * r, Lane{});
}

// Four touching pairs, one per lane, as contact_one (for HystereticLaw::plain_pairs). The
// forces are added pair by pair in order, so the bits are contact_one's.
PELLETDEM_INLINE void contact_group(const Index* gi, const Index* gj, ContactHistory* const* gh,
                                    const PosRad* xr, const Motion* mo, const HystereticLaw& law,
                                    const ContactLawParams& cp, double dt_inc, double adh, Load* A,
                                    PairStats& out) {
  static_assert(sizeof(ContactHistory) == 4 * sizeof(double) && offsetof(ContactHistory, ft) == 8,
                "ContactHistory is (delta0, ft) as four doubles");
  const PairLanes q = pair_lanes(gi, gj, xr, mo);
  const L4 hist = load_run(gh, 0);
  Lane fn, delta0;
  L3 ft, hft;
  contact_law_lanes(q, hist, law, dt_inc, adh, fn, ft, delta0, hft);
  store_run(gh, 0, delta0, hft.x, hft.y, hft.z);
  const L3& nv = q.n;
  const L3 fj{fn * nv.x + ft.x, fn * nv.y + ft.y, fn * nv.z + ft.z};
  const L3 nxft = lane_cross(nv, ft);
  const Lane mai = -q.ai, maj = -q.aj;
  const L3 ti{mai * nxft.x, mai * nxft.y, mai * nxft.z}, tj{maj * nxft.x, maj * nxft.y, maj * nxft.z};
  add_loads(A, gi, gj, fj, ti, tj, roll_lanes(cp, fn, q.ri), roll_lanes(cp, fn, q.rj));
  out.contacts += kLanes;
  note_overlap(out, q.delta, q.ri, q.rj, gi, gj);
}

// Four bonded pairs, one per lane, whose bonds are the four slots of block `k`, as bonded_one:
// the contact (where the pair touches) and the bond share the pair's kinematics and one load
// and store per particle. `left`: the bonds' capacity left (bonds_left). Returns false,
// having changed nothing, when a bond needs the scalar path.
PELLETDEM_INLINE bool bonded_group(const Index* gi, const Index* gj, ContactHistory* const* gh, BondBlock& k,
                                   Lane left, const PosRad* xr, const Motion* mo, const HystereticLaw& law,
                                   const ContactLawParams& cp, double dt_inc, double adh, Load* A,
                                   PairStats& out) {
  const PairLanes q = pair_lanes(gi, gj, xr, mo);
  BondLanes bl;
  if (!bond_lanes(BondSlots(k), q, dt_inc, left, bl)) return false;
  const LaneMask on = q.touch;
  const unsigned touching = lane_bits(on);
  Lane fn{};
  L3 ft{Lane{}, Lane{}, Lane{}};
  if (touching) {
    const L4 hist = load_run(gh, 0);
    Lane delta0;
    L3 hft;
    contact_law_lanes(q, hist, law, dt_inc, adh, fn, ft, delta0, hft);
    if (touching != (1u << kLanes) - 1) {
      // A pair apart has no contact force, and keeps its (cleared) history.
      fn = lane_select(on, fn, Lane{});
      ft = lane_select(on, ft, L3{Lane{}, Lane{}, Lane{}});
      delta0 = lane_select(on, delta0, hist.c0);
      hft = lane_select(on, hft, L3{hist.c1, hist.c2, hist.c3});
    }
    store_run(gh, 0, delta0, hft.x, hft.y, hft.z);
  }
  // The contact's and the bond's normal and tangential forces act at the same point.
  add_pair_loads(A, gi, gj, q, fn + bl.fn, L3{ft.x + bl.ft.x, ft.y + bl.ft.y, ft.z + bl.ft.z}, bl.moment,
                 roll_lanes(cp, fn, q.ri), roll_lanes(cp, fn, q.rj));
  out.contacts += __builtin_popcount(touching);
  note_overlap(out, q.delta, q.ri, q.rj, gi, gj);
  return true;
}
#endif

}  // namespace
}  // namespace pelletdem
