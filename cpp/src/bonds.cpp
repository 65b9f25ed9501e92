#include "pelletdem/bonds.hpp"

#include <cmath>

#include "pelletdem/errors.hpp"

namespace pelletdem {

void BondParams::validate() const {
  require_positive("bond radius r_b", radius, "m");
  require_range("bond radius r_b", radius, 1e-9, 1.0, "m");
  require_positive("bond Young's modulus E_b", youngs_modulus, "Pa");
  require_range("bond kt_ratio", kt_ratio, 0.0, 100.0);
  require_positive("bond tension strength sigma_c", sigma_c, "Pa");
  require_positive("bond shear strength tau_c", tau_c, "Pa");
  require_nonnegative("bond gap_tolerance", gap_tolerance, "m");
  if (weibull_modulus != 0.0) require_range("bond weibull_modulus", weibull_modulus, 0.5, 100.0);
  require_range("bond strength_seed", strength_seed, 0.0, 9.0e15);
  require(strength_seed == std::floor(strength_seed),
          cat("bond strength_seed = ", strength_seed, " must be a whole number"));
  require_range("bond softening", softening, 0.0, 100.0);
  require_range("bond overlap_radius_gain", overlap_radius_gain, 0.0, 1.0e3);
  require_range("bond moisture_content", moisture_content, 0.0, 100.0, "%");
  require_range("bond moisture_reference", moisture_reference, 0.0, 100.0, "%");
  require_range("bond moisture_coefficient", moisture_coefficient, -1.0, 1.0, "1/%");
}

double BondParams::moisture_factor() const {
  return std::exp(-moisture_coefficient * (moisture_content - moisture_reference));
}

}  // namespace pelletdem
