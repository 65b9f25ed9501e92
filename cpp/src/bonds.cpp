#include "pelletdem/bonds.hpp"

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
}

}  // namespace pelletdem
