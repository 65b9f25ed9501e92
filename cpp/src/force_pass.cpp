// The force pass (World::compute_forces): the particle records packed, the pair loop and the
// bond loop run on the threads, the walls' contacts, and the threads' loads reduced in a fixed
// order, with the step's closing half kick or left for the next drift pass.
#include <omp.h>
#include <algorithm>
#include <cmath>

#include "pair_loop.hpp"
#include "pelletdem/integrate.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem {

void World::size_particle_scratch() {
  const std::size_t n = p_.size();
  xr_.resize(n);
  mo_.resize(n);
  spin_inv_.resize(n);
  if (loads_.empty()) loads_.resize(1);
  loads_[0].resize(n);
}

double World::adhesion_scale() const {
  if (ramp_duration_ < 0.0 || time_ < ramp_start_) return 1.0;
  if (ramp_duration_ == 0.0) return 0.0;
  return std::max(0.0, 1.0 - (time_ - ramp_start_) / ramp_duration_);
}

void World::compute_forces(bool advance, Finish finish) {
  const long n = static_cast<long>(p_.size());
  const int nt = team();
  size_particle_scratch();
  if (static_cast<int>(loads_.size()) < nt) loads_.resize(nt);
  for (int k = 1; k < nt; ++k) loads_[k].resize(n);
  const double dt = params_.dt;
  // Incremental springs advance by v dt only when the particles moved since the last force
  // evaluation; a recomputation in place (after set_velocities, a new wall, a restored state)
  // must not stretch them again.
  const double dt_inc = advance ? dt : 0.0;
  const double adh = adhesion_scale();
  const ContactLawParams& cp = law_.params();
  // Bonded pairs in the list go with the pair loop; the rest (orphans_) through bond_loop.
  if (!bonds_.empty() && bond_map_generation_ != nbr_.generation) map_bonds();
  const long n_orphans = static_cast<long>(orphans_.size());
  std::vector<long> contacts_t(nt, 0);
  std::vector<double> maxov_t(nt, 0.0);
  std::vector<Index> maxov_i_t(nt, 0);
  std::vector<std::vector<long>> broke_t(nt);
  const int nt_walls = start_walls(nt);
  // Each thread takes a run of particles holding an equal share of the listed pairs, not of
  // the particles: a compacted pellet is denser under the piston, and equal particle shares
  // left one thread waiting for the other at the barrier (~11 % of a step in libgomp).
  std::vector<long> run(nt + 1, n);
  for (int t = 0; t < nt; ++t) {
    const double target = static_cast<double>(nbr_.start[n]) * t / nt;
    run[t] = std::lower_bound(nbr_.start.begin(), nbr_.start.begin() + n, target) - nbr_.start.begin();
  }
  load_range_.assign(2 * static_cast<std::size_t>(nt), 0);
  const LoadSums sums = load_sums(nt);

#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    Load* A = loads_[tid].data();
    long lo = run[tid], hi = run[tid + 1];
    long blo = 0, bhi = 0;
    if (n_orphans > 0) static_share(n_orphans, nt, tid, blo, bhi);
    if (tid > 0) {
      // Thread t's buffer holds its pairs' particles (bonded pairs among them), its orphan
      // bonds' and the wall contacts of its
      // run: zeroing and summing only that range keeps the other core's half out of this
      // one's cache (zeroing all N and reading it back across cores cost ~10 % of a
      // two-thread step).
      long rlo = lo, rhi = hi;
      const Index* J = nbr_.j.data();
      Index jmin = static_cast<Index>(lo), jmax = 0;
      for (Index k = nbr_.start[lo]; k < nbr_.start[hi]; ++k) {
        jmin = std::min(jmin, J[k]);
        jmax = std::max(jmax, J[k]);
      }
      rlo = std::min<long>(rlo, jmin);
      rhi = std::max<long>(rhi, static_cast<long>(jmax) + 1);
      for (long e = blo; e < bhi; ++e) {
        const Bond& b = bonds_[orphans_[e]];
        rlo = std::min<long>(rlo, std::min(b.i, b.j));
        rhi = std::max<long>(rhi, std::max(b.i, b.j) + 1);
      }
      if (rhi <= rlo) rlo = rhi = 0;
      load_range_[2 * tid] = rlo;
      load_range_[2 * tid + 1] = rhi;
      std::fill(loads_[tid].begin() + rlo, loads_[tid].begin() + rhi, Load{});
    }
    if (!prepared_) {
      long lo, hi;
      static_share(n, nt, tid, lo, hi);
      pack_particles(lo, hi, p_, 1.0 / dt, cp.rolling > 0.0, loads_[0].data(), xr_.data(), mo_.data(),
                     spin_inv_.data());
#pragma omp barrier
    }
    const PairStats ps = bonds_.empty()
                             ? pair_loop_plain(lo, hi, p_, xr_.data(), nbr_, law_, cp, dt_inc, adh,
                                               mo_.data(), A, vector_kernels_)
                             : pair_loop_bonded(lo, hi, p_, xr_.data(), nbr_, law_, cp, dt_inc, adh,
                                                mo_.data(), A, vector_kernels_,
                                                BondedPairs{bonds_.data(), slots_.data(), pair_slot_.data(),
                                                            slot_bond_.data(), &broke_t[tid], bonds_soften_});
    // A thread's orphan bonds add to its own buffers, so it goes on to them without waiting
    // for the others' pairs; the reduction below waits for all.
    if (n_orphans > 0)
      bond_loop(bonds_, orphans_.data(), blo, bhi, p_, xr_.data(), mo_.data(), dt_inc, bonds_soften_, A,
                broke_t[tid], vector_kernels_);
    // The wall contacts of this thread's run of particles go into its own buffer as well.
    if (tid < nt_walls) wall_share(tid, nt_walls, nt_walls == 1 ? 0 : lo, nt_walls == 1 ? n : hi, dt_inc, A);
#pragma omp barrier
    contacts_t[tid] = ps.contacts;
    maxov_t[tid] = ps.max_ov;
    maxov_i_t[tid] = ps.max_ov_i;
    // Reduce the thread buffers in a fixed order: the same thread count gives the same bits.
    // With step()'s closing half kick, here while the forces are in registers (a pass of its
    // own read and wrote the velocities again: 4 % of a step), or left to the next drift pass.
    if (finish != Finish::Defer) {
      static_share(n, nt, tid, lo, hi);
      reduce_loads(lo, hi, sums, finish == Finish::ReduceKick ? 0.5 * dt : 0.0, p_);
    }
  }
  kick_pending_ = finish == Finish::Defer;
  kick_nt_ = nt;
  finish_walls(nt_walls);
  n_contacts_ = 0;
  max_overlap_ = 0.0;
  for (int k = 0; k < nt; ++k) {
    n_contacts_ += contacts_t[k];
    if (maxov_t[k] > max_overlap_) {
      max_overlap_ = maxov_t[k];
      max_overlap_i_ = maxov_i_t[k];
    }
  }
  // Broken bonds in bond order, whatever the thread count.
  std::vector<long> broke;
  for (int k = 0; k < nt; ++k) broke.insert(broke.end(), broke_t[k].begin(), broke_t[k].end());
  std::sort(broke.begin(), broke.end());
  const double marker = load_marker();
  for (long b : broke) {
    Bond& bond = bonds_[b];
    const Vec3 d = p_.x[bond.j] - p_.x[bond.i];
    const double dist = d.norm();
    const double half_gap = 0.5 * (dist - p_.r[bond.i] - p_.r[bond.j]);
    const Vec3 centre = p_.x[bond.i] + (p_.r[bond.i] + half_gap) * d / dist;
    // compute_forces runs after step() advanced time_ and step_: they are the breakage time.
    broken_.push_back(BrokenBond{time_, step_, bond.i, bond.j, centre, bond.mode, bond.sigma_max(),
                                 bond.tau_max(), marker});
    bond.fn = 0.0;
    bond.ft.setZero();
    bond.mn = 0.0;
    bond.mt.setZero();
  }
  max_overlap_seen_ = std::max(max_overlap_seen_, max_overlap_);
  prepared_ = false;
}

LoadSums World::load_sums(int nt) const {
  return LoadSums{
      loads_.data(),     nt, params_.gravity / params_.density_scale, mo_.data(), spin_inv_.data(),
      load_range_.data()};
}

void World::finish_pending_kick() {
  if (!kick_pending_) return;
  const long n = static_cast<long>(p_.size());
  const LoadSums sums = load_sums(kick_nt_);
  const double half_dt = 0.5 * params_.dt;
#pragma omp parallel num_threads(kick_nt_)
  {
    long lo, hi;
    static_share(n, kick_nt_, omp_get_thread_num(), lo, hi);
    reduce_loads(lo, hi, sums, half_dt, p_);
  }
  kick_pending_ = false;
}

}  // namespace pelletdem
