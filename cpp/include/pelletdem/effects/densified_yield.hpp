#pragma once
// Densified yield: the loading (plastic) stiffness k1 times Y >= 1 once the pellet is made.
// Sawdust particles are porous wood (BD_w 510-675 kg/m^3 against ~1500 for the cell wall);
// compaction to 60-120 MPa collapses their pores, and densified wood yields at a far higher
// pressure than the loose sawdust of eq. 7's p_y. A contact that starts or grows in the
// diametral test then flattens less: the pellet deforms less before its bonds break. The
// stages put it in force from the bonding on (pelletdem.stages.compaction_law keeps it off
// from fill to relaxation), so the relaxed pellet is that of the paper's law. A loading line
// made steeper than the unloading one is followed at it (eq. 5's first case): Y >= k2/k1 is
// a test in which no contact yields.
#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_DensifiedYield(X)                                                        \
  X(double, densified_yield, 1.0, Range, 1.0, 1.0e4, "-", "densified_yield", true,              \
    "Y: k1 of the made pellet's contacts over the loose sawdust's, from the bonding on (stage " \
    "'diametral'); 1 off")

namespace pelletdem {

struct DensifiedYield : ContactEffect {
  // A factor on k1, not on the loading force: one product per law, none per contact and step.
  template <class P>
  static double loading_stiffness_factor(const P& p) {
    return p.densified_yield;
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(DensifiedYield)
