#include "services/segment/fill_pockets.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

enum CellState : uint8_t { kUnobserved = 0, kFree = 1, kSolid = 2 };

// The chunk and its neighbours' cells within `pad` of it, as states and the p of free cells.
class PaddedCells {
 public:
  PaddedCells(int n, int pad, const LeafKey& chunk_min)
      : n_(n), pad_(pad), m_(n + 2 * pad), origin_(chunk_min - LeafKey::Constant(pad)) {
    const size_t cells = size_t(m_) * m_ * m_;
    state_.assign(cells, kUnobserved);
    p_.assign(cells, 0.0);
  }
  [[nodiscard]] int m() const { return m_; }
  [[nodiscard]] size_t Index(int x, int y, int z) const {
    return size_t(x) + size_t(m_) * (size_t(y) + size_t(m_) * size_t(z));
  }
  [[nodiscard]] CellState state(size_t i) const { return CellState(state_[i]); }
  [[nodiscard]] double p(size_t i) const { return p_[i]; }

  // A stored leaf covering global finest cells [lo, lo + size) on each axis.
  void Add(const LeafKey& lo, int size, const LeafStats& stats) {
    Eigen::Vector3i a, b;  // padded coordinates, clipped
    for (int d = 0; d < 3; ++d) {
      a[d] = std::max(lo[d] - origin_[d], 0);
      b[d] = std::min(lo[d] + size - origin_[d], m_);
      if (a[d] >= b[d]) return;
    }
    // A stored leaf no ray observed holds scan points only: evidence of a surface, so it ends
    // a pocket as solid space does.
    const CellState s = stats.observed() && stats.interior() ? kFree : kSolid;
    const double p = stats.p();
    for (int z = a.z(); z < b.z(); ++z) {
      for (int y = a.y(); y < b.y(); ++y) {
        const size_t row = Index(a.x(), y, z);
        std::fill(state_.begin() + ptrdiff_t(row),
                  state_.begin() + ptrdiff_t(row) + (b.x() - a.x()), uint8_t(s));
        std::fill(p_.begin() + ptrdiff_t(row), p_.begin() + ptrdiff_t(row) + (b.x() - a.x()), p);
      }
    }
  }

 private:
  int n_, pad_, m_;
  LeafKey origin_;
  std::vector<uint8_t> state_;
  std::vector<double> p_;
};

}  // namespace

absl::Status PocketFillOptions::Validate() const {
  if (!std::isfinite(max_thickness_m) || !(max_thickness_m > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "pocket fill: max_thickness_m must be a positive length in metres, got ", max_thickness_m));
  }
  return absl::OkStatus();
}

absl::StatusOr<FilledChunk> FillPockets(const ChunkNeighbourhood& hood,
                                        const PocketFillOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const int k = hood.grid.chunk_depth;
  const int n = hood.grid.leaves_per_side();
  FilledChunk out;
  const TileData* centre = hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)];
  if (centre == nullptr) {
    // All unobserved: a run through it would be longer than the chunk, so nothing to fill.
    out.tile.chunk = hood.chunk;
    out.tile.grid = hood.grid;
    return out;
  }
  out.tile = *centre;
  if (n < 2) return out;
  // Runs of up to `run` cells; their ends lie within run + 1 cells of the chunk.
  const int run = std::clamp(
      int(std::floor(options.max_thickness_m / hood.grid.resolution_m() * (1 + 1e-9))), 1, n - 1);
  const int pad = run + 1;  // ≤ n: inside the 26 neighbours
  const LeafKey chunk_min = hood.chunk * n;
  PaddedCells cells(n, pad, chunk_min);
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const TileData* tile = hood.tiles[ChunkNeighbourhood::Index(dx, dy, dz)];
        if (tile == nullptr) continue;
        const ChunkKey key = hood.chunk + ChunkKey(dx, dy, dz);
        if (tile->chunk != key || tile->grid.chunk_depth != k) {
          return absl::InvalidArgumentError(
              absl::StrCat("pocket fill: chunk ", hood.chunk.x(), ",", hood.chunk.y(), ",",
                           hood.chunk.z(), ": the neighbour slot ", dx, ",", dy, ",", dz,
                           " holds the tile of chunk ", tile->chunk.x(), ",", tile->chunk.y(), ",",
                           tile->chunk.z(), " at depth ", tile->grid.chunk_depth, " (expected ",
                           key.x(), ",", key.y(), ",", key.z(), " at depth ", k, ")"));
        }
        for (size_t i = 0; i < tile->leaves.size(); ++i) {
          const ChunkNode& node = tile->leaves[i].node;
          const int size = node.depth >= 0 && node.depth <= k ? 1 << (k - node.depth) : 0;
          if (size == 0 || (node.local.array() < 0).any() ||
              (node.local.array() * size >= n).any()) {
            return absl::InvalidArgumentError(
                absl::StrCat("pocket fill: chunk ", key.x(), ",", key.y(), ",", key.z(), " leaf ",
                             i, " lies outside its chunk (depth ", node.depth, ")"));
          }
          cells.Add(key * n + node.local * size, size, tile->leaves[i].stats);
        }
      }
    }
  }

  // Along each axis, every line through the chunk: unobserved runs of ≤ `run` cells between
  // two free cells. A cell filled along several axes takes the lowest p offered.
  const int m = cells.m();
  std::vector<double> fill(size_t(n) * n * n, std::numeric_limits<double>::infinity());
  const auto core = [&](const Eigen::Vector3i& c) {
    return size_t(c.x() - pad) +
           size_t(n) * (size_t(c.y() - pad) + size_t(n) * size_t(c.z() - pad));
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    Eigen::Vector3i c;
    for (int j = pad; j < pad + n; ++j) {
      for (int i = pad; i < pad + n; ++i) {
        c[u] = i;
        c[v] = j;
        int t = 0;
        while (t < m) {
          c[axis] = t;
          if (cells.state(cells.Index(c.x(), c.y(), c.z())) != kUnobserved) {
            ++t;
            continue;
          }
          const int t0 = t;
          while (t < m) {
            c[axis] = t;
            if (cells.state(cells.Index(c.x(), c.y(), c.z())) != kUnobserved) break;
            ++t;
          }
          const int t1 = t - 1;  // the run is [t0, t1]; t is the cell after it (or m)
          if (t0 == 0 || t == m || t1 - t0 + 1 > run || t1 < pad || t0 >= pad + n) continue;
          c[axis] = t0 - 1;
          const size_t before = cells.Index(c.x(), c.y(), c.z());
          c[axis] = t;
          const size_t after = cells.Index(c.x(), c.y(), c.z());
          if (cells.state(before) != kFree || cells.state(after) != kFree) continue;
          const double p = std::min(cells.p(before), cells.p(after));
          for (int s = std::max(t0, pad); s <= std::min(t1, pad + n - 1); ++s) {
            c[axis] = s;
            double& f = fill[core(c)];
            f = std::min(f, p);
          }
        }
      }
    }
  }
  for (int z = 0; z < n; ++z) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const double p = fill[size_t(x) + size_t(n) * (size_t(y) + size_t(n) * size_t(z))];
        if (!std::isfinite(p)) continue;
        TileLeaf leaf;
        leaf.node = ChunkNode{Eigen::Vector3i(x, y, z), k};
        leaf.stats.sum_w = 1;
        leaf.stats.sum_wp = p;
        leaf.stats.sum_wp2 = p * p;
        leaf.stats.count = 1;
        out.tile.leaves.push_back(leaf);
        ++out.filled_cells;
      }
    }
  }
  if (out.filled_cells > 0) SortTileLeaves(out.tile.grid, out.tile.leaves);
  return out;
}

}  // namespace carvemap
