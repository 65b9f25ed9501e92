#pragma once
// The parallel bond kernel (eq. 12-14): one bond at a time, and four at a time on lanes with
// the scalar kernel's operations in its order (the same bits either way).
#include <algorithm>
#include <cmath>

#include "lanes.hpp"
#include "pair_kinematics.hpp"
#include "pelletdem/bonds.hpp"

namespace pelletdem {
namespace {

// Sine and cosine of a step's twist angle: short series for the tiny angles of a time step
// (below 1e-3 rad to the last bit with two and three terms, the four-lane bond kernel's; below
// 1e-2 rad with error < 1e-15), the library functions otherwise.
constexpr double kShortSeries = 1e-3;
PELLETDEM_INLINE void small_angle_sin_cos(double phi, double& s, double& c) {
  if (std::abs(phi) < kShortSeries) {
    const double p2 = phi * phi;
    constexpr double k6 = 1.0 / 6.0, k20 = 1.0 / 20.0, k12 = 1.0 / 12.0;
    s = phi * (1.0 - p2 * k6 * (1.0 - p2 * k20));
    c = 1.0 - 0.5 * p2 * (1.0 - p2 * k12);
  } else if (std::abs(phi) < 1e-2) {
    const double p2 = phi * phi;
    constexpr double k6 = 1.0 / 6.0, k20 = 1.0 / 20.0, k42 = 1.0 / 42.0;
    constexpr double k12 = 1.0 / 12.0, k30 = 1.0 / 30.0;
    s = phi * (1.0 - p2 * k6 * (1.0 - p2 * k20 * (1.0 - p2 * k42)));
    c = 1.0 - 0.5 * p2 * (1.0 - p2 * k12 * (1.0 - p2 * k30));
  } else {
    s = std::sin(phi);
    c = std::cos(phi);
  }
}

// Parallel bond update, eq. 12, and breakage test, eq. 14. `dt` is the increment: zero when
// forces are recomputed in place (compute_forces' `advance`), like the contacts' springs.
// A softening bond whose capacity has fallen below this fraction of its strength is broken.
constexpr double kSofteningGone = 0.01;

// The bond kernel handles the shear force F_t and the bending moment M_t side by side: both
// turn with the pair in the same way and take the same kind of increment, so each component
// is a pair (F_t, M_t) in one SIMD register, as are (F_n, M_n). Every lane does the same
// operations, in the same order, as the scalar formulas written in the comments.
using Pair = Eigen::Array2d;

// a . b of three pairs against one vector, summed in Eigen's order ((0 + 1) + 2).
PELLETDEM_INLINE Pair dot3(const Pair& X, const Pair& Y, const Pair& Z, const Vec3& a) {
  return (X * a.x() + Y * a.y()) + Z * a.z();
}

// Updates the bond's loads from the pair's kinematics g; unless it broke (then it returns
// true), `out` holds them.
PELLETDEM_INLINE bool bond_one(Bond& b, const PairGeometry& g, double dt, BondLoad& out) {
  const Vec3& n = g.n;
  // (ft, mt) component by component: X = (ft.x, mt.x), Y = (ft.y, mt.y), Z = (ft.z, mt.z).
  Pair X(b.ft.x(), b.mt.x()), Y(b.ft.y(), b.mt.y()), Z(b.ft.z(), b.mt.z());
  // Turn the stored shear force and bending moment with the pair: first the tilt of the
  // normal, then the mean spin about n. A rigid rotation of the pair then leaves them as they
  // were in the bond's own frame. The tilt is the smallest rotation taking a = n_prev to n,
  // two reflections: R v = v + 2 n (a.v) - s (s.v) / (1 + c) with s = a + n, c = a.n (exact,
  // no square root). v lies in the plane normal to a, so the middle term is round-off: left
  // out, the turned vectors stay in the bond plane to round-off, which does not accumulate
  // (each step's leftover along n is the last one's, with its sign turned, plus new round-off).
  const double c = b.n_prev.dot(n);
  if (c > -0.5) {  // (a reversal in one step never happens)
    const Vec3 sv = b.n_prev + n;
    const double k = 1.0 / (1.0 + c);
    const Pair t = k * dot3(X, Y, Z, sv);  // k (s . v)
    X -= t * sv.x();
    Y -= t * sv.y();
    Z -= t * sv.z();
  }
  const Vec3 &wi = g.wi, &wj = g.wj;
  const double phi = 0.5 * (wi + wj).dot(n) * dt;
  double s, cs;
  small_angle_sin_cos(phi, s, cs);
  // Rotation about n, cs v + s n x v; the component along n is projected out below.
  const Pair x2 = cs * X + s * (n.y() * Z - n.z() * Y);
  const Pair y2 = cs * Y + s * (n.z() * X - n.x() * Z);
  const Pair z2 = cs * Z + s * (n.x() * Y - n.y() * X);
  X = x2;
  Y = y2;
  Z = z2;
  b.n_prev = n;

  // Increments from the relative velocities at the contact point: normal parts (v_n, w_n)
  // and tangential ones (v_t, w_t).
  const Vec3 w_rel = wj - wi;
  const double wn = w_rel.dot(n);
  const Vec3 wt = w_rel - wn * n;
  const double area = b.area(), jpolar = b.polar_moment();
  // (fn, mn) -= (kn A, kt J) dt (v_n, w_n)
  const Pair kn_pair(b.kn * area * dt, b.kt * jpolar * dt);
  // (ft, mt) -= (kt A, kn J / 2) dt (v_t, w_t)
  const Pair kt_pair(b.kt * area * dt, b.kn * 0.5 * jpolar * dt);
  Pair N(b.fn, b.mn);
  N -= kn_pair * Pair(g.vn, wn);
  X -= kt_pair * Pair(g.vt.x(), wt.x());
  Y -= kt_pair * Pair(g.vt.y(), wt.y());
  Z -= kt_pair * Pair(g.vt.z(), wt.z());

  // Eq. 14 times A: sigma A = -F_n + 4 |M_t| / r_b, tau A = |F_t| + 2 |M_n| / r_b. The 1-norm
  // bounds the 2-norm from above, so most bonds pass without a square root.
  const double inv_r = 1.0 / b.radius;
  const double left = 1.0 - b.damage;  // capacity left (softening bonds), 1 for brittle ones
  const double fs = left * b.sigma_c * area, ts = left * b.tau_c * area;
  const Pair abs1 = (X.abs() + Y.abs()) + Z.abs();  // (|ft|_1, |mt|_1)
  const double sig_bound = -N[0] + 4.0 * inv_r * abs1[1];
  const double tau_bound = abs1[0] + 2.0 * inv_r * std::abs(N[1]);
  if (sig_bound > fs || tau_bound > ts) {
    b.fn = N[0];
    b.mn = N[1];
    b.ft = Vec3(X[0], Y[0], Z[0]);
    b.mt = Vec3(X[1], Y[1], Z[1]);
    const double sigma = b.sigma_max(), tau = b.tau_max();
    const double q = std::max(sigma / (left * b.sigma_c), tau / (left * b.tau_c));
    if (q > 1.0) {
      // Broken, unless an effect leaves it some capacity (effects/bond_softening.hpp): the
      // stress is then returned to it. Eq. 14's stresses are homogeneous of degree 1 in
      // (F_n, M_t) and (F_t, M_n), so scaling all four by left_new / (left q) puts the
      // governing one on it.
      const double left_new = BondEffects::capacity_after_overload(b, left, q);
      if (left_new < kSofteningGone) {
        b.mode = (sigma / b.sigma_c >= tau / b.tau_c) ? BondMode::Tension : BondMode::Shear;
        return true;
      }
      const double scale = left_new / (left * q);
      N *= scale;
      X *= scale;
      Y *= scale;
      Z *= scale;
      b.damage = 1.0 - left_new;
    }
  }
  b.fn = N[0];
  b.mn = N[1];
  b.ft = Vec3(X[0], Y[0], Z[0]);
  b.mt = Vec3(X[1], Y[1], Z[1]);
  out.fn = N[0];
  out.ft = b.ft;
  out.moment = N[1] * n + b.mt;  // mn n + mt
  return false;
}

// A bond whose pair is not in the neighbour list (stretched past it) on its own: its loads
// updated and added to A, unless it broke (then returns true and adds nothing).
PELLETDEM_INLINE bool update_bond(Bond& b, const Particles& p, const Motion* mo, double dt, Load* A) {
  const PairGeometry g = pair_geometry(b.i, b.j, p, mo);
  BondLoad bl;
  if (bond_one(b, g, dt, bl)) return true;
  add_pair_load(b.i, b.j, g, bl.fn, bl.ft, bl.moment, A);
  return false;
}

#ifdef PELLETDEM_LANES
// The bond's fields as four runs of four doubles, so the group loads each run with one 32-byte
// load per bond and a transpose: (n_prev, fn), (ft, mn), (mt, radius), (kn, kt, sigma_c, tau_c).
constexpr std::size_t kRunNormal = offsetof(Bond, n_prev), kRunShear = offsetof(Bond, ft),
                      kRunBend = offsetof(Bond, mt), kRunStiff = offsetof(Bond, kn);
static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 is three packed doubles");
static_assert(offsetof(Bond, fn) == kRunNormal + 24 && offsetof(Bond, mn) == kRunShear + 24 &&
                  offsetof(Bond, radius) == kRunBend + 24,
              "Bond keeps (n_prev, fn), (ft, mn) and (mt, radius) adjacent");
static_assert(offsetof(Bond, kt) == kRunStiff + 8 && offsetof(Bond, sigma_c) == kRunStiff + 16 &&
                  offsetof(Bond, tau_c) == kRunStiff + 24,
              "Bond keeps kn, kt, sigma_c, tau_c adjacent");

// BondLoad of four bonds.
struct BondLanes {
  Lane fn;
  L3 ft, moment;
};

// Four bonds' state and constants, a lane each, as bond_lanes reads and writes them: from and
// to four Bond records (transposed runs) or a BondBlock (each field one aligned vector, read
// where it is used, so it need not stay in a register).
class BondRecords {
 public:
  explicit BondRecords(Bond* const* g)
      : g_(g),
        n_(load_run(g, kRunNormal)),
        s_(load_run(g, kRunShear)),
        b_(load_run(g, kRunBend)),
        k_(load_run(g, kRunStiff)) {}
  L3 np() const { return {n_.c0, n_.c1, n_.c2}; }
  L3 ft() const { return {s_.c0, s_.c1, s_.c2}; }
  L3 mt() const { return {b_.c0, b_.c1, b_.c2}; }
  Lane fn() const { return n_.c3; }
  Lane mn() const { return s_.c3; }
  Lane rad() const { return b_.c3; }
  // BondBlock's constants, as store_slot computes them.
  Lane area() const { return kPi * b_.c3 * b_.c3; }
  Lane jpolar() const { return 0.5 * kPi * b_.c3 * b_.c3 * b_.c3 * b_.c3; }
  Lane kn_a() const { return k_.c0 * area(); }
  Lane kt_a() const { return k_.c1 * area(); }
  Lane kt_j() const { return k_.c1 * jpolar(); }
  Lane kn_half_j() const { return k_.c0 * 0.5 * jpolar(); }
  Lane sigma_ar() const { return k_.c2 * area() * b_.c3; }
  Lane tau_ar() const { return k_.c3 * area() * b_.c3; }
  void store(const L3& n, Lane fn, const L3& ft, Lane mn, const L3& mt) const {
    store_run(g_, kRunNormal, n.x, n.y, n.z, fn);
    store_run(g_, kRunShear, ft.x, ft.y, ft.z, mn);
    store_run(g_, kRunBend, mt.x, mt.y, mt.z, b_.c3);  // the radius goes back unchanged
  }

 private:
  Bond* const* g_;
  L4 n_, s_, b_, k_;
};

class BondSlots {
 public:
  explicit BondSlots(BondBlock& k) : k_(k) {}
  L3 np() const { return {F(B::NX), F(B::NY), F(B::NZ)}; }
  L3 ft() const { return {F(B::FTX), F(B::FTY), F(B::FTZ)}; }
  L3 mt() const { return {F(B::MTX), F(B::MTY), F(B::MTZ)}; }
  Lane fn() const { return F(B::FN); }
  Lane mn() const { return F(B::MN); }
  Lane rad() const { return F(B::RADIUS); }
  Lane kn_a() const { return F(B::KN_A); }
  Lane kt_a() const { return F(B::KT_A); }
  Lane kt_j() const { return F(B::KT_J); }
  Lane kn_half_j() const { return F(B::KN_HALF_J); }
  Lane sigma_ar() const { return F(B::SIGMA_AR); }
  Lane tau_ar() const { return F(B::TAU_AR); }
  void store(const L3& n, Lane fn, const L3& ft, Lane mn, const L3& mt) const {
    W(B::NX, n.x), W(B::NY, n.y), W(B::NZ, n.z), W(B::FN, fn);
    W(B::FTX, ft.x), W(B::FTY, ft.y), W(B::FTZ, ft.z), W(B::MN, mn);
    W(B::MTX, mt.x), W(B::MTY, mt.y), W(B::MTZ, mt.z);
  }

 private:
  using B = BondBlock;
  Lane F(int f) const { return *reinterpret_cast<const Lane*>(k_.f[f]); }
  void W(int f, Lane v) const { *reinterpret_cast<Lane*>(k_.f[f]) = v; }
  BondBlock& k_;
};

// bond_one on four intact bonds b (BondRecords or BondSlots; capacity left `left`: 1 - damage)
// of the pairs q: their new state stored in b and their loads in `out`. Returns false, having
// changed nothing, when a bond needs the scalar path.
template <class Bonds>
PELLETDEM_INLINE bool bond_lanes(const Bonds& b, const PairLanes& q, double dt, Lane left, BondLanes& out) {
  const L3 np = b.np();
  L3 ft = b.ft(), mt = b.mt();
  const L3& n = q.n;
  // Tilt of the normal (see bond_one); a reversal (c <= -0.5) goes to the scalar path.
  const Lane c = lane_dot(np, n);
  const L3 sv{np.x + n.x, np.y + n.y, np.z + n.z};
  const Lane k = 1.0 / (1.0 + c);
  auto tilt = [&](L3& v) {
    const Lane t = k * lane_dot(v, sv);
    v = {v.x - t * sv.x, v.y - t * sv.y, v.z - t * sv.z};
  };
  tilt(ft);
  tilt(mt);
  // Spin about n (small_angle_sin_cos' short series); beyond it, the scalar path.
  const L3 &wi = q.wi, &wj = q.wj;
  const L3 ws{wi.x + wj.x, wi.y + wj.y, wi.z + wj.z};
  const Lane phi = 0.5 * lane_dot(ws, n) * dt;
  const LaneMask odd = (c <= -0.5) | (lane_abs(phi) >= kShortSeries);
  const Lane p2 = phi * phi;
  constexpr double k6 = 1.0 / 6.0, k20 = 1.0 / 20.0, k12 = 1.0 / 12.0;
  const Lane s = phi * (1.0 - p2 * k6 * (1.0 - p2 * k20));
  const Lane cs = 1.0 - 0.5 * p2 * (1.0 - p2 * k12);
  auto spin = [&](L3& v) {
    const L3 nxv = lane_cross(n, v);
    v = {cs * v.x + s * nxv.x, cs * v.y + s * nxv.y, cs * v.z + s * nxv.z};
  };
  spin(ft);
  spin(mt);
  const L3 w_rel{wj.x - wi.x, wj.y - wi.y, wj.z - wi.z};
  const Lane wn = lane_dot(w_rel, n);
  const L3 wt{w_rel.x - wn * n.x, w_rel.y - wn * n.y, w_rel.z - wn * n.z};
  const Lane rad = b.rad();
  Lane fn = b.fn(), mn = b.mn();
  const Lane kna = b.kn_a() * dt, kta = b.kt_a() * dt;
  const Lane ktj = b.kt_j() * dt, kni = b.kn_half_j() * dt;
  fn -= kna * q.vn;
  mn -= ktj * wn;
  ft = {ft.x - kta * q.vt.x, ft.y - kta * q.vt.y, ft.z - kta * q.vt.z};
  mt = {mt.x - kni * wt.x, mt.y - kni * wt.y, mt.z - kni * wt.z};
  // Strength bounds of bond_one; a group with a bond past them is redone bond by bond.
  // The bounds times r_b (r_b > 0), which spares a division. This only picks the path: a group
  // within rounding of a bound is redone by bond_one, whose own test then decides.
  const Lane sig_bound = -fn * rad + 4.0 * ((lane_abs(mt.x) + lane_abs(mt.y)) + lane_abs(mt.z));
  const Lane tau_bound = ((lane_abs(ft.x) + lane_abs(ft.y)) + lane_abs(ft.z)) * rad + 2.0 * lane_abs(mn);
  if (lane_any(odd | (sig_bound > left * b.sigma_ar()) | (tau_bound > left * b.tau_ar()))) return false;

  out.fn = fn;
  out.ft = ft;
  out.moment = {mn * n.x + mt.x, mn * n.y + mt.y, mn * n.z + mt.z};
  b.store(n, fn, ft, mn, mt);
  return true;
}

// The capacity left, 1 - damage, of bonds[id[0..3]]: exactly 1 where no bond softens (`damage`
// false).
template <class Id>
PELLETDEM_INLINE Lane bonds_left(bool damage, Id&& id) {
  return damage ? 1.0 - gather([&](int k) { return id(k).damage; }) : Lane{} + 1.0;
}

// update_bond on kLanes intact bonds whose pairs are not in the neighbour list, in bond order.
// Returns false, having changed nothing, when a bond needs the scalar path.
PELLETDEM_INLINE bool update_bond_group(Bond* const* g, const PosRad* xr, const Motion* mo, double dt,
                                        bool damage, Load* A) {
  Index bi[kLanes], bj[kLanes];
  for (int k = 0; k < kLanes; ++k) {
    bi[k] = g[k]->i;
    bj[k] = g[k]->j;
  }
  const PairLanes q = pair_lanes(bi, bj, xr, mo);
  BondLanes bl;
  if (!bond_lanes(BondRecords(g), q, dt, bonds_left(damage, [&](int k) -> const Bond& { return *g[k]; }), bl))
    return false;
  add_pair_loads(A, bi, bj, q, bl.fn, bl.ft, bl.moment);
  return true;
}
#endif

}  // namespace
}  // namespace pelletdem
