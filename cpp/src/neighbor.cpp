#include "pelletdem/neighbor.hpp"

#include <omp.h>
#include <algorithm>
#include <cmath>

#include "pelletdem/errors.hpp"

namespace pelletdem {

void NeighborList::build(const Particles& p, const Box& box, double skin, double r_max, long step,
                         int threads) {
  const std::size_t n = p.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (!box.contains(p.x[i]))
      throw ParticleEscapedError(
          cat("particle ", i, " at (", p.x[i].x(), ", ", p.x[i].y(), ", ", p.x[i].z(),
              ") m left the domain box [", box.lo.x(), ", ", box.hi.x(), "] x [", box.lo.y(), ", ",
              box.hi.y(), "] x [", box.lo.z(), ", ", box.hi.z(), "] at step ", step,
              ": a wall let it through or it was thrown out; likely causes: time step too large or "
              "loading speed too high"));
  }
  // Cells no smaller than the largest possible cutoff, so 27 cells hold every neighbour.
  const double cell = 2.0 * r_max + skin;
  const Vec3 ext = box.hi - box.lo;
  // Counted in floating point first: an empty world has cell 0 and a 1e300 m box has more
  // cells than an int holds, and neither may overflow the cast or allocate the grid.
  auto cells_along = [&](double e) {
    const double q = cell > 0.0 ? std::floor(e / cell) : 1.0;
    return q >= 1.0 ? static_cast<int>(std::min(q, 1e9)) : 1;
  };
  const int nx = cells_along(ext.x()), ny = cells_along(ext.y()), nz = cells_along(ext.z());
  constexpr double kMaxCells = 1 << 24;
  if (static_cast<double>(nx) * ny * nz > kMaxCells)
    throw ParameterError(cat("the domain box [", box.lo.transpose(), "] .. [", box.hi.transpose(), "] m is ",
                             static_cast<double>(nx) * ny * nz, " neighbour cells of ", cell,
                             " m (2 r_max + skin): allowed at most ", kMaxCells,
                             " cells; shrink the box to the particles' reach"));
  const double sx = nx / ext.x(), sy = ny / ext.y(), sz = nz / ext.z();
  const std::size_t ncell = static_cast<std::size_t>(nx) * ny * nz;
  auto cell_of = [&](const Vec3& x, int& cx, int& cy, int& cz) {
    cx = std::min(nx - 1, std::max(0, static_cast<int>((x.x() - box.lo.x()) * sx)));
    cy = std::min(ny - 1, std::max(0, static_cast<int>((x.y() - box.lo.y()) * sy)));
    cz = std::min(nz - 1, std::max(0, static_cast<int>((x.z() - box.lo.z()) * sz)));
  };
  // Counting sort of particles into cells; items within a cell stay in index order.
  cell_start_.assign(ncell + 1, 0);
  std::vector<Index> cell_id(n);
  for (std::size_t i = 0; i < n; ++i) {
    int cx, cy, cz;
    cell_of(p.x[i], cx, cy, cz);
    cell_id[i] = static_cast<Index>((static_cast<std::size_t>(cz) * ny + cy) * nx + cx);
    ++cell_start_[cell_id[i] + 1];
  }
  for (std::size_t c = 0; c < ncell; ++c) cell_start_[c + 1] += cell_start_[c];
  cell_items_.resize(n);
  {
    std::vector<Index> fill(cell_start_.begin(), cell_start_.end() - 1);
    for (std::size_t i = 0; i < n; ++i) cell_items_[fill[cell_id[i]]++] = static_cast<Index>(i);
  }

  auto visit = [&](std::size_t i, auto&& emit) {
    int cx, cy, cz;
    cell_of(p.x[i], cx, cy, cz);
    const Vec3 xi = p.x[i];
    const double ri = p.r[i];
    for (int dz = -1; dz <= 1; ++dz) {
      const int z = cz + dz;
      if (z < 0 || z >= nz) continue;
      for (int dy = -1; dy <= 1; ++dy) {
        const int y = cy + dy;
        if (y < 0 || y >= ny) continue;
        for (int dx = -1; dx <= 1; ++dx) {
          const int x = cx + dx;
          if (x < 0 || x >= nx) continue;
          const std::size_t c = (static_cast<std::size_t>(z) * ny + y) * nx + x;
          for (Index k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
            const Index jj = cell_items_[k];
            if (jj <= i) continue;
            const double cut = ri + p.r[jj] + skin;
            if ((p.x[jj] - xi).squaredNorm() < cut * cut) emit(jj);
          }
        }
      }
    }
  };
  // One search per particle: each thread lists the pairs of its contiguous share of particles
  // into its own buffer (sorted by j per particle), then the shares are laid end to end.
  // The list is the same whatever the thread count.
  const int nt = std::max(1, std::min(threads, static_cast<int>(std::max<std::size_t>(n, 1))));
  if (static_cast<int>(share_j_.size()) < nt) share_j_.resize(nt);
  new_start_.assign(n + 1, 0);
  const bool have_old = start.size() == n + 1;
#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    const long q = static_cast<long>(n) / nt, extra = static_cast<long>(n) % nt;
    const long lo = q * tid + std::min<long>(tid, extra), hi = lo + q + (tid < extra ? 1 : 0);
    std::vector<Index>& buf = share_j_[tid];
    buf.clear();
    for (long i = lo; i < hi; ++i) {
      const std::size_t b0 = buf.size();
      visit(static_cast<std::size_t>(i), [&](Index jj) { buf.push_back(jj); });
      std::sort(buf.begin() + b0, buf.end());
      new_start_[i + 1] = static_cast<Index>(buf.size() - b0);
    }
#pragma omp barrier
#pragma omp single
    {
      for (std::size_t i = 0; i < n; ++i) new_start_[i + 1] += new_start_[i];
      new_j_.resize(new_start_[n]);
      new_first_.resize(new_start_[n]);
      new_history_.assign(new_start_[n], ContactHistory{});
    }
    if (hi > lo) std::copy(buf.begin(), buf.end(), new_j_.begin() + new_start_[lo]);
    for (long i = lo; i < hi; ++i) {
      std::fill(new_first_.begin() + new_start_[i], new_first_.begin() + new_start_[i + 1],
                static_cast<Index>(i));
      if (!have_old) continue;
      // Linear merge of the old and the new sorted slices carries the history over.
      const Index* out = new_j_.data() + new_start_[i];
      const Index k = new_start_[i + 1] - new_start_[i];
      Index a = start[i], a_end = start[i + 1];
      for (Index b = 0; b < k && a < a_end; ++b) {
        while (a < a_end && j[a] < out[b]) ++a;
        if (a < a_end && j[a] == out[b]) new_history_[new_start_[i] + b] = history[a];
      }
    }
  }
  start.swap(new_start_);
  j.swap(new_j_);
  first.swap(new_first_);
  history.swap(new_history_);
  mark_live();
}

void NeighborList::mark_live() {
  ++generation;
  live.resize(history.size());
  for (std::size_t k = 0; k < history.size(); ++k) live[k] = !history[k].blank();
}

std::vector<std::pair<Index, Index>> NeighborList::brute_force(const Particles& p, double skin) {
  std::vector<std::pair<Index, Index>> out;
  const std::size_t n = p.size();
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t k = i + 1; k < n; ++k) {
      const double cut = p.r[i] + p.r[k] + skin;
      if ((p.x[k] - p.x[i]).squaredNorm() < cut * cut)
        out.emplace_back(static_cast<Index>(i), static_cast<Index>(k));
    }
  return out;
}

}  // namespace pelletdem
