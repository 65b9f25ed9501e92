#pragma once
// The world: particles, walls, bonds, the contact table and the integrator. One call runs
// thousands of steps; stop conditions are evaluated here, never in Python.
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "pelletdem/bonds.hpp"
#include "pelletdem/contact_law.hpp"
#include "pelletdem/integrate.hpp"
#include "pelletdem/neighbor.hpp"
#include "pelletdem/particles.hpp"
#include "pelletdem/state.hpp"
#include "pelletdem/walls.hpp"

namespace pelletdem {

struct WorldParams {
  double dt = 2.0e-6;                // time step, s
  Vec3 gravity = Vec3(0, 0, -9.81);  // physical gravity, m/s^2 (divided by density_scale)
  double density = 680.0;            // particle solid density, kg/m^3 (Table 4)
  double density_scale = 1.0e4;      // mass factor; gravity is divided by it (section 3.1.2)
  double skin = 2.0e-5;              // Verlet skin, m
  Box box;                           // the domain; leaving it is an error
  int threads = 1;
  double max_overlap_ratio = 0.9;  // guard: delta / r beyond this stops the run
  long sample_interval = 100;      // steps between samples of the time series
  ContactLawParams contact;
  void validate() const;
};

enum class StopKind {
  Time,                        // time >= value, s
  Steps,                       // steps run in this call >= value
  KineticEnergyBelow,          // kinetic energy < value, J (scaled mass)
  InternalKineticEnergyBelow,  // kinetic energy about the centre of mass < value, J
  WallForceAbove,              // wall's compressive normal force >= value, N
  WallForceBelow,              // wall's compressive normal force <= value, N
  WallTravelAbove,             // wall's travel along its normal >= value, m
  LoadMarkerAbove,             // load marker (sum of travels of load walls) >= value, m
  LoadDropBelow,               // smoothed load force <= value * its peak (track_load_peak), 0 < value < 1
};

struct StopCondition {
  StopKind kind;
  double value;
  int wall = -1;
  long check_interval = 1;  // steps between checks (kinetic energy costs a pass)
};

// One spring of the time step guard (World::time_step_springs).
struct TimeStepSpring {
  std::string what;  // where it acts and what sets it, in the parameters' names
  double k;          // its stiffness as the law gives it (walls' and eq. 7's scale in it), N/m
  double k_eff;      // the stiffness it puts on the lightest particle: x2 between two particles
                     // (the reduced mass), x3.5 tangential (the spin it drives), N/m
  double zeta;       // its viscous damping, fraction of critical (-)
  double dt_limit;   // 2 / omega (sqrt(1 + zeta^2) - zeta), omega^2 = k_eff / m_min, s
};

struct RunOutcome {
  int condition = -1;  // index of the condition that fired; -1: the step budget ran out
  long steps = 0;
};

// One row of the global time series.
struct Sample {
  double time, kinetic_energy, coordination_number, max_overlap_ratio, load_marker;
  long n_contacts, n_bonds_intact, n_bonds_broken;
};

struct WallSample {
  double time;
  Vec3 force;
  double normal_force;
  Vec3 point;
  double radius;
  double travel;
};

class World {
 public:
  explicit World(const WorldParams& params);

  // --- set-up ----------------------------------------------------------------------------
  void add_particles(const std::vector<Vec3>& x, const std::vector<double>& r);
  int add_plane(const std::string& name, const Vec3& point, const Vec3& normal);
  int add_cylinder(const std::string& name, const Vec3& axis_point, double radius);
  Wall& wall(int k);
  const Wall& wall(int k) const;
  int wall_count() const { return static_cast<int>(walls_.size()); }
  void set_contact_params(const ContactLawParams& c);
  void set_dt(double dt);
  void set_threads(int threads);
  void set_gravity(const Vec3& g);
  void set_load_walls(const std::vector<int>& walls);
  void set_adhesion_ramp(double t_start, double duration);  // kc scaled 1 -> 0 over it
  void set_max_overlap_ratio(double ratio);

  // --- running -----------------------------------------------------------------------------
  void step();
  void run(long n);
  RunOutcome run_until(const std::vector<StopCondition>& conditions, long max_steps);

  // --- bonds -------------------------------------------------------------------------------
  // Bonds every pair whose surfaces are closer than params.gap_tolerance (touching pairs when
  // 0), stress-free now. Returns the number created.
  long create_bonds(const BondParams& params);
  const std::vector<Bond>& bonds() const {
    flush_slots();
    return bonds_;
  }
  // For changing bonds' constants: the slots are rebuilt from the records before the next step.
  std::vector<Bond>& bonds_mut() {
    flush_slots();
    guard_stale_ = true;  // stiffer bonds may lower the stable step: checked before the next step
    slots_live_ = false;
    bond_map_generation_ = -1;
    return bonds_;
  }
  const std::vector<BrokenBond>& broken_bonds() const { return broken_; }
  long intact_bond_count() const;

  // --- state -------------------------------------------------------------------------------
  Particles& particles() { return p_; }
  const Particles& particles() const { return p_; }
  const WorldParams& params() const { return params_; }
  double time() const { return time_; }
  long step_count() const { return step_; }
  double kinetic_energy() const;
  // Kinetic energy in the centre-of-mass frame (a pellet drifting as a whole has none), J.
  double internal_kinetic_energy() const;
  Vec3 mean_velocity() const;  // mass-weighted, m/s
  void remove_mean_velocity();
  double potential_energy() const;  // contacts, bonds and (scaled) gravity, J
  double coordination_number() const;
  long contact_count() const { return n_contacts_; }
  double max_overlap_ratio_seen() const { return max_overlap_seen_; }
  void reset_max_overlap_seen() { max_overlap_seen_ = 0.0; }
  double load_marker() const;
  // Mean compressive normal force of the load walls, N (0 when there are none).
  double load_force() const;
  // The LoadDropBelow stop, a test machine's break detection: from now on the world keeps
  // load_force() averaged over ~smoothing_steps steps (exponential mean, load_smoothed, N) and,
  // from the step at which the load marker reaches from_marker (m), its largest value
  // (load_peak, N). Both are part of the saved state: a resumed test stops where it would have.
  // from_marker = inf stops keeping them.
  void track_load_peak(double from_marker, double smoothing_steps = 1.0);
  double load_peak() const { return load_peak_; }
  double load_smoothed() const { return load_smoothed_ == -kInf ? 0.0 : load_smoothed_; }
  // The time step guard (time_step.cpp). Each spring the laws can reach, with the stiffness
  // it puts on the lightest particle and the stability limit it sets; the smallest limit
  // (critical_time_step, s); and the largest dt the world accepts, kTimeStepSafety of it (s).
  std::vector<TimeStepSpring> time_step_springs() const;
  double critical_time_step() const;
  double max_time_step() const { return kTimeStepSafety * critical_time_step(); }
  // The fraction of the stiffest single spring's limit that the guard allows. A particle
  // pressed by many contacts at once has network modes above a single contact's: for the
  // chosen model's peak-compaction network an eigenvalue estimate gave 0.76 of the
  // single-contact limit (4.3-4.4e-6 s against 5.7e-6 s). 0.5 refuses that network's
  // unstable steps with a margin, and keeps the presets' 2e-6 s for it.
  static constexpr double kTimeStepSafety = 0.5;
  // Threads a step uses: below kParallelMin particles one thread is faster than a team (the
  // fork/join and barrier cost exceeds the work), so small systems run serial.
  static constexpr std::size_t kParallelMin = 2048;
  int team() const { return p_.size() >= kParallelMin ? params_.threads : 1; }
  double adhesion_scale() const;
  const NeighborList& neighbors() const { return nbr_; }
  long rebuild_count() const { return rebuilds_; }
  // The four-lane pair and bond kernels (on by default). They give the scalar kernels' bits;
  // switching them off is for the test that checks exactly that.
  void set_vector_kernels(bool on) { vector_kernels_ = on; }
  bool vector_kernels() const { return vector_kernels_; }
  // Pairs currently overlapping: (i, j, overlap m, normal force N).
  void contacts(std::vector<Index>& i, std::vector<Index>& j, std::vector<double>& overlap,
                std::vector<double>& fn) const;

  // --- time series -------------------------------------------------------------------------
  const std::vector<Sample>& samples() const { return samples_; }
  const std::vector<WallSample>& wall_samples(int k) const { return wall_samples_.at(k); }
  void clear_samples();
  void set_sample_interval(long n);
  void record_sample();

  // --- numpy views: the bindings refuse to add particles while a view is alive ----------------
  std::shared_ptr<int> view_counter() const { return views_; }

  // A deep copy (a relaxed pellet branches into many bond-parameter runs); views not shared.
  World clone() const {
    World w(*this);
    w.views_ = std::make_shared<int>(0);
    return w;
  }
  // Positions/velocities set from outside invalidate the contact list and the forces.
  void invalidate() {
    list_valid_ = false;
    forces_valid_ = false;
  }

  // Save and restore the whole state. load_state needs a world built with the same
  // WorldParams; after it the next step is exactly the step the saved world would have taken.
  WorldState save_state() const;
  void load_state(const WorldState& s);
  // Renumbers the particles in Morton order of their neighbour cells, so that particles in
  // contact sit near each other in memory (a settled bed's pair loop then runs from cache).
  // Everything moves with them: velocities, forces, contact and wall histories; the dynamics
  // are the same up to the order in which forces add. Only before bonds exist, and with no
  // numpy view of the arrays alive. Returns the old index of each new particle.
  std::vector<Index> sort_particles();

  // --- restart support --------------------------------------------------------------------------
  void set_time(double t, long step) {
    time_ = t;
    step_ = step;
  }
  void set_broken_bonds(std::vector<BrokenBond> b) { broken_ = std::move(b); }

 private:
  void ensure_forces();
  void size_particle_scratch();
  // Forces and torques of the present positions (springs advanced by a step unless `advance`
  // is false) into the threads' Load buffers, and then (Finish) into Particles::f and t, with
  // step()'s closing half kick, or left in the buffers for the next step's drift pass to sum
  // and kick (run() and run_until() step that way: one pass over the particles less a step).
  enum class Finish { Reduce, ReduceKick, Defer };
  void compute_forces(bool advance = true, Finish finish = Finish::Reduce);
  // The deferred closing half kick (Finish::Defer) done now: f, t, v, w are then the step's.
  // Whatever reads them between steps calls it; run() and run_until() call it before they
  // return or throw.
  void finish_pending_kick();
  LoadSums load_sums(int nt) const;
  void advance(bool defer);  // one step; defer: Finish::Defer
  RunOutcome run_steps_until(const std::vector<StopCondition>& conds, long max_steps);
  bool kick_pending_ = false;
  int kick_nt_ = 1;  // threads of the force pass whose kick is pending
  // The walls' part of compute_forces: start_walls zeroes the walls' sums and says how many
  // threads share the wall contacts; wall_share adds thread tid's share to its Load buffer A
  // (the wall contacts of particles [p_lo, p_hi)) and to its WallPart; finish_walls adds the
  // parts up in thread order.
  struct WallPart {
    Vec3 force = Vec3::Zero(), torque = Vec3::Zero();
    double radial = 0.0, max_ov = 0.0;
    Index max_ov_i = 0;
  };
  int start_walls(int nt);
  void wall_share(int tid, int nt_walls, long p_lo, long p_hi, double dt_inc, Load* A);
  void finish_walls(int nt_walls);
  std::vector<WallPart> wall_part_;
  // Particles [lo, hi) whose Load records thread t > 0 zeroed and filled in the last force
  // pass, as (lo, hi) pairs per thread (thread 0's buffer covers every particle).
  std::vector<long> load_range_;
  // Marks the neighbour-list pairs that have an intact bond (NeighborList::kLiveBonded) and
  // moves those bonds' state into slots_, in list order (pair k's slot in pair_slot_, slot s's
  // bond in slot_bond_): the pair loop updates them with their contacts, four consecutive
  // slots at a time. Intact bonds whose pair is not in the list go to orphans_ and stay in
  // their records. Done when the list changed since the last time (bond_map_generation_ !=
  // nbr_.generation), after flushing the slots back.
  void map_bonds();
  // While slots_live_, the slotted bonds' state (BondBlock's fields) is in slots_ and their
  // records' copies may be stale; this writes them back (intact bonds only: a bond that broke
  // was last written to its record), and the slots stay in use. Every reader of bonds_ outside
  // the force pass calls it.
  void flush_slots() const;
  std::vector<Index> pair_slot_;
  std::vector<Index> slot_bond_;
  mutable std::vector<BondBlock> slots_;
  mutable bool slots_live_ = false;
  std::vector<Index> orphans_;
  long bond_map_generation_ = -1;
  bool bonds_soften_ = false;  // some intact bond softens or is damaged (map_bonds)
  void move_walls();
  void rebuild();
  void build_wall_lists();
  bool needs_rebuild(double max_disp) const;
  void check_guards();
  double effective_skin() const;
  void validate_time_step() const;
  // The spring with the smallest stability limit (nullptr: no particles), from `springs`.
  static const TimeStepSpring* stiffest(const std::vector<TimeStepSpring>& springs);
  double r_max_;

  WorldParams params_;
  Particles p_;
  NeighborList nbr_;
  std::vector<Wall> walls_;
  mutable std::vector<Bond> bonds_;  // mutable for flush_slots
  std::vector<BrokenBond> broken_;
  std::vector<Vec3> x_build_;
  std::vector<std::vector<Load>> loads_;  // per thread: its share of the forces (Load)
  // Positions and radii, and velocities, masses and rolling-friction terms (eq. 11), packed
  // for the contact kernels; refreshed by every force pass (pack_particles).
  std::vector<PosRad> xr_;
  std::vector<Motion> mo_;
  std::vector<double> spin_inv_;  // 1 / |w| (0 for a body at rest), 1/(rad/s): eq. 11's direction
  std::vector<int> load_walls_;
  std::vector<Sample> samples_;
  std::vector<std::vector<WallSample>> wall_samples_;
  std::shared_ptr<int> views_ = std::make_shared<int>(0);
  double time_ = 0.0;
  long step_ = 0;
  long rebuilds_ = 0;
  long n_contacts_ = 0;
  double max_overlap_ = 0.0, max_overlap_seen_ = 0.0;
  Index max_overlap_i_ = 0;
  bool forces_valid_ = false;
  bool list_valid_ = false;
  bool prepared_ = false;  // records packed (step's drift pass) since the last forces
  bool vector_kernels_ = true;
  // Set where the bonds or the whole state change without a check (bonds_mut, load_state):
  // step() then checks the time step before it steps (run and run_until always do). Beside
  // the other flags, in their padding: the members the step reads keep their places.
  mutable bool guard_stale_ = false;
  double ramp_start_ = 0.0, ramp_duration_ = -1.0;
  double load_peak_from_ = std::numeric_limits<double>::infinity(), load_peak_ = 0.0;
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  // -inf: no step averaged yet (a plate with wall adhesion can pull: the force may be < 0)
  double load_smoothing_ = 1.0, load_smoothed_ = -kInf;
  HystereticLaw law_;
};

// Radii from a normal distribution truncated to [r_min, r_max] (rejection sampling), seeded.
std::vector<double> truncated_normal_radii(long n, double mean, double sd, double r_min, double r_max,
                                           std::uint64_t seed);

// Random sequential addition of non-overlapping spheres inside a z-aligned cylinder between
// z_lo and z_hi. Throws ParameterError when they do not fit. Output sorted along z for locality.
std::vector<Vec3> random_pack_cylinder(std::vector<double>& radii, double cx, double cy, double radius,
                                       double z_lo, double z_hi, std::uint64_t seed, long max_attempts);

}  // namespace pelletdem
