#pragma once
// Crushing where the diametral plates touch the pellet: on walls marked crushable (the plates)
// the loading branch is capped at plate_yield_stress pi r^2, so a particle under a plate
// flattens at constant force instead of stiffening: a longer toe of sigma_1(dL/D), failure at
// larger dL/D, little change of the peak. Past kCrushedDepth of its radius (contact_law.hpp)
// the crushed particle stiffens again.
#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_PlateCrushing(X)                                                    \
  X(double, plate_yield_stress, 0.0, Range, 0.0, 1.0e12, "Pa", "plate_yield_stress", true, \
    "crushing under the diametral plates: their contacts' loading force capped at p pi r^2; 0 off")

namespace pelletdem {

struct PlateCrushing : ContactEffect {
  template <class P>
  static double wall_load_cap(const P& p, double cap, double r, bool crushable) {
    return (crushable && p.plate_yield_stress > 0.0) ? kPi * p.plate_yield_stress * r * r : cap;
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(PlateCrushing)
