#include "services/segment/fill_pockets.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>
#include <vector>

#include "absl/strings/str_cat.h"
#include "geometry/union_find.h"

namespace carvemap {
namespace {

enum CellState : uint8_t { kUnobserved = 0, kFree = 1, kSolid = 2 };

// The chunk and its neighbours' cells within `pad` of it, as states and the p of free cells.
class PaddedCells {
 public:
  PaddedCells(int n, int pad, const LeafKey& chunk_min)
      : m_(n + 2 * pad), origin_(chunk_min - LeafKey::Constant(pad)) {
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
  int m_;
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

absl::StatusOr<std::vector<PocketCell>> PocketCandidates(const ChunkNeighbourhood& hood,
                                                         const PocketFillOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  // Every tile against its slot (chunk, depth, leaves inside it), as the other per-chunk
  // stages check them.
  if (absl::StatusOr<NeighbourhoodIndex> index = NeighbourhoodIndex::Build(hood); !index.ok()) {
    return index.status();
  }
  const int k = hood.grid.chunk_depth;
  const int n = hood.grid.leaves_per_side();
  std::vector<PocketCell> out;
  if (hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)] == nullptr || n < 4) return out;
  // Runs of up to `run` cells. The cells within one of the chunk are judged too (a candidate
  // beside a non-candidate is tainted), and their runs' ends lie within run + 1 beyond them.
  const int run = std::clamp(
      int(std::floor(options.max_thickness_m / hood.grid.resolution_m() * (1 + 1e-9))), 1, n - 2);
  const int pad = run + 2;  // ≤ n: inside the 26 neighbours
  PaddedCells cells(n, pad, hood.chunk * n);
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const TileData* tile = hood.tiles[ChunkNeighbourhood::Index(dx, dy, dz)];
        if (tile == nullptr) continue;
        const ChunkKey key = hood.chunk + ChunkKey(dx, dy, dz);
        for (const TileLeaf& leaf : tile->leaves) {
          const int size = 1 << (k - leaf.node.depth);
          cells.Add(key * n + leaf.node.local * size, size, leaf.stats);
        }
      }
    }
  }

  // Along each axis, every line through the zone (the chunk and one cell around it):
  // unobserved runs of ≤ `run` cells between two free cells. A cell in several takes the lowest
  // p offered.
  const int m = cells.m(), lo = pad - 1, zn = n + 2;
  std::vector<double> best(size_t(zn) * zn * zn, std::numeric_limits<double>::infinity());
  const auto zone = [&](const Eigen::Vector3i& c) {
    return size_t(c.x() - lo) + size_t(zn) * (size_t(c.y() - lo) + size_t(zn) * size_t(c.z() - lo));
  };
  const auto at = [&](const Eigen::Vector3i& c) { return cells.Index(c.x(), c.y(), c.z()); };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    Eigen::Vector3i c;
    for (int j = lo; j < lo + zn; ++j) {
      for (int i = lo; i < lo + zn; ++i) {
        c[u] = i;
        c[v] = j;
        int t = 0;
        while (t < m) {
          c[axis] = t;
          if (cells.state(at(c)) != kUnobserved) {
            ++t;
            continue;
          }
          const int t0 = t;
          while (t < m) {
            c[axis] = t;
            if (cells.state(at(c)) != kUnobserved) break;
            ++t;
          }
          const int t1 = t - 1;  // the run is [t0, t1]; t is the cell after it (or m)
          if (t0 == 0 || t == m || t1 - t0 + 1 > run || t1 < lo || t0 >= lo + zn) continue;
          c[axis] = t0 - 1;
          const size_t before = at(c);
          c[axis] = t;
          const size_t after = at(c);
          if (cells.state(before) != kFree || cells.state(after) != kFree) continue;
          const double p = std::min(cells.p(before), cells.p(after));
          for (int s = std::max(t0, lo); s <= std::min(t1, lo + zn - 1); ++s) {
            c[axis] = s;
            double& b = best[zone(c)];
            b = std::min(b, p);
          }
        }
      }
    }
  }
  const LeafKey origin = hood.chunk * n - LeafKey::Constant(pad);
  for (int z = pad; z < pad + n; ++z) {
    for (int y = pad; y < pad + n; ++y) {
      for (int x = pad; x < pad + n; ++x) {
        const Eigen::Vector3i c(x, y, z);
        const double p = best[zone(c)];
        if (!std::isfinite(p)) continue;
        bool tainted = false;
        for (int d = 0; d < 3 && !tainted; ++d) {
          for (int step : {-1, 1}) {
            Eigen::Vector3i q = c;
            q[d] += step;
            tainted |= cells.state(at(q)) == kUnobserved && !std::isfinite(best[zone(q)]);
          }
        }
        out.push_back(PocketCell{origin + c, tainted, p});
      }
    }
  }
  return out;
}

namespace {

bool CellLess(const LeafKey& a, const LeafKey& b) {
  return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
}

// The pockets of `cells` (sorted by CellLess): sets over their indices, 6-neighbours joined.
template <typename Index>
UnionFind<Index> JoinNeighbours(const std::vector<PocketCell>& cells) {
  const auto find = [&cells](const LeafKey& key) -> Index {
    auto it =
        std::lower_bound(cells.begin(), cells.end(), key,
                         [](const PocketCell& a, const LeafKey& b) { return CellLess(a.cell, b); });
    return it != cells.end() && it->cell == key ? Index(it - cells.begin()) : Index(-1);
  };
  UnionFind<Index> sets(cells.size());
  for (size_t i = 0; i < cells.size(); ++i) {
    for (int d = 0; d < 3; ++d) {
      const Index j = find(cells[i].cell + LeafKey::Unit(d));
      if (j >= 0) sets.Union(Index(i), j);
    }
  }
  return sets;
}

}  // namespace

std::vector<PocketCell> FillablePocketCells(std::vector<PocketCell> candidates) {
  std::sort(candidates.begin(), candidates.end(),
            [](const PocketCell& a, const PocketCell& b) { return CellLess(a.cell, b.cell); });
  UnionFind<int64_t> sets = JoinNeighbours<int64_t>(candidates);
  std::vector<uint8_t> tainted(candidates.size(), 0);
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (candidates[i].tainted) tainted[size_t(sets.Find(int64_t(i)))] = 1;
  }
  std::vector<PocketCell> out;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (!tainted[size_t(sets.Find(int64_t(i)))]) out.push_back(candidates[i]);
  }
  return out;
}

namespace {

template <typename Index>
void KeepFillable(std::vector<std::pair<ChunkKey, std::vector<PocketCell>>>& chunks,
                  const std::vector<uint64_t>& offset, const OctreeGrid& grid) {
  // The global index of a candidate cell, or −1; `hint` is the chunk of the cell asked from.
  const auto find = [&](size_t hint, const LeafKey& key) -> int64_t {
    const ChunkKey ck = ChunkOfLeaf(grid, key);
    size_t ci = hint;
    if (ck != chunks[hint].first) {
      auto it = std::lower_bound(
          chunks.begin(), chunks.end(), ck,
          [](const auto& e, const ChunkKey& k) { return ChunkKeyLess{}(e.first, k); });
      if (it == chunks.end() || it->first != ck) return -1;
      ci = size_t(it - chunks.begin());
    }
    const std::vector<PocketCell>& v = chunks[ci].second;
    auto it = std::lower_bound(v.begin(), v.end(), key, [](const PocketCell& a, const LeafKey& b) {
      return CellLess(a.cell, b);
    });
    return it != v.end() && it->cell == key ? int64_t(offset[ci] + uint64_t(it - v.begin())) : -1;
  };
  UnionFind<Index> sets(offset.back());
  for (size_t ci = 0; ci < chunks.size(); ++ci) {
    const std::vector<PocketCell>& v = chunks[ci].second;
    for (size_t i = 0; i < v.size(); ++i) {
      for (int d = 0; d < 3; ++d) {
        const int64_t j = find(ci, v[i].cell + LeafKey::Unit(d));
        if (j >= 0) sets.Union(Index(offset[ci] + i), Index(j));
      }
    }
  }
  std::vector<uint8_t> tainted(offset.back(), 0);
  for (size_t ci = 0; ci < chunks.size(); ++ci) {
    const std::vector<PocketCell>& v = chunks[ci].second;
    for (size_t i = 0; i < v.size(); ++i) {
      if (v[i].tainted) tainted[size_t(sets.Find(Index(offset[ci] + i)))] = 1;
    }
  }
  for (size_t ci = 0; ci < chunks.size(); ++ci) {
    std::vector<PocketCell>& v = chunks[ci].second;
    size_t kept = 0;
    for (size_t i = 0; i < v.size(); ++i) {
      if (!tainted[size_t(sets.Find(Index(offset[ci] + i)))]) v[kept++] = v[i];
    }
    v.resize(kept);
    v.shrink_to_fit();
  }
}

}  // namespace

void DropInnerTaintedPockets(std::vector<PocketCell>& cells, const ChunkKey& chunk,
                             const OctreeGrid& grid) {
  const int n = grid.leaves_per_side();
  const LeafKey origin = chunk * n;
  UnionFind<int> sets = JoinNeighbours<int>(cells);
  // Per set (at its root): 1 tainted, 2 on a face of the chunk.
  std::vector<uint8_t> flags(cells.size(), 0);
  for (size_t i = 0; i < cells.size(); ++i) {
    const LeafKey local = cells[i].cell - origin;
    const bool on_face = (local.array() == 0).any() || (local.array() == n - 1).any();
    flags[size_t(sets.Find(int(i)))] |= (cells[i].tainted ? 1 : 0) | (on_face ? 2 : 0);
  }
  size_t kept = 0;
  for (size_t i = 0; i < cells.size(); ++i) {
    if (flags[size_t(sets.Find(int(i)))] != 1) cells[kept++] = cells[i];
  }
  cells.resize(kept);
}

absl::Status KeepFillablePocketCells(
    std::vector<std::pair<ChunkKey, std::vector<PocketCell>>>& chunks, const OctreeGrid& grid) {
  std::sort(chunks.begin(), chunks.end(),
            [](const auto& a, const auto& b) { return ChunkKeyLess{}(a.first, b.first); });
  std::vector<uint64_t> offset(chunks.size() + 1, 0);
  for (size_t ci = 0; ci < chunks.size(); ++ci) {
    if (ci > 0 && chunks[ci].first == chunks[ci - 1].first) {
      return absl::InvalidArgumentError(absl::StrCat("pocket fill: chunk ", chunks[ci].first.x(),
                                                     ",", chunks[ci].first.y(), ",",
                                                     chunks[ci].first.z(), " is given twice"));
    }
    for (const PocketCell& c : chunks[ci].second) {
      if (ChunkOfLeaf(grid, c.cell) != chunks[ci].first) {
        return absl::InvalidArgumentError(absl::StrCat(
            "pocket fill: cell ", c.cell.x(), ",", c.cell.y(), ",", c.cell.z(), " is not in chunk ",
            chunks[ci].first.x(), ",", chunks[ci].first.y(), ",", chunks[ci].first.z()));
      }
    }
    offset[ci + 1] = offset[ci] + chunks[ci].second.size();
  }
  // 4-byte set indices while they fit: the sets are as many as the candidates.
  if (offset.back() <= uint64_t(std::numeric_limits<int32_t>::max())) {
    KeepFillable<int32_t>(chunks, offset, grid);
  } else {
    KeepFillable<int64_t>(chunks, offset, grid);
  }
  return absl::OkStatus();
}

absl::StatusOr<TileData> WithFilledCells(const TileData& tile, std::span<const PocketCell> cells) {
  TileData out = tile;
  const int n = tile.grid.leaves_per_side();
  for (const PocketCell& c : cells) {
    const Eigen::Vector3i local = c.cell - tile.chunk * n;
    if ((local.array() < 0).any() || (local.array() >= n).any()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "pocket fill: cell ", c.cell.x(), ",", c.cell.y(), ",", c.cell.z(), " is not in chunk ",
          tile.chunk.x(), ",", tile.chunk.y(), ",", tile.chunk.z()));
    }
    TileLeaf leaf;
    leaf.node = ChunkNode{local, tile.grid.chunk_depth};
    leaf.stats.sum_w = 1;
    leaf.stats.sum_wp = c.p;
    leaf.stats.sum_wp2 = c.p * c.p;
    leaf.stats.count = 1;
    out.leaves.push_back(leaf);
  }
  if (!cells.empty()) SortTileLeaves(out.grid, out.leaves);
  return out;
}

}  // namespace carvemap
