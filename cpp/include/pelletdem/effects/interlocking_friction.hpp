#pragma once
// Interlocking friction: the particle-particle friction coefficient mu times F >= 1 once the
// pellet is made. Table 4's mu = 0.5 is loose sawdust on sawdust; compaction to 60-120 MPa
// flattens the particles into one another and entangles their fibres (mechanical
// interlocking, one of the binding mechanisms of biomass pellets besides solid bridges), so a
// contact of the made pellet resists sliding more. Particles of the diametral test then slide
// less past one another while the bonds stretch: the pellet deforms less before they break,
// and is stronger. The stages put it in force from the bonding on
// (pelletdem.stages.compaction_law keeps it off from fill to relaxation), so the relaxed
// pellet is that of the paper's law; the plates and the mould keep mu_wall.
#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_InterlockingFriction(X)                                                  \
  X(double, interlocking_friction, 1.0, Range, 1.0, 100.0, "-", "interlocking_friction", true,  \
    "F: mu of the made pellet's contacts over the loose sawdust's, from the bonding on (stage " \
    "'diametral'); 1 off")

namespace pelletdem {

struct InterlockingFriction : ContactEffect {
  // A factor on mu, not on each contact's limit: one product per law.
  template <class P>
  static double friction_factor(const P& p) {
    return p.interlocking_friction;
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(InterlockingFriction)
