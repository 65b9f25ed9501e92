#pragma once
// Parallel bonds (Potyondy & Cundall 2004; the paper's eq. 12-15). Each bond carries its own
// incremental force and moment, stored in the bond's frame which turns with the pair, so a
// rigid rotation of a bonded pair creates no force. Bonds live in their own list, apart from
// the contact table: they persist until they break, however far the pair moves apart.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "pelletdem/effects_list.hpp"
#include "pelletdem/params.hpp"
#include "pelletdem/vec.hpp"

namespace pelletdem {

// The paper's parallel bond, one row per parameter (params.hpp); the candidate effects' rows
// (effects/*.hpp) follow them in BondParams.
#define PELLETDEM_BOND_ROWS(X)                                                                             \
  X(double, radius, 2.0e-5, Positive, 1e-9, 1.0, "m", "bond radius r_b", true,                             \
    "bond radius r_b: Table 4 (10-40 um; 20 um chosen in section 3.2.3 from SEM images)")                  \
  X(double, youngs_modulus, 120e6, Positive, 0.0, kHuge, "Pa", "bond Young's modulus E_b", true,           \
    "bond Young's modulus E_b, k_n^b = E_b / (r_i + r_j), eq. 13: Table 5 (oak, MC 8 %, 120 MPa); fitted " \
    "per variant")                                                                                         \
  X(double, kt_ratio, 1.0, Range, 0.0, 100.0, "-", "bond kt_ratio", true,                                  \
    "k_t^b / k_n^b; ours: 1, the paper leaves it open")                                                    \
  X(double, sigma_c, 36e6, Positive, 0.0, kHuge, "Pa", "bond tension strength sigma_c", true,              \
    "bond tension strength, eq. 14: Table 5 (oak, MC 8 %, 120 MPa); fitted per variant")                   \
  X(double, tau_c, 36e6, Positive, 0.0, kHuge, "Pa", "bond shear strength tau_c", true,                    \
    "bond shear strength, eq. 14: Table 5 (equal to sigma_c in the paper's calibration)")                  \
  X(double, gap_tolerance, 0.0, NonNegative, 0.0, kHuge, "m", "bond gap_tolerance", true,                  \
    "pairs whose surfaces are closer than this get a bond too; ours: 0, touching pairs only")

#define PELLETDEM_BOND_ALL_ROWS(X) PELLETDEM_BOND_ROWS(X) PELLETDEM_BOND_EFFECT_ROWS(X)

struct BondParams {
  PELLETDEM_BOND_ALL_ROWS(PELLETDEM_PARAM_FIELD)
  // Not rows: the sawdust's moisture is the contact law's (one value per world), copied here
  // by World::create_bonds for the bond effects that read it, %.
  double moisture_content = 8.0, moisture_reference = 8.0;
  void validate() const { PELLETDEM_BOND_ALL_ROWS(PELLETDEM_PARAM_CHECK) }
  static std::vector<ParamRow> rows() { return {PELLETDEM_BOND_ALL_ROWS(PELLETDEM_PARAM_ROW)}; }
};

enum class BondMode : std::uint8_t { Intact = 0, Tension = 1, Shear = 2 };

// The field order matters: the bond loop loads (n_prev, fn), (ft, mn), (mt, radius) and
// (kn, kt, sigma_c, tau_c) as runs of four doubles (forces.cpp checks it at compile time).
struct Bond {
  Index i, j;
  Vec3 n_prev;                            // normal at the last update, for turning the stored vectors
  double fn = 0.0;                        // normal force on j along n, N (> 0 compression, < 0 tension)
  Vec3 ft = Vec3::Zero();                 // tangential force on j, N
  double mn = 0.0;                        // twisting moment on j about n, N m
  Vec3 mt = Vec3::Zero();                 // bending moment on j, N m
  double radius, kn, kt, sigma_c, tau_c;  // per bond, so spreads of strength are possible
  double softening = 0.0;                 // the bond's softening (effects/bond_softening.hpp); 0 brittle
  double damage = 0.0;  // 0 intact .. 1 gone: the capacity left is (1 - damage) sigma_c, tau_c
  BondMode mode = BondMode::Intact;

  double area() const { return kPi * radius * radius; }
  double polar_moment() const { return 0.5 * kPi * radius * radius * radius * radius; }
  // Maximum normal and shear stress of eq. 14, Pa.
  double sigma_max() const { return -fn / area() + 2.0 * mt.norm() * radius / polar_moment(); }
  double tau_max() const { return ft.norm() / area() + std::abs(mn) * radius / polar_moment(); }
};

// Four bonds' loading state and constants, one bond per lane, as the pair loop keeps the bonds
// whose pairs are in the neighbour list (World::map_bonds puts them in "slots", in list order,
// four to a block). A group of four bonded pairs then reads and writes its bonds with one
// aligned vector load or store per field, where gathering them from four Bond records and
// transposing them made the bonds' share of a step about a sixth larger (README, Performance).
// Besides the state, the constants that the update uses, computed once when the slots are
// filled: k_n A, k_t A, k_t J, k_n J / 2 (eq. 12's stiffnesses without dt) and sigma_c A r_b,
// tau_c A r_b (the strength bounds' right-hand sides, as the four-lane kernel tests them).
struct alignas(64) BondBlock {
  enum Field {
    NX,
    NY,
    NZ,
    FN,
    FTX,
    FTY,
    FTZ,
    MN,
    MTX,
    MTY,
    MTZ,
    RADIUS,
    KN_A,
    KT_A,
    KT_J,
    KN_HALF_J,
    SIGMA_AR,
    TAU_AR,
    kFields
  };
  double f[kFields][4];
};

// A slot that holds no bond (the padding before a run of slots starts a block).
constexpr Index kNoBond = ~Index{0};

// Slot s of `blocks` (block s / 4, lane s % 4): its state into a Bond's fields of the same
// names (the record holds the constants), and a Bond's state and constants into it.
inline void load_slot(const BondBlock* blocks, std::size_t s, Bond& b) {
  const BondBlock& k = blocks[s / 4];
  const std::size_t l = s % 4;
  b.n_prev = Vec3(k.f[BondBlock::NX][l], k.f[BondBlock::NY][l], k.f[BondBlock::NZ][l]);
  b.fn = k.f[BondBlock::FN][l];
  b.ft = Vec3(k.f[BondBlock::FTX][l], k.f[BondBlock::FTY][l], k.f[BondBlock::FTZ][l]);
  b.mn = k.f[BondBlock::MN][l];
  b.mt = Vec3(k.f[BondBlock::MTX][l], k.f[BondBlock::MTY][l], k.f[BondBlock::MTZ][l]);
}
inline void store_slot(BondBlock* blocks, std::size_t s, const Bond& b) {
  BondBlock& k = blocks[s / 4];
  const std::size_t l = s % 4;
  // As the bond kernels write them (kn * area * dt is (kn * area) * dt): the same bits.
  const double area = b.area(), jpolar = b.polar_moment();
  const double v[BondBlock::kFields] = {b.n_prev.x(),
                                        b.n_prev.y(),
                                        b.n_prev.z(),
                                        b.fn,
                                        b.ft.x(),
                                        b.ft.y(),
                                        b.ft.z(),
                                        b.mn,
                                        b.mt.x(),
                                        b.mt.y(),
                                        b.mt.z(),
                                        b.radius,
                                        b.kn * area,
                                        b.kt * area,
                                        b.kt * jpolar,
                                        b.kn * 0.5 * jpolar,
                                        b.sigma_c * area * b.radius,
                                        b.tau_c * area * b.radius};
  for (int f = 0; f < BondBlock::kFields; ++f) k.f[f][l] = v[f];
}

struct BrokenBond {
  double time;  // s
  long step;
  Index i, j;
  Vec3 position;  // bond centre at breakage, m
  BondMode mode;
  double sigma, tau;   // stresses at breakage, Pa
  double load_marker;  // the world's load marker at breakage (e.g. plate displacement, m)
};

}  // namespace pelletdem
