// The pair loop and the bond loop (pair_loop.hpp): everything per step that touches every
// contact, so this file and the kernels it includes are the ones to read for speed.
#include "pair_loop.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "bond_kernel.hpp"
#include "contact_kernel.hpp"
#include "lanes.hpp"

namespace pelletdem {

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
  auto one = [&](Index k) { contact_one(I[k], J[k], H[k], p, law, cp, dt_inc, adh, mo, A, out); };
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
        if (lanes)
          contact_group(gi, gj, gh, xr, mo, law, cp, dt_inc, adh, A, out);
        else
          for (int l = 0; l < kLanes; ++l) one(e[l]);
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
          const Lane left =
              bonds_left(bp.damage, [&](int l) -> const Bond& { return bp.bonds[bp.slot_bond[s0 + l]]; });
          if (!lanes ||
              !bonded_group(gi, gj, gh, bp.slots[s0 / kLanes], left, xr, mo, law, cp, dt_inc, adh, A, out))
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
                          const HystereticLaw& law, const ContactLawParams& cp, double dt_inc, double adh,
                          const Motion* mo, Load* A, bool vector_kernel) {
  return pair_loop_body<false>(lo, hi, p, xr, nbr, law, cp, dt_inc, adh, mo, A, vector_kernel, BondedPairs{});
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
__attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif
PairStats pair_loop_bonded(long lo, long hi, const Particles& p, const PosRad* xr, NeighborList& nbr,
                           const HystereticLaw& law, const ContactLawParams& cp, double dt_inc, double adh,
                           const Motion* mo, Load* A, bool vector_kernel, const BondedPairs& bp) {
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
               const PosRad* xr, const Motion* mo, double dt, bool damage, Load* A, std::vector<long>& broke,
               bool vector_kernel) {
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

}  // namespace pelletdem
