#pragma once
// Verlet neighbour list built from a cell grid: O(N) to build, rebuilt only when some particle
// has moved more than half the skin. Pairs are stored once (j > i) in CSR form, sorted by j, so
// that the contact history of the old list can be merged into the new one in linear time.
#include <cstdint>
#include <vector>

#include "pelletdem/contact_law.hpp"
#include "pelletdem/particles.hpp"
#include "pelletdem/vec.hpp"

namespace pelletdem {

struct Box {
  Vec3 lo = Vec3::Zero();
  Vec3 hi = Vec3::Zero();
  bool contains(const Vec3& p) const {
    return p.x() >= lo.x() && p.y() >= lo.y() && p.z() >= lo.z() && p.x() <= hi.x() && p.y() <= hi.y() &&
           p.z() <= hi.z();
  }
};

class NeighborList {
 public:
  std::vector<Index> start;             // start[i]..start[i+1]: pairs of particle i
  std::vector<Index> j;                 // second particle of each pair (j > i)
  std::vector<Index> first;             // first particle i of each pair, for flat pair loops
  std::vector<ContactHistory> history;  // per pair, survives rebuilds
  // Per pair, bit kLiveTouch: the history may be non-zero (the pair touched at the last force
  // pass). The pair loop clears the history of pairs that came apart; with this flag it reads
  // one byte of a pair that does not touch instead of its 32-byte history, without a branch.
  // Bits kLiveBonded and kLiveBondApart: the pair has an intact bond (set by World::map_bonds),
  // in the run of slots of pairs that touched, or of pairs that were apart, when it was set.
  std::vector<std::uint8_t> live;
  static constexpr std::uint8_t kLiveTouch = 1, kLiveBonded = 2, kLiveBondApart = 4;
  static constexpr std::uint8_t kLiveBond = kLiveBonded | kLiveBondApart;
  // Counts the builds and mark_live calls: whatever maps onto the pairs is stale when it changes.
  long generation = 0;

  std::size_t pair_count() const { return j.size(); }

  // The touch test of a pair whose centres are (dx, dy, dz) apart, radii summing to rsum,
  // written as the pair loop's four-lane test computes it: every scalar copy (the pair loop's
  // tail, World::map_bonds' runs of slots) must agree with it to the bit.
  static bool touching(double dx, double dy, double dz, double rsum) {
    return (dx * dx + dy * dy) + dz * dz < rsum * rsum;
  }

  // Sets `live` from the histories: after anything but the pair loop wrote them.
  void mark_live();

  // Rebuild for cutoff r_i + r_j + skin. Throws ParticleEscapedError for a particle outside
  // the box. History of pairs still present is kept; pairs that left the list had no contact.
  void build(const Particles& p, const Box& box, double skin, double r_max, long step, int threads);

  // Brute-force reference, O(N^2): every pair (i < j) closer than r_i + r_j + skin.
  static std::vector<std::pair<Index, Index>> brute_force(const Particles& p, double skin);

 private:
  std::vector<Index> cell_start_, cell_items_;
  std::vector<std::vector<Index>> share_j_;  // per thread: the pairs of its share of particles
  std::vector<Index> new_start_, new_j_, new_first_;
  std::vector<ContactHistory> new_history_;
};

}  // namespace pelletdem
