#pragma once
// Everything that makes up a world's state, so a run can be saved and resumed bit for bit:
// particles (with the forces of the last step, which the next half-kick uses), the history of
// every contact, walls with their contact histories, bonds, broken bonds and the clock.
#include <limits>
#include <vector>

#include "pelletdem/bonds.hpp"
#include "pelletdem/walls.hpp"

namespace pelletdem {

struct WorldState {
  double time = 0.0;
  long step = 0;
  double ramp_start = 0.0, ramp_duration = -1.0;
  double max_overlap_seen = 0.0;
  double load_peak_from = std::numeric_limits<double>::infinity(), load_peak = 0.0;
  double load_smoothing = 1.0, load_smoothed = -std::numeric_limits<double>::infinity();
  bool forces_valid = false;
  std::vector<Vec3> x, v, w, f, t;
  // Positions at the last neighbour-list build (empty: unknown). The restored world builds its
  // list from them, so it holds the same pairs as the saved one, in which the bonded pairs'
  // forces add up in the same order, and is rebuilt at the same steps.
  std::vector<Vec3> x_build;
  std::vector<double> r, m;
  // Contacts whose history is not blank (pairs i < j).
  std::vector<Index> ci, cj;
  std::vector<double> c_delta0;
  std::vector<Vec3> c_ft;
  std::vector<Wall> walls;
  std::vector<int> load_walls;
  std::vector<Bond> bonds;
  std::vector<BrokenBond> broken;
};

}  // namespace pelletdem
