#pragma once
// Four-lane vectors (GCC vector extensions) and the loads, stores and transposes that the
// four-lane contact and bond kernels share. Internal to the force pass (anonymous namespace:
// each kernel's translation unit inlines its own copy).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "pelletdem/particles.hpp"
#include "pelletdem/vec.hpp"

namespace pelletdem {
namespace {

// --- Lanes: four bonds, or four contacts, at a time -----------------------------------------
// The same arithmetic as update_bond (and contact_one, below), written on vectors of kLanes
// bonds or pairs (GCC vector extensions: 2 SSE2 operations per vector on a plain x86-64 build,
// one AVX operation where the CPU has it). Every lane does the scalar kernel's operations in the
// same order, so a bond or contact gets the same bits whichever way it is updated
// (test_determinism checks it). A bond group that reaches the strength test or twists by more
// than the series covers is left untouched and redone one bond at a time.
#if defined(__GNUC__)
#define PELLETDEM_LANES 1
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
  return {__builtin_shufflevector(xy02, xy13, 0, 4, 2, 6), __builtin_shufflevector(xy02, xy13, 1, 5, 3, 7),
          __builtin_shufflevector(yz02, yz13, 1, 5, 3, 7)};
}
PELLETDEM_INLINE L3 gather3(const std::vector<Vec3>& a, const Index* idx) { return gather3(a.data(), idx); }
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
#endif  // __GNUC__

}  // namespace
}  // namespace pelletdem
