#include "pelletdem/walls.hpp"

#include <cmath>

#include "pelletdem/errors.hpp"

namespace pelletdem {

void Wall::validate() const {
  require(point.allFinite(), cat("wall '", name, "': point must be finite"));
  require(velocity.allFinite(), cat("wall '", name, "': velocity must be finite"));
  require(std::isfinite(radius_rate), cat("wall '", name, "': radius_rate must be finite"));
  if (kind == WallKind::Plane) {
    require(normal.allFinite() && std::abs(normal.norm() - 1.0) < 1e-9,
            cat("wall '", name, "': normal must be a unit vector (got norm ", normal.norm(), ")"));
  } else {
    require_positive("cylinder radius", radius, "m");
  }
  if (servo) {
    require_nonnegative("servo_force", servo_force, "N");
    require_positive("servo_gain", servo_gain, "m/(s N)");
    require_positive("servo_max_speed", servo_max_speed, "m/s");
  }
}

}  // namespace pelletdem
