#pragma once
// The per-particle passes of a step around the force pass: velocity Verlet's first half kick
// and drift, and the packed records (PosRad, Motion, a zeroed Load) that the contact kernels
// read. One job: stream through the particle arrays once.
#include <algorithm>
#include <vector>

#include "pelletdem/particles.hpp"

namespace pelletdem {

// The contiguous share [lo, hi) of `count` items that thread `tid` of `nt` gets, as
// `omp for schedule(static)` would hand it out: the first count % nt threads one more.
inline void static_share(long count, int nt, int tid, long& lo, long& hi) {
  const long q = count / nt, extra = count % nt;
  lo = q * tid + (tid < extra ? tid : extra);
  hi = lo + q + (tid < extra ? 1 : 0);
}

struct DriftResult {
  double max_disp2 = 0.0;  // largest squared displacement since the list was built, m^2
  long bad = -1;           // largest index of a particle whose position is not finite
};

// The threads' Load buffers of a force pass and what turns their sums into Particles::f and t.
struct LoadSums {
  const std::vector<Load>* bufs;  // buffers of threads 0 .. nt-1, added in that order
  int nt;
  Vec3 g;                  // gravity (divided by the density scale), m/s^2
  const Motion* mo;        // v and w of the force pass (pack_particles)
  const double* spin_inv;  // 1 / |w| of the force pass, 1/(rad/s)
  const long* range;       // buffer k > 0 holds particles [range[2k], range[2k+1])
};

// Force f and torque t on particle i from the buffers: the threads' sums, eq. 11's rolling
// moments turned along -w/|w| (Load::roll), and gravity. The rolling moments of all the
// body's contacts together are capped at |w| I / dt (Motion::roll_cap): friction can stop a
// spin within a step but never reverse it. A cap per contact would not do: n contacts
// would each take the whole spin away, and with n >= 3 the spin would grow as (1 - n) w.
PELLETDEM_INLINE void sum_loads(const LoadSums& s, long i, const Particles& p, Vec3& f, Vec3& t) {
  const Load& a = s.bufs[0][i];
  f = a.f;
  t = a.t;
  double roll = a.roll;
  for (int k = 1; k < s.nt; ++k) {
    if (i < s.range[2 * k] || i >= s.range[2 * k + 1]) continue;
    const Load& b = s.bufs[k][i];
    f += b.f;
    t += b.t;
    roll += b.roll;
  }
  t -= std::min(roll, s.mo[i].roll_cap) * (s.mo[i].w() * s.spin_inv[i]);
  f += p.m[i] * s.g;
}

// For particles [lo, hi): p.f and p.t from sum_loads, then (half_dt > 0) the closing half kick
// of a step from the force pass's v and w (s.mo): p.v = v + half_dt f/m, p.w = w + half_dt t/I.
void reduce_loads(long lo, long hi, const LoadSums& s, double half_dt, Particles& p);

// For particles [lo, hi): zero A0, and write xr (position, radius), mo (velocity, mass, spin,
// and the rolling-friction cap |w| I / dt of eq. 11) and spin_inv (1 / |w|, 0 at rest); cap
// and spin_inv are zero when `rolling` is false.
void pack_particles(long lo, long hi, const Particles& p, double inv_dt, bool rolling, Load* A0, PosRad* xr,
                    Motion* mo, double* spin_inv);

// For particles [lo, hi): v += dt/2 f/m, w += dt/2 t/I, x += dt v, then pack_particles.
// Reports the largest displacement from x_build and any non-finite position. With `pending`
// (the last step's force pass left its sums in the buffers), reduce_loads' closing half kick
// comes first, in the same pass: the same bits as the two passes one after the other. p.f and
// p.t, and p.v and p.w, are then left as they were: the velocities live in mo (Motion) until
// finish_pending_kick or the next reduction writes them.
DriftResult kick_drift_pack(long lo, long hi, double dt, bool rolling, Particles& p, const Vec3* x_build,
                            Load* A0, PosRad* xr, Motion* mo, double* spin_inv, const LoadSums* pending);

}  // namespace pelletdem
