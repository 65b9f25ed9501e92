// Bonds in the world: made on the relaxed pellet's contacts (with the bond law's effects),
// counted, and kept in slots for the pair loop (World::map_bonds, World::flush_slots).
#include <algorithm>
#include <cmath>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

long World::intact_bond_count() const {
  long c = 0;
  for (const Bond& b : bonds_) c += b.mode == BondMode::Intact;
  return c;
}

long World::create_bonds(const BondParams& law) {
  law.validate();
  BondParams bp = law;
  bp.moisture_content = params_.contact.moisture_content;
  bp.moisture_reference = params_.contact.moisture_reference;
  require(bp.gap_tolerance <= effective_skin(),
          cat("bond gap_tolerance = ", bp.gap_tolerance, " m must not exceed the neighbour skin ",
              effective_skin(), " m (raise skin)"));
  require(bonds_.empty(), "bonds were already created; a world is bonded once");
  ensure_forces();
  rebuild();
  const double stiffness = BondEffects::stiffness_factor(bp);
  long created = 0;
  for (std::size_t i = 0; i + 1 < nbr_.start.size(); ++i)
    for (Index k = nbr_.start[i]; k < nbr_.start[i + 1]; ++k) {
      const Index j = nbr_.j[k];
      const Vec3 d = p_.x[j] - p_.x[i];
      const double dist = d.norm();
      const double rsum = p_.r[i] + p_.r[j];
      if (!(dist < rsum + bp.gap_tolerance)) continue;  // touching, or within the gap
      Bond b;
      b.i = static_cast<Index>(i);
      b.j = j;
      b.n_prev = d / dist;
      const double r_star = p_.r[i] * p_.r[j] / rsum;
      b.radius = BondEffects::radius(bp, bp.radius, nbr_.history[k].delta0, r_star);
      b.kn = stiffness * bp.youngs_modulus / rsum;  // eq. 13
      b.kt = bp.kt_ratio * b.kn;
      const double strength = BondEffects::strength_factor(bp, b.i, j);
      b.sigma_c = strength * bp.sigma_c;
      b.tau_c = strength * bp.tau_c;
      BondEffects::init(bp, b);
      bonds_.push_back(b);
      ++created;
    }
  try {
    validate_time_step();  // stiff bonds can lower the stable step: refused before any step
  } catch (...) {
    bonds_.clear();
    throw;
  }
  forces_valid_ = false;
  bond_map_generation_ = -1;
  return created;
}

void World::flush_slots() const {
  if (!slots_live_) return;
  for (std::size_t s = 0; s < slot_bond_.size(); ++s) {
    if (slot_bond_[s] == kNoBond) continue;
    Bond& b = bonds_[slot_bond_[s]];
    if (b.mode == BondMode::Intact) load_slot(slots_.data(), s, b);
  }
}

void World::map_bonds() {
  flush_slots();
  pair_slot_.assign(nbr_.pair_count(), 0);
  orphans_.clear();
  bonds_soften_ = false;
  std::uint8_t* live = nbr_.live.data();
  for (std::size_t k = 0; k < nbr_.pair_count(); ++k)
    live[k] &= static_cast<std::uint8_t>(~NeighborList::kLiveBond);
  for (std::size_t b = 0; b < bonds_.size(); ++b) {
    const Bond& bond = bonds_[b];
    if (bond.mode != BondMode::Intact) continue;
    if (bond.softening > 0.0 || bond.damage != 0.0) bonds_soften_ = true;
    // The pair loop's normal points from the pair's first particle (the lower index) to its
    // second, as a bond's does from i to j when i < j.
    bool listed = false;
    if (bond.i < bond.j) {
      const auto first = nbr_.j.begin() + nbr_.start[bond.i], last = nbr_.j.begin() + nbr_.start[bond.i + 1];
      const auto it = std::lower_bound(first, last, bond.j);
      if (it != last && *it == bond.j) {
        const std::size_t k = static_cast<std::size_t>(it - nbr_.j.begin());
        live[k] |= NeighborList::kLiveBonded;
        pair_slot_[k] = static_cast<Index>(b);  // the bond for now; its slot below
        listed = true;
      }
    }
    if (!listed) orphans_.push_back(static_cast<Index>(b));
  }
  // Slots in list order, so that the pair loop meets them four by four: first the pairs that
  // touched when the list was built (the pair loop's test, to the bit), then, from the next
  // block on, those apart, which go through the pair loop in a queue of their own and skip
  // the contact law while all four of a group stay apart. The grouping sets the order in which
  // the pairs' loads add up, so it is taken at the list's positions, which a saved state
  // carries, not at the positions of whenever the map is made: a restored world then groups
  // its bonds as the saved one did and resumes bit for bit.
  std::vector<Index> runs[2];  // listed bonded pairs touching at the list build, and apart
  for (std::size_t k = 0; k < nbr_.pair_count(); ++k) {
    if (!(live[k] & NeighborList::kLiveBonded)) continue;
    const Vec3 d = x_build_[nbr_.j[k]] - x_build_[nbr_.first[k]];
    const bool touch = NeighborList::touching(d.x(), d.y(), d.z(), p_.r[nbr_.first[k]] + p_.r[nbr_.j[k]]);
    runs[touch ? 0 : 1].push_back(static_cast<Index>(k));
    if (!touch) live[k] ^= NeighborList::kLiveBond;  // kLiveBonded -> kLiveBondApart
  }
  slot_bond_.clear();
  for (const std::vector<Index>& run : runs) {
    while (slot_bond_.size() % 4) slot_bond_.push_back(kNoBond);
    for (Index k : run) {
      slot_bond_.push_back(pair_slot_[k]);
      pair_slot_[k] = static_cast<Index>(slot_bond_.size() - 1);
    }
  }
  slots_.assign((slot_bond_.size() + 3) / 4, BondBlock{});
  for (std::size_t s = 0; s < slot_bond_.size(); ++s)
    if (slot_bond_[s] != kNoBond) store_slot(slots_.data(), s, bonds_[slot_bond_[s]]);
  slots_live_ = true;
  bond_map_generation_ = nbr_.generation;
}

}  // namespace pelletdem
