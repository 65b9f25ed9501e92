#pragma once
// The pair loop: every listed particle pair's contact (eq. 5-11) and, where it has one, its
// bond (eq. 12-14), over a run of particles, into a thread's Load buffer; and the loop over
// bonds whose pair has left the neighbour list. World::compute_forces runs them on its threads.
#include <vector>

#include "pair_kinematics.hpp"
#include "pelletdem/bonds.hpp"
#include "pelletdem/contact_law.hpp"
#include "pelletdem/neighbor.hpp"
#include "pelletdem/particles.hpp"

namespace pelletdem {

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

// The listed pairs of particles [lo, hi), without bonds and with them (bp).
PairStats pair_loop_plain(long lo, long hi, const Particles& p, const PosRad* xr, NeighborList& nbr,
                          const HystereticLaw& law, const ContactLawParams& cp, double dt_inc, double adh,
                          const Motion* mo, Load* A, bool vector_kernel);
PairStats pair_loop_bonded(long lo, long hi, const Particles& p, const PosRad* xr, NeighborList& nbr,
                           const HystereticLaw& law, const ContactLawParams& cp, double dt_inc, double adh,
                           const Motion* mo, Load* A, bool vector_kernel, const BondedPairs& bp);
// The bonds list[lo, hi) whose pairs are not in the neighbour list; broken ones into `broke`.
void bond_loop(std::vector<Bond>& bonds, const Index* list, long lo, long hi, const Particles& p,
               const PosRad* xr, const Motion* mo, double dt, bool damage, Load* A, std::vector<long>& broke,
               bool vector_kernel);

}  // namespace pelletdem
