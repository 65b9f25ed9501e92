// Velocity Verlet's first half kick and drift, and the packing of the particle records the
// contact kernels read (see integrate.hpp).
#include "pelletdem/integrate.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace pelletdem {

namespace {

// Particles are packed in blocks: the roots and divisions of the rolling terms then run four
// at a time. One at a time they were ~a quarter of the drift pass, a divider latency each.
constexpr long kBlock = 32;

// The rest of a block's records once mo[i] holds v, m and w and len[k] = |w|^2: zeroed Load,
// (x, r), and eq. 11's cap |w| I / dt and 1 / |w|.
PELLETDEM_INLINE void pack_block(long b, long e, const Particles& p, double inv_dt, bool rolling, Load* A0,
                                 PosRad* xr, Motion* mo, double* spin_inv, double* len) {
  alignas(32) double inertia[kBlock], cap[kBlock], inv[kBlock];
  const int nb = static_cast<int>(e - b);
  // The callers' blocks hold 1 to kBlock particles (kBlock a multiple of 4); said so, GCC no
  // longer warns of writes past the arrays on paths that cannot happen.
  static_assert(kBlock % 4 == 0, "blocks are whole runs of four");
  if (nb < 1 || nb > kBlock) __builtin_unreachable();
  for (int k = 0; k < nb; ++k) {
    const long i = b + k;
    A0[i] = Load{};
    xr[i] = PosRad{p.x[i].x(), p.x[i].y(), p.x[i].z(), p.r[i]};
    inertia[k] = sphere_inertia(p.m[i], p.r[i]);
  }
  if (rolling) {
    // Four at a time, written as vectors (the loop vectorizer left it scalar); the tail of a
    // short block computes on zeros that nobody reads.
    for (int k = nb; k < (nb + 3) / 4 * 4; ++k) {
      if (k >= kBlock) __builtin_unreachable();
      len[k] = inertia[k] = 0.0;
    }
    for (int k = 0; k < nb; k += 4) {
      if (k > kBlock - 4) __builtin_unreachable();
      typedef double V4 __attribute__((vector_size(32)));
      V4 l2, inr, wl;
      std::memcpy(&l2, len + k, sizeof l2);
      std::memcpy(&inr, inertia + k, sizeof inr);
      for (int m = 0; m < 4; ++m) wl[m] = std::sqrt(l2[m]);  // |w|
      const V4 c = wl * inr * inv_dt;                        // |w| I / dt
      const auto nonzero = wl != 0.0;
      const V4 q = 1.0 / (nonzero ? wl : V4{} + 1.0);
      const V4 iv = nonzero ? q : V4{};
      std::memcpy(cap + k, &c, sizeof c);
      std::memcpy(inv + k, &iv, sizeof iv);
    }
  } else {
    std::fill(cap, cap + nb, 0.0);
    std::fill(inv, inv + nb, 0.0);
  }
  for (int k = 0; k < nb; ++k) {
    mo[b + k].roll_cap = cap[k];
    spin_inv[b + k] = inv[k];
  }
}

}  // namespace

// Copies for AVX2 and x86-64-v4 as the force kernels have; -ffp-contract=off keeps the bits.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define PELLETDEM_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define PELLETDEM_CLONES
#endif

PELLETDEM_CLONES
void pack_particles(long lo, long hi, const Particles& p, double inv_dt, bool rolling, Load* A0, PosRad* xr,
                    Motion* mo, double* spin_inv) {
  alignas(32) double len[kBlock];
  for (long b = lo; b < hi; b += kBlock) {
    const long e = std::min(hi, b + kBlock);
    for (long i = b; i < e; ++i) {
      const Vec3 &v = p.v[i], &w = p.w[i];
      mo[i] = Motion{v.x(), v.y(), v.z(), p.m[i], w.x(), w.y(), w.z(), 0.0};
      len[i - b] = w.squaredNorm();
    }
    pack_block(b, e, p, inv_dt, rolling, A0, xr, mo, spin_inv, len);
  }
}

PELLETDEM_CLONES
void reduce_loads(long lo, long hi, const LoadSums& s, double half_dt, Particles& p) {
  for (long i = lo; i < hi; ++i) {
    sum_loads(s, i, p, p.f[i], p.t[i]);
    if (half_dt > 0.0) {
      Vec3 v = s.mo[i].v(), w = s.mo[i].w();
      v += (half_dt * p.inv_m[i]) * p.f[i];
      w += (half_dt * p.inv_i[i]) * p.t[i];
      p.v[i] = v;
      p.w[i] = w;
    }
  }
}

PELLETDEM_CLONES
DriftResult kick_drift_pack(long lo, long hi, double dt, bool rolling, Particles& p, const Vec3* x_build,
                            Load* A0, PosRad* xr, Motion* mo, double* spin_inv, const LoadSums* pending) {
  DriftResult out;
  const double inv_dt = 1.0 / dt;
  alignas(32) double len[kBlock];
  for (long b = lo; b < hi; b += kBlock) {
    const long e = std::min(hi, b + kBlock);
    double sum_disp2 = 0.0;  // not finite iff some position is not (Eigen's allFinite per
                             // particle, three compares and branches, was 13 % of this pass)
    for (long i = b; i < e; ++i) {
      const double hm = 0.5 * dt * p.inv_m[i], hi_ = 0.5 * dt * p.inv_i[i];
      Vec3 v, w;
      if (pending) {  // the last step's closing half kick (reduce_loads), then this one's
        Vec3 f, t;
        sum_loads(*pending, i, p, f, t);
        v = mo[i].v();
        w = mo[i].w();
        v += hm * f;
        w += hi_ * t;
        v += hm * f;
        w += hi_ * t;
        mo[i].set_v(v);
        mo[i].set_w(w);
      } else {
        v = p.v[i];
        w = p.w[i];
        v += hm * p.f[i];
        w += hi_ * p.t[i];
        p.v[i] = v;
        p.w[i] = w;
        mo[i] = Motion{v.x(), v.y(), v.z(), p.m[i], w.x(), w.y(), w.z(), 0.0};
      }
      len[i - b] = w.squaredNorm();
      p.x[i] += dt * v;
      const double disp2 = (p.x[i] - x_build[i]).squaredNorm();
      sum_disp2 += disp2;
      out.max_disp2 = std::max(out.max_disp2, disp2);
    }
    if (!std::isfinite(sum_disp2))
      for (long i = b; i < e; ++i)
        if (!p.x[i].allFinite()) out.bad = i;
    pack_block(b, e, p, inv_dt, rolling, A0, xr, mo, spin_inv, len);
  }
  return out;
}

}  // namespace pelletdem
