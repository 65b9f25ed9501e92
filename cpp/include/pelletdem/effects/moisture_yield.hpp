#pragma once
// Moisture-dependent yield: the loading (plastic) stiffness k1, which eq. 7 ties to the
// particles' yield strength (k1 = 5 r* p_y), times exp(-c (MC - MC_ref)). Water plasticises
// lignin, so wetter sawdust yields at a lower pressure (c > 0); the unloading stiffness k2,
// the elastic response, is unchanged. A loading line made steeper than k2 is followed at k2
// (eq. 5's first case). The relaxed density then trends with moisture at every pressure.
#include <cmath>

#include "pelletdem/effect.hpp"

#define PELLETDEM_ROWS_MoistureYield(X)                                                   \
  X(double, moisture_yield, 0.0, Range, -1.0, 1.0, "1/%", "moisture_yield", true,         \
    "c in k1 exp(-c (MC - MC_ref)) on the loading branch (MC, MC_ref: moisture_content, " \
    "moisture_reference); 0 off")

namespace pelletdem {

struct MoistureYield : ContactEffect {
  template <class P>
  static bool reads_moisture(const P& p) {
    return p.moisture_yield != 0.0;
  }
  // A factor on k1, not on the loading force: one exp per law, not one per contact and step.
  template <class P>
  static double loading_stiffness_factor(const P& p) {
    return std::exp(-p.moisture_yield * (p.moisture_content - p.moisture_reference));
  }
};

}  // namespace pelletdem

PELLETDEM_CONTACT_EFFECT(MoistureYield)
