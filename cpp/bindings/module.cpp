// The only C++ that knows Python: the module _core, put together from the parts in this folder
// (bindings.hpp), with the engine's errors and the functions that make particles.
#include <cmath>

#include "bindings.hpp"

namespace py = pybind11;
using namespace pelletdem;
using namespace pelletdem::bindings;

namespace {

// Radii are drawn by rejection, so a range holding almost none of the distribution (sd huge,
// infinite, or the range far in a tail) would loop for ever; refuse it before drawing. The
// count is capped so that a huge n is an error, not an 8n-byte allocation.
constexpr double kMaxRadii = 1e7;
constexpr double kMinAcceptance = 1e-3;

std::vector<double> checked_truncated_normal_radii(long n, double mean, double sd, double r_min, double r_max,
                                                   std::uint64_t seed) {
  require_range("n", static_cast<double>(n), 0, kMaxRadii, "particles");
  if (std::isfinite(mean) && std::isfinite(r_min) && std::isfinite(r_max) && sd > 0.0 && r_max >= r_min) {
    // Fraction of N(mean, sd) inside [r_min, r_max]; 0 for an infinite sd.
    const double s = std::isfinite(sd) ? sd * std::sqrt(2.0) : HUGE_VAL;
    const double p = 0.5 * (std::erfc((mean - r_max) / s) - std::erfc((mean - r_min) / s));
    if (!(p >= kMinAcceptance))
      throw ParameterError(cat("radius range [r_min, r_max] = [", r_min, ", ", r_max, "] m holds a fraction ",
                               p, " of the normal distribution (mean ", mean, " m, sd ", sd,
                               " m): allowed >= ", kMinAcceptance, " (narrow sd or widen the range)"));
  }
  return truncated_normal_radii(n, mean, sd, r_min, r_max, seed);
}

// The placement grid indexes cells of 2 r_max with ints and hashes them into a 64-bit key:
// coordinates must be finite and within a million cells of the origin, and the region must
// be tall enough for the largest sphere (else it is placed outside it).
void check_pack_region(const std::vector<double>& r, double cx, double cy, double radius, double z_lo,
                       double z_hi) {
  require(std::isfinite(cx) && std::isfinite(cy), cat("fill centre (", cx, ", ", cy, ") m must be finite"));
  require(std::isfinite(z_lo) && std::isfinite(z_hi),
          cat("fill region z_lo = ", z_lo, " m, z_hi = ", z_hi, " m must be finite"));
  require_positive("fill radius", radius, "m");
  double r_max = 0.0;
  for (double q : r)
    if (q > 0.0 && std::isfinite(q)) r_max = std::max(r_max, q);
  if (r_max <= 0.0) return;  // no valid radius: the engine names the bad one
  const double reach =
      std::max({std::abs(cx) + radius, std::abs(cy) + radius, std::abs(z_lo), std::abs(z_hi)});
  if (!(reach / (2.0 * r_max) < 1e6))
    throw ParameterError(cat("fill region reaches ", reach,
                             " m from the origin, more than 1e6 particle "
                             "diameters (2 r_max = ",
                             2.0 * r_max, " m): allowed |coordinate| < ", 2e6 * r_max, " m"));
  require(!(z_hi > z_lo) || z_hi - z_lo >= 2.0 * r_max,  // (a reversed range: the engine says so)
          cat("fill region height z_hi - z_lo = ", z_hi - z_lo, " m must be >= the largest diameter ",
              2.0 * r_max, " m"));
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() =
      "pelletdem's C++ engine: DEM with the linear hysteretic adhesive contact law and "
      "parallel bonds. Use the Python layer (pelletdem) rather than this module directly.";

  auto param_err = py::register_exception<ParameterError>(m, "ParameterError", PyExc_ValueError);
  auto sim_err = py::register_exception<SimulationError>(m, "SimulationError", PyExc_RuntimeError);
  py::register_exception<ParticleEscapedError>(m, "ParticleEscapedError", sim_err.ptr());
  py::register_exception<OverlapError>(m, "OverlapError", sim_err.ptr());
  py::register_exception<NonFiniteError>(m, "NonFiniteError", sim_err.ptr());
  (void)param_err;
  bind_laws(m);
  bind_world(m);

  m.attr("TIME_STEP_SAFETY") = World::kTimeStepSafety;
  m.def("truncated_normal_radii", &checked_truncated_normal_radii, py::arg("n"), py::arg("mean"),
        py::arg("sd"), py::arg("r_min"), py::arg("r_max"), py::arg("seed"),
        "Radii (m) from a normal distribution truncated to [r_min, r_max], seeded.");
  m.def(
      "random_pack_cylinder",
      [](const py::object& radii, double cx, double cy, double radius, double z_lo, double z_hi,
         std::uint64_t seed, long max_attempts) {
        std::vector<double> r = to_vector(radii, "radii");
        check_pack_region(r, cx, cy, radius, z_lo, z_hi);
        std::vector<Vec3> x;
        {
          py::gil_scoped_release rel;
          x = random_pack_cylinder(r, cx, cy, radius, z_lo, z_hi, seed, max_attempts);
        }
        return py::make_tuple(copy_vec3(x), copy_vector(r));
      },
      py::arg("radii"), py::arg("cx"), py::arg("cy"), py::arg("radius"), py::arg("z_lo"), py::arg("z_hi"),
      py::arg("seed"), py::arg("max_attempts") = 100000,
      "Random non-overlapping placement in a z-aligned cylinder; returns (positions, radii) sorted along z.");
  m.def(
      "brute_force_pairs",
      [](const py::object& x, const py::object& r, double skin) {
        Particles p;
        auto xx = to_vec3_array(x, "positions");
        auto rr = to_vector(r, "radii");
        if (xx.size() != rr.size()) throw ParameterError("positions and radii must have the same length");
        for (std::size_t k = 0; k < xx.size(); ++k) p.push(xx[k], rr[k], 1.0);
        auto pairs = NeighborList::brute_force(p, skin);
        std::vector<Index> i, j;
        for (auto& q : pairs) {
          i.push_back(q.first);
          j.push_back(q.second);
        }
        return py::make_tuple(copy_vector(i), copy_vector(j));
      },
      "Reference O(N^2) pair search (for tests): pairs closer than r_i + r_j + skin.");
  m.def(
      "neighbor_pairs",
      [](const World& w) {
        const NeighborList& nb = w.neighbors();
        std::vector<Index> i, j;
        for (std::size_t a = 0; a + 1 < nb.start.size(); ++a)
          for (Index k = nb.start[a]; k < nb.start[a + 1]; ++k) {
            i.push_back(static_cast<Index>(a));
            j.push_back(nb.j[k]);
          }
        return py::make_tuple(copy_vector(i), copy_vector(j));
      },
      "The world's current neighbour pairs (i < j) as two arrays.");
}
