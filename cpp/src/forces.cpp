// The force kernels: particle pairs, bonds and walls. Everything per step that touches every
// contact is here, so this file is the one to read for speed.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <omp.h>

#include "pelletdem/integrate.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

namespace {

// Magnitude of one contact's rolling-friction moment on one body, eq. 11: m_r f_n r for a
// compressive contact. The moments of all of a body's contacts are summed and turned along
// -w/|w| once per body, where the sum is capped (sum_loads).
PELLETDEM_INLINE double rolling_moment(double m_r, double fn, double r) {
  return (m_r > 0.0 && fn > 0.0) ? m_r * fn * r : 0.0;
}

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
      // Softening: the stress is returned to the shrinking capacity. Eq. 14's stresses are
      // homogeneous of degree 1 in (F_n, M_t) and (F_t, M_n), so scaling all four by
      // left_new / (left q) puts the governing one on it. This step's stretch beyond the
      // capacity, (q - 1) left sigma_c / E_b, lowers it by (q - 1) left sigma_c / s: slope
      // -E_b / s, zero at (1 + s) times the strain at the peak.
      const double left_new = (b.softening > 0.0) ? left * (1.0 - (q - 1.0) / b.softening) : 0.0;
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


// --- Lanes: four bonds, or four contacts, at a time -----------------------------------------
// The same arithmetic as update_bond (and contact_one, below), written on vectors of kLanes
// bonds or pairs (GCC vector extensions: 2 SSE2 operations per vector on a plain x86-64 build,
// one AVX operation where the CPU has it). Every lane does the scalar kernel's operations in the
// same order, so a bond or contact gets the same bits whichever way it is updated
// (test_determinism checks it). A bond group that reaches the strength test or twists by more
// than the series covers is left untouched and redone one bond at a time.
#if defined(__GNUC__)
#define PELLETDEM_LANES 1
// The lane helpers are always inlined, so the ABI of passing wide vectors never arises.
#pragma GCC diagnostic ignored "-Wpsabi"
constexpr int kLanes = 4;
typedef double Lane __attribute__((vector_size(kLanes * sizeof(double))));
typedef long long LaneMask __attribute__((vector_size(kLanes * sizeof(double))));

struct L3 {
  Lane x, y, z;
};

PELLETDEM_INLINE Lane lane_dot(const L3& a, const L3& b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
// a x b, as Eigen's cross()
PELLETDEM_INLINE L3 lane_cross(const L3& a, const L3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
PELLETDEM_INLINE Lane lane_abs(Lane a) {
  return reinterpret_cast<Lane>(reinterpret_cast<LaneMask>(a) & 0x7fffffffffffffffLL);
}
PELLETDEM_INLINE Lane lane_select(LaneMask m, Lane a, Lane b) {  // m ? a : b
  return reinterpret_cast<Lane>((reinterpret_cast<LaneMask>(a) & m) | (reinterpret_cast<LaneMask>(b) & ~m));
}
PELLETDEM_INLINE L3 lane_select(LaneMask m, const L3& a, const L3& b) {
  return {lane_select(m, a.x, b.x), lane_select(m, a.y, b.y), lane_select(m, a.z, b.z)};
}
static_assert(kLanes == 4, "gather() and transpose() list four lanes");
template <class Get>
PELLETDEM_INLINE Lane gather(Get&& get) {
  return Lane{get(0), get(1), get(2), get(3)};
}
typedef double Half __attribute__((vector_size(2 * sizeof(double))));
PELLETDEM_INLINE Half load2(const double* a) {
  Half h;
  std::memcpy(&h, a, sizeof h);
  return h;
}
PELLETDEM_INLINE Lane load4(const void* a) {
  Lane l;
  std::memcpy(&l, a, sizeof l);
  return l;
}
PELLETDEM_INLINE void store4(void* a, Lane l) { std::memcpy(a, &l, sizeof l); }
// x, y and z of a[idx[0..3]]. Each Vec3 is read as (x, y) and (y, z), two 16-byte loads that
// stay inside the vector (a 32-byte load would run past the last particle), and shuffled into
// place: 8 loads and 7 shuffles where element by element it took twice as many instructions.
PELLETDEM_INLINE L3 gather3(const Vec3* a, const Index* idx) {
  const double* p0 = a[idx[0]].data();
  const double* p1 = a[idx[1]].data();
  const double* p2 = a[idx[2]].data();
  const double* p3 = a[idx[3]].data();
  const Lane xy02 = __builtin_shufflevector(load2(p0), load2(p2), 0, 1, 2, 3);
  const Lane xy13 = __builtin_shufflevector(load2(p1), load2(p3), 0, 1, 2, 3);
  const Lane yz02 = __builtin_shufflevector(load2(p0 + 1), load2(p2 + 1), 0, 1, 2, 3);
  const Lane yz13 = __builtin_shufflevector(load2(p1 + 1), load2(p3 + 1), 0, 1, 2, 3);
  return {__builtin_shufflevector(xy02, xy13, 0, 4, 2, 6),
          __builtin_shufflevector(xy02, xy13, 1, 5, 3, 7),
          __builtin_shufflevector(yz02, yz13, 1, 5, 3, 7)};
}
PELLETDEM_INLINE L3 gather3(const std::vector<Vec3>& a, const Index* idx) {
  return gather3(a.data(), idx);
}
// Rows of four doubles (one per bond) to columns (one per field), and back: a 4x4 transpose.
struct L4 {
  Lane c0, c1, c2, c3;
};
PELLETDEM_INLINE L4 transpose(Lane r0, Lane r1, Lane r2, Lane r3) {
  const Lane t0 = __builtin_shufflevector(r0, r1, 0, 4, 2, 6);
  const Lane t1 = __builtin_shufflevector(r0, r1, 1, 5, 3, 7);
  const Lane t2 = __builtin_shufflevector(r2, r3, 0, 4, 2, 6);
  const Lane t3 = __builtin_shufflevector(r2, r3, 1, 5, 3, 7);
  return {__builtin_shufflevector(t0, t2, 0, 1, 4, 5), __builtin_shufflevector(t1, t3, 0, 1, 4, 5),
          __builtin_shufflevector(t0, t2, 2, 3, 6, 7), __builtin_shufflevector(t1, t3, 2, 3, 6, 7)};
}
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
// The four doubles at `offset` in each of g[0..3] (bonds, contact histories) as columns, and back.
template <class Obj>
PELLETDEM_INLINE L4 load_run(Obj* const* g, std::size_t offset) {
  auto row = [&](int k) { return load4(reinterpret_cast<const char*>(g[k]) + offset); };
  return transpose(row(0), row(1), row(2), row(3));
}
// Positions and radii of xr[idx[0..3]] as columns (x, y, z, r): four aligned loads.
PELLETDEM_INLINE L4 load_posrad(const PosRad* xr, const Index* idx) {
  auto row = [&](int k) { return *reinterpret_cast<const Lane*>(xr + idx[k]); };
  return transpose(row(0), row(1), row(2), row(3));
}
// Run `offset` (a byte offset of a run of four doubles in Motion) of mo[idx[0..3]] as columns.
constexpr std::size_t kRunVel = offsetof(Motion, vx), kRunSpin = offsetof(Motion, wx);
PELLETDEM_INLINE L4 load_motion(const Motion* mo, const Index* idx, std::size_t offset) {
  auto row = [&](int k) {
    return *reinterpret_cast<const Lane*>(reinterpret_cast<const char*>(mo + idx[k]) + offset);
  };
  return transpose(row(0), row(1), row(2), row(3));
}
template <class Obj>
PELLETDEM_INLINE void store_run(Obj* const* g, std::size_t offset, Lane c0, Lane c1, Lane c2, Lane c3) {
  const L4 r = transpose(c0, c1, c2, c3);
  store4(reinterpret_cast<char*>(g[0]) + offset, r.c0);
  store4(reinterpret_cast<char*>(g[1]) + offset, r.c1);
  store4(reinterpret_cast<char*>(g[2]) + offset, r.c2);
  store4(reinterpret_cast<char*>(g[3]) + offset, r.c3);
}
// For each 4-bit lane mask m: the lanes set in it, in order (offset[m], the rest 0), and how
// many there are (count[m]). The pair loop's queues append four lanes' pairs with them.
typedef std::uint32_t LaneOffsets __attribute__((vector_size(kLanes * sizeof(std::uint32_t))));
struct LaneList {
  std::uint32_t offset[1 << kLanes][kLanes];
  int count[1 << kLanes];
};
constexpr LaneList make_lane_list() {
  LaneList t{};
  for (int m = 0; m < (1 << kLanes); ++m) {
    int c = 0;
    for (int l = 0; l < kLanes; ++l)
      if (m >> l & 1) t.offset[m][c++] = static_cast<std::uint32_t>(l);
    t.count[m] = c;
  }
  return t;
}
constexpr LaneList kLaneList = make_lane_list();
// Lane l's mask (all ones or all zeros) in bit l.
PELLETDEM_INLINE unsigned lane_bits(LaneMask m) {
  return static_cast<unsigned>((m[0] & 1) | (m[1] & 2) | (m[2] & 4) | (m[3] & 8));
}
// Horizontal OR of a mask (lanes all ones or all zeros), in two shuffles.
PELLETDEM_INLINE bool lane_any(LaneMask m) {
  const LaneMask h = m | __builtin_shufflevector(m, m, 2, 3, 0, 1);
  return (h | __builtin_shufflevector(h, h, 1, 0, 3, 2))[0] != 0;
}
// Adds four pairs' results to the particle loads: force f on j and -f on i, torques ti on i
// and tj on j with rolling moments rolli and rollj (Load::roll), lane by lane in the scalar
// kernels' order (A[j].f += f; A[i].f -= f; A[i].t += ti; A[j].t += tj), so a particle in two
// lanes sums in the same order. Each lane's vector is a row (x, y, z, 0) or (x, y, z, roll)
// after a transpose and goes in with one load, add and store.
static_assert(offsetof(Load, f) == 0 && offsetof(Load, t) == 32 && offsetof(Load, roll) == 56,
              "Load is (f, 0, t, roll)");
PELLETDEM_INLINE void add_loads(Load* A, const Index* gi, const Index* gj, const L3& f, const L3& ti,
                                const L3& tj, Lane rolli = Lane{}, Lane rollj = Lane{}) {
  const L4 rf = transpose(f.x, f.y, f.z, Lane{});
  const L4 ri = transpose(ti.x, ti.y, ti.z, rolli);
  const L4 rj = transpose(tj.x, tj.y, tj.z, rollj);
  const Lane row_f[kLanes] = {rf.c0, rf.c1, rf.c2, rf.c3};
  const Lane row_i[kLanes] = {ri.c0, ri.c1, ri.c2, ri.c3};
  const Lane row_j[kLanes] = {rj.c0, rj.c1, rj.c2, rj.c3};
  for (int k = 0; k < kLanes; ++k) {
    double* fj = A[gj[k]].f.data();
    double* fi = A[gi[k]].f.data();
    double* ti_ = A[gi[k]].t.data();
    double* tj_ = A[gj[k]].t.data();
    store4(fj, load4(fj) + row_f[k]);
    store4(fi, load4(fi) - row_f[k]);
    store4(ti_, load4(ti_) + row_i[k]);
    store4(tj_, load4(tj_) + row_j[k]);
  }
}

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
PELLETDEM_INLINE void add_pair_loads(Load* A, const Index* gi, const Index* gj, const PairLanes& q,
                                     Lane fn, const L3& ft, const L3& moment, Lane roll_i = Lane{},
                                     Lane roll_j = Lane{}) {
  const L3& n = q.n;
  const L3 f{fn * n.x + ft.x, fn * n.y + ft.y, fn * n.z + ft.z};
  const L3 nxft = lane_cross(n, ft);
  const Lane mai = -q.ai, maj = -q.aj;
  const L3 ti{mai * nxft.x - moment.x, mai * nxft.y - moment.y, mai * nxft.z - moment.z};
  const L3 tj{maj * nxft.x + moment.x, maj * nxft.y + moment.y, maj * nxft.z + moment.z};
  add_loads(A, gi, gj, f, ti, tj, roll_i, roll_j);
}

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
      : g_(g), n_(load_run(g, kRunNormal)), s_(load_run(g, kRunShear)), b_(load_run(g, kRunBend)),
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
PELLETDEM_INLINE bool update_bond_group(Bond* const* g, const PosRad* xr, const Motion* mo,
                                        double dt, bool damage, Load* A) {
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

// What the pair loop reports besides the forces.
struct PairStats {
  long contacts = 0;
  double max_ov = 0.0;  // largest delta / min(r_i, r_j)
  Index max_ov_i = 0;   // the smaller particle of that pair
};

namespace {

// The contact force of eq. 5-10 of the touching pair (i, j) with kinematics g and history h;
// the pair counts in the loop's statistics.
PELLETDEM_INLINE ContactForce contact_force(Index i, Index j, ContactHistory& h, const PairGeometry& g,
                                            const Particles& p, const HystereticLaw& law,
                                            const ContactLawParams& cp, double dt_inc, double adh,
                                            PairStats& out) {
  const double ri = p.r[i], rj = p.r[j];
  ContactKinematics c{g.delta, g.vn, g.vt, g.n, ri * rj / (ri + rj),
                      p.m[i] * p.m[j] / (p.m[i] + p.m[j])};
  const ContactForce cf = law.evaluate(c, h, dt_inc, cp.mu, adh);
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
  const ContactForce cf = contact_force(i, j, h, g, p, law, cp, dt_inc, adh, out);
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
                                 const HystereticLaw& law, const ContactLawParams& cp,
                                 double dt_inc, double adh, const Motion* mo, Load* A,
                                 PairStats& out) {
  const PairGeometry g = pair_geometry(i, j, p, mo);
  const ContactForce cf = on ? contact_force(i, j, h, g, p, law, cp, dt_inc, adh, out)
                             : ContactForce{0.0, Vec3::Zero()};
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
// branches as selects, for the law without its optional effects (HystereticLaw::plain_pairs;
// k_2 is then constant and the stiffness scale 1). Out: the normal force fn, the tangential
// force ft and the new history (delta0, hft).
PELLETDEM_INLINE void contact_law_lanes(const PairLanes& q, const L4& hist, const HystereticLaw& law,
                                        const ContactLawParams& cp, double dt_inc, double adh,
                                        Lane& fn, L3& ft, Lane& delta0, L3& hft) {
  const L3& nv = q.n;
  const Lane delta = q.delta;
  const L3& vt = q.vt;
  const Lane m_eff = q.mi * q.mj / (q.mi + q.mj);

  // Eq. 5 (HystereticLaw::normal_force with scale 1 and constant k2).
  delta0 = hist.c0;
  hft = {hist.c1, hist.c2, hist.c3};
  const ContactLawParams& lp = law.params();
  const double s = 1.0;
  const double k1 = s * lp.k1, k2 = s * lp.k2, kc = s * lp.kc * adh;
  const Lane f_elastic = k2 * (delta - delta0);
  const Lane kd = k1 * delta;
  const Lane f_load = lane_select(kHuge < kd, Lane{} + kHuge, kd);  // std::min(k1 delta, kHuge)
  const LaneMask loading = f_elastic >= f_load;
  const LaneMask sticking = ~loading & (f_elastic <= -kc * delta);
  fn = lane_select(loading, f_load, lane_select(sticking, -kc * delta, f_elastic));
  delta0 = lane_select(loading, delta - f_load * (1.0 / k2),
                       lane_select(sticking, delta * (1.0 + kc / k2), delta0));

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
  const Lane limit = cp.mu * lane_select(fn < 0.0, Lane{}, fn);  // mu std::max(fn, 0)
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

// Four touching pairs, one per lane, as contact_one (for HystereticLaw::plain_pairs). The
// forces are added pair by pair in order, so the bits are contact_one's.
PELLETDEM_INLINE void contact_group(const Index* gi, const Index* gj, ContactHistory* const* gh,
                                    const PosRad* xr, const Motion* mo, const HystereticLaw& law,
                                    const ContactLawParams& cp, double dt_inc, double adh,
                                    Load* A, PairStats& out) {
  static_assert(sizeof(ContactHistory) == 4 * sizeof(double) && offsetof(ContactHistory, ft) == 8,
                "ContactHistory is (delta0, ft) as four doubles");
  const PairLanes q = pair_lanes(gi, gj, xr, mo);
  const L4 hist = load_run(gh, 0);
  Lane fn, delta0;
  L3 ft, hft;
  contact_law_lanes(q, hist, law, cp, dt_inc, adh, fn, ft, delta0, hft);
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
PELLETDEM_INLINE bool bonded_group(const Index* gi, const Index* gj, ContactHistory* const* gh,
                                   BondBlock& k, Lane left, const PosRad* xr, const Motion* mo,
                                   const HystereticLaw& law, const ContactLawParams& cp,
                                   double dt_inc, double adh, Load* A, PairStats& out) {
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
    contact_law_lanes(q, hist, law, cp, dt_inc, adh, fn, ft, delta0, hft);
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

// The bonded pairs of the neighbour list (NeighborList::kLiveBond in `live`): the bonds, the
// slots that hold their state (World::map_bonds), the slot of each pair (read only where a
// bond bit is set) and the bond of each slot, and where a thread notes the bonds that broke.
// bonds == nullptr: the world has no bonds. damage: some bond may be softening
// (BondParams::softening), so its capacity is below its strength.
struct BondedPairs {
  Bond* bonds = nullptr;
  BondBlock* slots = nullptr;
  const Index* slot_of = nullptr;    // per listed pair (World::pair_slot_)
  const Index* slot_bond = nullptr;  // per slot
  std::vector<long>* broke = nullptr;
  bool damage = false;
};

namespace {

// The pair loop over particles [lo, hi), i.e. over their listed pairs [start[lo], start[hi]):
// the contact force of every pair that touches (eq. 5-11) and, with kBonded, the bond of every
// bonded pair whether it touches or not, added to A; the history of pairs that came apart is
// cleared. The touch test runs four pairs at a time on the packed positions and radii (one
// aligned load per particle). Pairs queue up by kind and leave four at a time: touching
// unbonded pairs through contact_group where the law allows (else contact_one), and bonded
// pairs, touching or not, in list order and so in slot order: four whose bonds fill one slot
// block through bonded_group, which shares the pair's kinematics and its one load and store per
// particle between the contact and the bond and reads and writes the block with plain vector
// loads and stores; any other (the first few of a thread's run, the partners of a bond that
// broke since the list was built) one at a time through bonded_one. The scalar kernels take
// the pairs in the same order as the lanes, so the forces add up in the same order either way.
template <bool kBonded>
PELLETDEM_INLINE PairStats pair_loop_body(long lo, long hi, const Particles& p, const PosRad* xr,
                                          NeighborList& nbr, const HystereticLaw& law,
                                          const ContactLawParams& cp, double dt_inc, double adh,
                                          const Motion* mo, Load* A, bool vector_kernel,
                                          const BondedPairs& bp) {
  PairStats out;
  const Index k0 = nbr.start[lo], k1 = nbr.start[hi];
  const Index* I = nbr.first.data();
  const Index* J = nbr.j.data();
  ContactHistory* H = nbr.history.data();
  std::uint8_t* live = nbr.live.data();
  constexpr std::uint8_t kTouch = NeighborList::kLiveTouch, kBond = NeighborList::kLiveBond,
                         kApart = NeighborList::kLiveBondApart;
  // The test written out as the four-lane one does it, so both paths see the same pairs touch.
  auto touching = [&](Index k) {
    const PosRad &a = xr[I[k]], &b = xr[J[k]];
    return NeighborList::touching(b.x - a.x, b.y - a.y, b.z - a.z, a.r + b.r);
  };
  // A pair that came apart loses its history (it touched at the last pass).
  auto settle = [&](Index k, bool on) {
    if (!on && (live[k] & kTouch)) H[k] = ContactHistory{};
    live[k] = static_cast<std::uint8_t>(on | (live[k] & kBond));
  };
  auto one = [&](Index k) {
    contact_one(I[k], J[k], H[k], p, law, cp, dt_inc, adh, mo, A, out);
  };
  // A bonded pair, touching or not, its bond's state taken from its slot and put back; a bond
  // that broke is noted (its record then holds its last state) and its pair is no longer bonded.
  auto bonded = [&](Index k) {
    const Index s = bp.slot_of[k];
    const Index b = bp.slot_bond[s];
    Bond& bond = bp.bonds[b];
    load_slot(bp.slots, s, bond);
    const bool broke = bonded_one(I[k], J[k], touching(k), H[k], bond, p, law, cp, dt_inc, adh, mo, A, out);
    store_slot(bp.slots, s, bond);
    if (broke) {
      bp.broke->push_back(b);
      live[k] &= static_cast<std::uint8_t>(~kBond);
    }
  };
#ifdef PELLETDEM_LANES
  const bool lanes = vector_kernel && law.plain_pairs();
  if (kBonded || lanes) {
    // Queues: touching unbonded pairs (q[0]), bonded pairs in the slots of pairs that touched
    // (q[1]) and of pairs that were apart (q[2]) when the bonds were mapped. The test appends
    // without a branch. Each group kernel is written out at one place: inlined at several, the
    // loop outgrew the instruction cache and ran at half speed.
    constexpr int kQueues = kBonded ? 3 : 1;
    Index q[kQueues][2 * kLanes];
    int nq[kQueues] = {};
    Index k = k0;
    // A queue is full from kLanes entries on, and holds fewer than 2 kLanes.
    static_assert((kLanes & (kLanes - 1)) == 0, "kLanes is a power of two");
    auto full = [&] {
      int any = 0;
      for (int c = 0; c < kQueues; ++c) any |= nq[c];
      return (any & kLanes) != 0;
    };
    // Pairs k + l for the lanes l set in mask m to the end of queue c: one 16-byte store.
    static_assert(sizeof(Index) == sizeof(std::uint32_t), "queue entries are 32-bit");
    auto append = [&](int c, unsigned m) {
      LaneOffsets v;
      std::memcpy(&v, kLaneList.offset[m], sizeof v);
      v += static_cast<std::uint32_t>(k);
      std::memcpy(q[c] + nq[c], &v, sizeof v);
      nq[c] += kLaneList.count[m];
    };
    for (;;) {
      while (!full() && k < k1) {
        if (k + kLanes <= k1) {
          const L4 a = load_posrad(xr, I + k), b = load_posrad(xr, J + k);
          const Lane dx = b.c0 - a.c0, dy = b.c1 - a.c1, dz = b.c2 - a.c2, rsum = a.c3 + b.c3;
          const LaneMask on = (dx * dx + dy * dy) + dz * dz < rsum * rsum;
          std::uint32_t was;  // lane l's `live` in byte l
          std::memcpy(&was, live + k, sizeof was);
          // Lane l's touch in bit l, and in bit 0 of byte l (multiplying spreads the four bits
          // to the four bytes without carries).
          const unsigned touch = lane_bits(on);
          const std::uint32_t on_bytes = (touch * 0x00204081u) & 0x01010101u;
          if constexpr (kBonded) {
            // Bits 1 and 2 of byte l to bit l (the multiply gathers the bytes' bits into the top
            // byte).
            const unsigned bonded_t = (((was >> 1) & 0x01010101u) * 0x01020408u) >> 24;
            const unsigned bonded_a = (((was >> 2) & 0x01010101u) * 0x01020408u) >> 24;
            append(0, touch & ~(bonded_t | bonded_a));
            append(1, bonded_t);
            append(2, bonded_a);
          } else {
            append(0, touch);
          }
          // Pairs that came apart are rare in a step: one test for the four, no branch per
          // pair (a branch on each pair's touch was mispredicted often enough to cost ~6 %).
          constexpr std::uint32_t kTouchBytes = 0x01010101u * kTouch, kBondBytes = 0x01010101u * kBond;
          const std::uint32_t gone = was & ~on_bytes & kTouchBytes;  // touched last pass, not now
          if (gone)
            for (int l = 0; l < kLanes; ++l)
              if (gone >> (8 * l) & 1u) H[k + l] = ContactHistory{};
          const std::uint32_t now = on_bytes | (was & kBondBytes);
          std::memcpy(live + k, &now, sizeof now);
          k += kLanes;
        } else {
          const bool on = touching(k);
          const int c = (kBonded && (live[k] & kBond)) ? ((live[k] & kApart) ? 2 : 1) : 0;
          q[c][nq[c]] = k;
          nq[c] += (c > 0 || on);
          settle(k, on);
          ++k;
        }
      }
      int c = 0;
      while (c < kQueues && nq[c] < kLanes) ++c;
      if (c == kQueues) break;
      const Index* e = q[c];
      Index gi[kLanes], gj[kLanes];
      ContactHistory* gh[kLanes];
      for (int l = 0; l < kLanes; ++l) {
        gi[l] = I[e[l]];
        gj[l] = J[e[l]];
        gh[l] = H + e[l];
      }
      int used = kLanes;
      if (c == 0) {
        if (lanes) contact_group(gi, gj, gh, xr, mo, law, cp, dt_inc, adh, A, out);
        else for (int l = 0; l < kLanes; ++l) one(e[l]);
      } else if constexpr (kBonded) {
        // Four pairs whose bonds fill one block go together; otherwise the first goes alone.
        // A queue's slots rise with the list (map_bonds numbers each run in list order), so
        // the first and the last tell.
        const Index s0 = bp.slot_of[e[0]];
        const bool block = (s0 & (kLanes - 1)) == 0 && bp.slot_of[e[kLanes - 1]] == s0 + kLanes - 1;
        if (!block) {
          bonded(e[0]);
          used = 1;
        } else {
          const Lane left = bonds_left(bp.damage, [&](int l) -> const Bond& { return bp.bonds[bp.slot_bond[s0 + l]]; });
          if (!lanes || !bonded_group(gi, gj, gh, bp.slots[s0 / kLanes], left, xr, mo, law, cp, dt_inc, adh, A, out))
            for (int l = 0; l < kLanes; ++l) bonded(e[l]);
        }
      }
      for (int l = used; l < nq[c]; ++l) q[c][l - used] = q[c][l];
      nq[c] -= used;
    }
    for (int l = 0; l < nq[0]; ++l) one(q[0][l]);
    if constexpr (kBonded)
      for (int c = 1; c < kQueues; ++c)
        for (int l = 0; l < nq[c]; ++l) bonded(q[c][l]);
    return out;
  }
#endif
  (void)vector_kernel;
  for (Index k = k0; k < k1; ++k) {
    const bool on = touching(k);
    if (kBonded && (live[k] & kBond)) {
      settle(k, on);
      bonded(k);
    } else {
      if (on) one(k);
      settle(k, on);
    }
  }
  return out;
}

}  // namespace

// The pair loop without bonds, and with them (pair_loop_body). Copies for AVX2 and x86-64-v4
// as the bond loop has.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
__attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif
PairStats pair_loop_plain(long lo, long hi, const Particles& p, const PosRad* xr, NeighborList& nbr,
                          const HystereticLaw& law, const ContactLawParams& cp, double dt_inc,
                          double adh, const Motion* mo, Load* A, bool vector_kernel) {
  return pair_loop_body<false>(lo, hi, p, xr, nbr, law, cp, dt_inc, adh, mo, A, vector_kernel,
                               BondedPairs{});
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
__attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif
PairStats pair_loop_bonded(long lo, long hi, const Particles& p, const PosRad* xr, NeighborList& nbr,
                           const HystereticLaw& law, const ContactLawParams& cp, double dt_inc,
                           double adh, const Motion* mo, Load* A, bool vector_kernel,
                           const BondedPairs& bp) {
  return pair_loop_body<true>(lo, hi, p, xr, nbr, law, cp, dt_inc, adh, mo, A, vector_kernel, bp);
}

// The bond loop over bonds list[lo, hi) (bonds whose pairs are not in the neighbour list, in
// bond order): intact bonds in groups of kLanes where the compiler has vector extensions, the
// rest (and groups that need it) one by one, always in list order so the forces add up in the
// same order. Broken bonds' indices go to `broke`. On x86-64 Linux with GCC a copy is chosen at
// load time: x86-64-v4 (AVX-512: its 32 vector registers hold a group's values where AVX2's 16
// spill to the stack), AVX2, or the baseline. The build has -ffp-contract=off, so no copy fuses
// a multiply and an add: all three give the same bits.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
__attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif
void bond_loop(std::vector<Bond>& bonds, const Index* list, long lo, long hi, const Particles& p,
               const PosRad* xr, const Motion* mo, double dt, bool damage, Load* A,
               std::vector<long>& broke, bool vector_kernel) {
  auto one = [&](long b) {
    if (update_bond(bonds[b], p, mo, dt, A)) broke.push_back(b);
  };
#ifdef PELLETDEM_LANES
  long idx[kLanes];
  Bond* g[kLanes];
  int m = 0;
  for (long e = lo; e < hi; ++e) {
    const long b = list[e];
    if (bonds[b].mode != BondMode::Intact) continue;
    if (!vector_kernel) {
      one(b);
      continue;
    }
    idx[m] = b;
    g[m] = &bonds[b];
    if (++m < kLanes) continue;
    m = 0;
    if (!update_bond_group(g, xr, mo, dt, damage, A))
      for (int k = 0; k < kLanes; ++k) one(idx[k]);
  }
  for (int k = 0; k < m; ++k) one(idx[k]);
#else
  (void)vector_kernel, (void)xr, (void)mo;
  for (long e = lo; e < hi; ++e)
    if (bonds[list[e]].mode == BondMode::Intact) one(list[e]);
#endif
}

void World::size_particle_scratch() {
  const std::size_t n = p_.size();
  xr_.resize(n);
  mo_.resize(n);
  spin_inv_.resize(n);
  if (loads_.empty()) loads_.resize(1);
  loads_[0].resize(n);
}

double World::adhesion_scale() const {
  if (ramp_duration_ < 0.0 || time_ < ramp_start_) return 1.0;
  if (ramp_duration_ == 0.0) return 0.0;
  return std::max(0.0, 1.0 - (time_ - ramp_start_) / ramp_duration_);
}

void World::compute_forces(bool advance, Finish finish) {
  const long n = static_cast<long>(p_.size());
  const int nt = team();
  size_particle_scratch();
  if (static_cast<int>(loads_.size()) < nt) loads_.resize(nt);
  for (int k = 1; k < nt; ++k) loads_[k].resize(n);
  const double dt = params_.dt;
  // Incremental springs advance by v dt only when the particles moved since the last force
  // evaluation; a recomputation in place (after set_velocities, a new wall, a restored state)
  // must not stretch them again.
  const double dt_inc = advance ? dt : 0.0;
  const double adh = adhesion_scale();
  const ContactLawParams& cp = law_.params();
  // Bonded pairs in the list go with the pair loop; the rest (orphans_) through bond_loop.
  if (!bonds_.empty() && bond_map_generation_ != nbr_.generation) map_bonds();
  const long n_orphans = static_cast<long>(orphans_.size());
  std::vector<long> contacts_t(nt, 0);
  std::vector<double> maxov_t(nt, 0.0);
  std::vector<Index> maxov_i_t(nt, 0);
  std::vector<std::vector<long>> broke_t(nt);
  const int nt_walls = start_walls(nt);
  // Each thread takes a run of particles holding an equal share of the listed pairs, not of
  // the particles: a compacted pellet is denser under the piston, and equal particle shares
  // left one thread waiting for the other at the barrier (~11 % of a step in libgomp).
  std::vector<long> run(nt + 1, n);
  for (int t = 0; t < nt; ++t) {
    const double target = static_cast<double>(nbr_.start[n]) * t / nt;
    run[t] = std::lower_bound(nbr_.start.begin(), nbr_.start.begin() + n, target) - nbr_.start.begin();
  }
  load_range_.assign(2 * static_cast<std::size_t>(nt), 0);
  const LoadSums sums = load_sums(nt);

#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    Load* A = loads_[tid].data();
    long lo = run[tid], hi = run[tid + 1];
    long blo = 0, bhi = 0;
    if (n_orphans > 0) static_share(n_orphans, nt, tid, blo, bhi);
    if (tid > 0) {
      // Thread t's buffer holds its pairs' particles (bonded pairs among them), its orphan
      // bonds' and the wall contacts of its
      // run: zeroing and summing only that range keeps the other core's half out of this
      // one's cache (zeroing all N and reading it back across cores cost ~10 % of a
      // two-thread step).
      long rlo = lo, rhi = hi;
      const Index* J = nbr_.j.data();
      Index jmin = static_cast<Index>(lo), jmax = 0;
      for (Index k = nbr_.start[lo]; k < nbr_.start[hi]; ++k) {
        jmin = std::min(jmin, J[k]);
        jmax = std::max(jmax, J[k]);
      }
      rlo = std::min<long>(rlo, jmin);
      rhi = std::max<long>(rhi, static_cast<long>(jmax) + 1);
      for (long e = blo; e < bhi; ++e) {
        const Bond& b = bonds_[orphans_[e]];
        rlo = std::min<long>(rlo, std::min(b.i, b.j));
        rhi = std::max<long>(rhi, std::max(b.i, b.j) + 1);
      }
      if (rhi <= rlo) rlo = rhi = 0;
      load_range_[2 * tid] = rlo;
      load_range_[2 * tid + 1] = rhi;
      std::fill(loads_[tid].begin() + rlo, loads_[tid].begin() + rhi, Load{});
    }
    if (!prepared_) {
      long lo, hi;
      static_share(n, nt, tid, lo, hi);
      pack_particles(lo, hi, p_, 1.0 / dt, cp.rolling > 0.0, loads_[0].data(), xr_.data(), mo_.data(),
                     spin_inv_.data());
#pragma omp barrier
    }
    const PairStats ps =
        bonds_.empty()
            ? pair_loop_plain(lo, hi, p_, xr_.data(), nbr_, law_, cp, dt_inc, adh, mo_.data(), A,
                              vector_kernels_)
            : pair_loop_bonded(lo, hi, p_, xr_.data(), nbr_, law_, cp, dt_inc, adh, mo_.data(), A,
                               vector_kernels_, BondedPairs{bonds_.data(), slots_.data(), pair_slot_.data(), slot_bond_.data(), &broke_t[tid], bonds_soften_});
    // A thread's orphan bonds add to its own buffers, so it goes on to them without waiting
    // for the others' pairs; the reduction below waits for all.
    if (n_orphans > 0)
      bond_loop(bonds_, orphans_.data(), blo, bhi, p_, xr_.data(), mo_.data(), dt_inc,
                bonds_soften_, A, broke_t[tid], vector_kernels_);
    // The wall contacts of this thread's run of particles go into its own buffer as well.
    if (tid < nt_walls) wall_share(tid, nt_walls, nt_walls == 1 ? 0 : lo, nt_walls == 1 ? n : hi, dt_inc, A);
#pragma omp barrier
    contacts_t[tid] = ps.contacts;
    maxov_t[tid] = ps.max_ov;
    maxov_i_t[tid] = ps.max_ov_i;
    // Reduce the thread buffers in a fixed order: the same thread count gives the same bits.
    // With step()'s closing half kick, here while the forces are in registers (a pass of its
    // own read and wrote the velocities again: 4 % of a step), or left to the next drift pass.
    if (finish != Finish::Defer) {
      static_share(n, nt, tid, lo, hi);
      reduce_loads(lo, hi, sums, finish == Finish::ReduceKick ? 0.5 * dt : 0.0, p_);
    }
  }
  kick_pending_ = finish == Finish::Defer;
  kick_nt_ = nt;
  finish_walls(nt_walls);
  n_contacts_ = 0;
  max_overlap_ = 0.0;
  for (int k = 0; k < nt; ++k) {
    n_contacts_ += contacts_t[k];
    if (maxov_t[k] > max_overlap_) {
      max_overlap_ = maxov_t[k];
      max_overlap_i_ = maxov_i_t[k];
    }
  }
  // Broken bonds in bond order, whatever the thread count.
  std::vector<long> broke;
  for (int k = 0; k < nt; ++k) broke.insert(broke.end(), broke_t[k].begin(), broke_t[k].end());
  std::sort(broke.begin(), broke.end());
  const double marker = load_marker();
  for (long b : broke) {
    Bond& bond = bonds_[b];
    const Vec3 d = p_.x[bond.j] - p_.x[bond.i];
    const double dist = d.norm();
    const double half_gap = 0.5 * (dist - p_.r[bond.i] - p_.r[bond.j]);
    const Vec3 centre = p_.x[bond.i] + (p_.r[bond.i] + half_gap) * d / dist;
    // compute_forces runs after step() advanced time_ and step_: they are the breakage time.
    broken_.push_back(BrokenBond{time_, step_, bond.i, bond.j, centre, bond.mode,
                                 bond.sigma_max(), bond.tau_max(), marker});
    bond.fn = 0.0;
    bond.ft.setZero();
    bond.mn = 0.0;
    bond.mt.setZero();
  }
  max_overlap_seen_ = std::max(max_overlap_seen_, max_overlap_);
  prepared_ = false;
}

LoadSums World::load_sums(int nt) const {
  return LoadSums{loads_.data(), nt, params_.gravity / params_.density_scale, mo_.data(),
                  spin_inv_.data(), load_range_.data()};
}

void World::finish_pending_kick() {
  if (!kick_pending_) return;
  const long n = static_cast<long>(p_.size());
  const LoadSums sums = load_sums(kick_nt_);
  const double half_dt = 0.5 * params_.dt;
#pragma omp parallel num_threads(kick_nt_)
  {
    long lo, hi;
    static_share(n, kick_nt_, omp_get_thread_num(), lo, hi);
    reduce_loads(lo, hi, sums, half_dt, p_);
  }
  kick_pending_ = false;
}

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
                              [](const WallContact& c, long v) { return c.i < v; }) - w.contacts.begin();
    };
    const long lo = first_of(p_lo), hi = first_of(p_hi);
    // Crushing caps the loading force at p_y,plate pi r^2 (kHuge / r^2 stays finite).
    const double cap_scale = (w.crushable && cp.plate_yield_stress > 0.0) ? kPi * cp.plate_yield_stress : kHuge;
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
      ContactKinematics c{delta, vn, v_rel - vn * n_into, n_into, p_.r[i], p_.m[i], true, cap_scale * p_.r[i] * p_.r[i]};
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
