#include "services/segment/segment_chunk.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <vector>

namespace carvemap {
namespace {

// The exact mirror of a leaf's evidence: Σw(1 − p) = Σw − Σwp, Σw(1 − p)² = Σw − 2Σwp + Σwp².
LeafStats Mirrored(const LeafStats& s) {
  LeafStats m = s;
  m.sum_wp = s.sum_w - s.sum_wp;
  m.sum_wp2 = std::max(0.0, s.sum_w - 2 * s.sum_wp + s.sum_wp2);
  return m;
}

// An interior-reading leaf for a cell that was exterior: the mirror when that is clearly
// interior, else the fixed kUnobservedObjectP (unobserved space, or p exactly 0.5).
LeafStats AsInterior(const LeafStats* s) {
  if (s != nullptr && s->observed()) {
    LeafStats m = Mirrored(*s);
    if (m.interior()) return m;
  }
  LeafStats u;
  u.Add(kUnobservedObjectP, 1.0);
  return u;
}

// What a cell's key is: its leaf row (−1 unstored) and its class. Uniform keys merge.
struct CellKey {
  int32_t leaf = -1;
  CellSegment segment = CellSegment::kBuilding;
  friend bool operator==(const CellKey&, const CellKey&) = default;
};

// What the first observed cell along a line says.
enum class Hit { kNothing, kFree, kSolid, kWall };

// The hidden-space test of segment_chunk.h for the unobserved cell centred at `c`.
bool HiddenBehindSolid(const NeighbourhoodIndex& index, const PlanVolume& plan,
                       const Eigen::Vector3d& c, const SegmentOptions& options) {
  const Eigen::Vector2d away = PlanAwayFromWalls(plan, c);
  if (away.isZero()) return false;
  const OctreeGrid& grid = index.hood().grid;
  const double res = grid.resolution_m();
  const int steps = static_cast<int>(std::ceil(options.hidden_fill_m / res));
  auto march = [&](double sign) {
    for (int s = 1; s <= steps; ++s) {
      const Eigen::Vector3d p = c + sign * s * res * Eigen::Vector3d(away.x(), away.y(), 0);
      const LeafKey cell = LeafOf(grid, p);
      if (index.SlotOf(cell) < 0) return Hit::kNothing;
      if (const TileLeaf* leaf = index.StoredAt(cell); leaf && leaf->stats.observed()) {
        return leaf->stats.interior() ? Hit::kFree : Hit::kSolid;
      }
      if (sign < 0) {
        const PlanColumn col = LookupPlan(plan, p);
        if (col.room < 0 || col.signed_distance_m < 0) return Hit::kWall;
      }
    }
    return Hit::kNothing;
  };
  if (march(+1) != Hit::kSolid) return false;
  const Hit back = march(-1);
  return back == Hit::kSolid || back == Hit::kWall;
}

class ChunkSegmenter {
 public:
  ChunkSegmenter(const NeighbourhoodIndex& index, const PlanVolume& plan,
                 const SegmentOptions& options, const ChunkRegion* only_in)
      : index_(index),
        plan_(plan),
        options_(options),
        tile_(index.hood().tiles[ChunkNeighbourhood::Index(0, 0, 0)]),
        k_(index.hood().grid.chunk_depth),
        n_(index.hood().grid.leaves_per_side()) {
    const OctreeGrid& grid = index.hood().grid;
    const TileData* tile = tile_;
    const ChunkKey chunk = index.hood().chunk;
    const double res = grid.resolution_m();
    cells_.assign(static_cast<size_t>(n_) * n_ * n_, CellKey{});
    // §4.2.3 point evidence: points per cube of 2^shift cells a side.
    const int& shift = shift_;
    while (shift_ < k_ && (res * (2 << shift_)) <= options.point_cell_m * (1 + 1e-9)) ++shift_;
    const int nc = n_ >> shift;
    auto cube = [&](int x, int y, int z) {
      return size_t(x >> shift) +
             size_t(nc) * (size_t(y >> shift) + size_t(nc) * size_t(z >> shift));
    };
    std::vector<uint32_t> cube_points;
    if (options.min_points > 0 && tile != nullptr) {
      cube_points.assign(static_cast<size_t>(nc) * nc * nc, 0);
      for (const TileLeaf& leaf : tile->leaves) {
        if (leaf.stats.points == 0) continue;
        // A leaf coarser than a cube (not written by this build's workers) counts in each.
        const int s = 1 << (k_ - leaf.node.depth);
        const Eigen::Vector3i lo = leaf.node.local * s;
        const int c0 = 1 << shift;
        for (int z = lo.z(); z < lo.z() + s; z += c0)
          for (int y = lo.y(); y < lo.y() + s; y += c0)
            for (int x = lo.x(); x < lo.x() + s; x += c0) {
              cube_points[cube(x, y, z)] += leaf.stats.points;
            }
      }
    }
    auto points_at = [&](int x, int y, int z) {
      return !cube_points.empty() &&
             cube_points[cube(x, y, z)] >= static_cast<uint32_t>(options.min_points);
    };
    if (tile != nullptr) {
      for (size_t row = 0; row < tile->leaves.size(); ++row) {
        const ChunkNode& node = tile->leaves[row].node;
        const int s = 1 << (k_ - node.depth);
        const Eigen::Vector3i lo = node.local * s;
        for (int z = lo.z(); z < lo.z() + s; ++z) {
          for (int y = lo.y(); y < lo.y() + s; ++y) {
            for (int x = lo.x(); x < lo.x() + s; ++x) {
              cells_[Index(x, y, z)].leaf = static_cast<int32_t>(row);
            }
          }
        }
      }
    }
    const LeafKey base = chunk * n_;
    for (int z = 0; z < n_; ++z) {
      for (int y = 0; y < n_; ++y) {
        for (int x = 0; x < n_; ++x) {
          CellKey& c = cells_[Index(x, y, z)];
          if (only_in != nullptr &&
              !only_in->Intersects(ChunkNode{Eigen::Vector3i(x, y, z), k_})) {
            c.segment = CellSegment::kBuilding;
            continue;
          }
          const LeafStats* s = c.leaf >= 0 ? &tile->leaves[c.leaf].stats : nullptr;
          const bool observed = s != nullptr && s->observed();
          c.segment = Segment(base + Eigen::Vector3i(x, y, z), s != nullptr && s->interior(),
                              observed, points_at(x, y, z));
          if (c.segment == CellSegment::kObject) {
            ++object_cells_;
            unobserved_object_cells_ += !observed;
          }
          if (c.segment == CellSegment::kTrimmed) ++trimmed_cells_;
        }
      }
    }
    // The floor band under standing objects (ClassifyCell's above_is_object), top down so that
    // the cell above is final; the chunk's top layer asks the chunk above. Only cells that
    // ClassifyCell rejects without the object above: the band, not unswept air that failed the
    // hidden-space test under an object.
    for (int y = 0; y < n_; ++y) {
      for (int x = 0; x < n_; ++x) {
        for (int z = n_ - 1; z >= 0; --z) {
          CellKey& c = cells_[Index(x, y, z)];
          if (c.segment == CellSegment::kObject || c.segment == CellSegment::kTrimmed) continue;
          if (z + 1 < n_ && cells_[Index(x, y, z + 1)].segment != CellSegment::kObject) continue;
          if (only_in != nullptr && !only_in->Intersects(ChunkNode{Eigen::Vector3i(x, y, z), k_})) {
            continue;
          }
          const LeafStats* s = c.leaf >= 0 ? &tile->leaves[c.leaf].stats : nullptr;
          const bool observed = s != nullptr && s->observed();
          const LeafKey key = base + Eigen::Vector3i(x, y, z);
          if (!StandsOnTheFloor(key, s != nullptr && s->interior(), observed, points_at(x, y, z))) {
            continue;
          }
          if (z + 1 == n_ && !ObjectOutside(key + LeafKey(0, 0, 1), BandCells())) continue;
          c.segment = CellSegment::kObject;
          ++object_cells_;
          unobserved_object_cells_ += !observed;
        }
      }
    }
  }

  void Emit(SegmentedChunk& out) {
    if (std::optional<CellKey> root = Visit(0, Eigen::Vector3i::Zero(), out)) {
      Write(ChunkNode{Eigen::Vector3i::Zero(), 0}, *root, out);
    }
    out.object_cells = object_cells_;
    out.unobserved_object_cells = unobserved_object_cells_;
    out.trimmed_cells = trimmed_cells_;
    if (object_cells_ == 0) out.objects.leaves.clear();
  }

 private:
  // The class of the cell `key` (this chunk's or a neighbour's) from the plan, with the
  // hidden-space test for unobserved object cells; the floor band aside.
  [[nodiscard]] CellSegment Segment(const LeafKey& key, bool interior, bool observed,
                                    bool points) const {
    const Eigen::Vector3d centre = LeafCenter(index_.hood().grid, key);
    const CellSegment segment = ClassifyCell(plan_, centre, interior, observed, points,
                                             index_.hood().grid.resolution_m(), options_);
    if (segment == CellSegment::kObject && !observed &&
        !HiddenBehindSolid(index_, plan_, centre, options_)) {
      return CellSegment::kBuilding;
    }
    return segment;
  }

  // Whether the cell `key` is object only because the cell above it is (the floor band).
  [[nodiscard]] bool StandsOnTheFloor(const LeafKey& key, bool interior, bool observed,
                                      bool points) const {
    const Eigen::Vector3d centre = LeafCenter(index_.hood().grid, key);
    const double res = index_.hood().grid.resolution_m();
    return ClassifyCell(plan_, centre, interior, observed, points, res, options_) !=
               CellSegment::kObject &&
           ClassifyCell(plan_, centre, interior, observed, points, res, options_, true) ==
               CellSegment::kObject;
  }

  // Cells of the band that ClassifyCell's above_is_object can reach: a cell's centre above
  // the floor and below floor + tolerance + half a cell.
  [[nodiscard]] int BandCells() const {
    const double res = index_.hood().grid.resolution_m();
    const double tol = options_.plan_tolerance_m < 0 ? res : options_.plan_tolerance_m;
    return static_cast<int>(std::ceil(tol / res + 0.5)) + 1;
  }

  // Whether `key`, a cell of a neighbouring chunk, is an object as that chunk's segmentation
  // classifies it (without its second pass's region, which this chunk does not know), looking
  // up at most `hops` cells of floor band.
  [[nodiscard]] bool ObjectOutside(const LeafKey& key, int hops) const {
    if (index_.SlotOf(key) < 0) return false;
    const TileLeaf* leaf = index_.StoredAt(key);
    const bool observed = leaf != nullptr && leaf->stats.observed();
    const bool interior = leaf != nullptr && leaf->stats.interior();
    const bool points = PointsOutside(key);
    const CellSegment segment = Segment(key, interior, observed, points);
    if (segment == CellSegment::kObject) return true;
    return hops > 0 && StandsOnTheFloor(key, interior, observed, points) &&
           ObjectOutside(key + LeafKey(0, 0, 1), hops - 1);
  }

  // The point evidence of a neighbouring chunk's cell: its cube's points, each leaf once (a
  // leaf coarser than the cube counts in full, as in this chunk's own count).
  [[nodiscard]] bool PointsOutside(const LeafKey& key) const {
    if (options_.min_points <= 0) return false;
    const int c0 = 1 << shift_;
    const LeafKey lo((key.x() >> shift_) << shift_, (key.y() >> shift_) << shift_,
                     (key.z() >> shift_) << shift_);
    std::vector<const TileLeaf*> seen;
    uint64_t points = 0;
    for (int z = 0; z < c0; ++z)
      for (int y = 0; y < c0; ++y)
        for (int x = 0; x < c0; ++x) {
          const TileLeaf* leaf = index_.StoredAt(lo + LeafKey(x, y, z));
          if (leaf == nullptr || std::find(seen.begin(), seen.end(), leaf) != seen.end()) continue;
          seen.push_back(leaf);
          points += leaf->stats.points;
        }
    return points >= static_cast<uint64_t>(options_.min_points);
  }

  [[nodiscard]] size_t Index(int x, int y, int z) const {
    return static_cast<size_t>(x) +
           static_cast<size_t>(n_) * (static_cast<size_t>(y) + static_cast<size_t>(n_) * z);
  }

  // The key of the node (depth, local) when all its cells share one; otherwise emits its
  // uniform children and returns nothing.
  std::optional<CellKey> Visit(int depth, const Eigen::Vector3i& local, SegmentedChunk& out) {
    if (depth == k_) return cells_[Index(local.x(), local.y(), local.z())];
    std::array<std::optional<CellKey>, 8> child;
    bool uniform = true;
    for (int c = 0; c < 8; ++c) {
      child[c] = Visit(depth + 1, 2 * local + Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1),
                       out);
      uniform = uniform && child[c].has_value() && *child[c] == *child[0];
    }
    if (uniform) return child[0];
    for (int c = 0; c < 8; ++c) {
      if (!child[c]) continue;
      Write(ChunkNode{2 * local + Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1), depth + 1},
            *child[c], out);
    }
    return std::nullopt;
  }

  void Write(const ChunkNode& node, const CellKey& key, SegmentedChunk& out) {
    const LeafStats* s = key.leaf >= 0 ? &tile_->leaves[key.leaf].stats : nullptr;
    switch (key.segment) {
      case CellSegment::kFree:  // free for both: stays free, and borders objects
        out.building.leaves.push_back(TileLeaf{node, *s});
        out.objects.leaves.push_back(TileLeaf{node, Mirrored(*s)});
        break;
      case CellSegment::kTrimmed:  // exterior for both
        out.building.leaves.push_back(TileLeaf{node, Mirrored(*s)});
        break;
      case CellSegment::kObject:
        out.building.leaves.push_back(TileLeaf{node, AsInterior(s)});
        out.objects.leaves.push_back(TileLeaf{node, AsInterior(s)});
        break;
      case CellSegment::kBuilding:  // as carved; exterior (unstored) for the objects
        if (s != nullptr) out.building.leaves.push_back(TileLeaf{node, *s});
        break;
    }
  }

  const NeighbourhoodIndex& index_;
  const PlanVolume& plan_;
  const SegmentOptions& options_;
  const TileData* tile_;
  int k_, n_;
  int shift_ = 0;
  std::vector<CellKey> cells_;
  uint64_t object_cells_ = 0, unobserved_object_cells_ = 0, trimmed_cells_ = 0;
};

}  // namespace

absl::Status SegmentOptions::Validate() const {
  if (!(trim_distance_m >= 0) || !std::isfinite(trim_distance_m)) {
    return absl::InvalidArgumentError("segment: trim_distance_m must be finite and ≥ 0");
  }
  if (!(hidden_fill_m >= 0) || !std::isfinite(hidden_fill_m)) {
    return absl::InvalidArgumentError("segment: hidden_fill_m must be finite and ≥ 0");
  }
  if (min_points < 0) return absl::InvalidArgumentError("segment: min_points must be ≥ 0");
  if (!(point_wall_margin_m >= 0) || !std::isfinite(point_wall_margin_m)) {
    return absl::InvalidArgumentError("segment: point_wall_margin_m must be finite and ≥ 0");
  }
  if (!(point_cell_m > 0) || !std::isfinite(point_cell_m)) {
    return absl::InvalidArgumentError("segment: point_cell_m must be finite and > 0");
  }
  if (!std::isfinite(plan_tolerance_m)) {
    return absl::InvalidArgumentError("segment: plan_tolerance_m must be finite");
  }
  return absl::OkStatus();
}

CellSegment ClassifyCell(const PlanVolume& plan, const Eigen::Vector3d& centre, bool interior,
                         bool observed, bool points, double res_m, const SegmentOptions& options,
                         bool above_is_object) {
  const PlanColumn col = LookupPlan(plan, centre);
  double wall_margin = 0;
  if (interior) {
    // §5.5: only levels with a plan trim; space above or below every level is kept.
    if (TrimmedByPlan(col, options.trim_distance_m)) return CellSegment::kTrimmed;
    // §4.2.3: carved, but the scan's points say solid: an object if the plan agrees below,
    // else free as carved (a wall's or floor's points stay building's free side).
    if (!points) return CellSegment::kFree;
    wall_margin = options.point_wall_margin_m;
  } else if (!observed && !options.unobserved_is_object) {
    return CellSegment::kBuilding;
  }
  const CellSegment not_object = interior ? CellSegment::kFree : CellSegment::kBuilding;
  if (col.room < 0) return not_object;
  const double tol = options.plan_tolerance_m < 0 ? res_m : options.plan_tolerance_m;
  // The whole cell inside: its half diagonal (2D) from the walls, its half side from the floor
  // and ceiling, plus the tolerance.
  const double half = 0.5 * res_m;
  if (col.signed_distance_m < half * std::sqrt(2.0) + tol + wall_margin) return not_object;
  const bool standing = above_is_object && centre.z() > col.floor_z;
  if ((centre.z() - half < col.floor_z + tol && !standing) ||
      centre.z() + half > col.ceiling_z - tol) {
    return not_object;
  }
  return CellSegment::kObject;
}

absl::StatusOr<SegmentedChunk> SegmentChunk(const ChunkNeighbourhood& hood,
                                            const PlanVolume& plan,
                                            const SegmentOptions& options,
                                            const ChunkRegion* only_in) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<NeighbourhoodIndex> index = NeighbourhoodIndex::Build(hood);
  if (!index.ok()) return index.status();
  const TileData* tile = hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)];
  const ChunkKey& chunk = hood.chunk;
  const OctreeGrid& grid = hood.grid;
  SegmentedChunk out;
  for (TileData* t : {&out.building, &out.objects}) {
    t->chunk = chunk;
    t->grid = grid;
    if (tile != nullptr) t->params = tile->params;
  }
  ChunkSegmenter segmenter(*index, plan, options, only_in);
  segmenter.Emit(out);
  return out;
}

ChunkRegion ObjectRecarveRegion(const TileData& objects, const PlanVolume& plan,
                                int margin_cells, double ceiling_reach_m) {
  const int depth = std::min(objects.grid.chunk_depth, ChunkRegion::kMaxDepth);
  const int n = 1 << depth;
  const double res = kChunkSizeM / n;
  const Eigen::Vector3d origin = objects.chunk.cast<double>() * kChunkSizeM;
  std::vector<bool> object(size_t(n) * n * n, false);
  auto at = [n](int x, int y, int z) {
    return size_t(x) + size_t(n) * (size_t(y) + size_t(n) * size_t(z));
  };
  for (const TileLeaf& leaf : objects.leaves) {
    if (!leaf.stats.interior()) continue;
    // The leaf's cells at `depth` (a leaf finer than that marks its one cell).
    const int sh = depth - leaf.node.depth;
    const Eigen::Vector3i lo = sh >= 0 ? Eigen::Vector3i(leaf.node.local * (1 << sh))
                                       : Eigen::Vector3i(leaf.node.local.x() >> -sh,
                                                         leaf.node.local.y() >> -sh,
                                                         leaf.node.local.z() >> -sh);
    const int s = sh >= 0 ? 1 << sh : 1;
    for (int z = lo.z(); z < lo.z() + s; ++z)
      for (int y = lo.y(); y < lo.y() + s; ++y)
        for (int x = lo.x(); x < lo.x() + s; ++x) object[at(x, y, z)] = true;
  }
  std::vector<Eigen::Vector3i> cells;
  std::vector<bool> taken(object.size(), false);
  auto take = [&](int x, int y, int z) {
    if (x < 0 || y < 0 || z < 0 || x >= n || y >= n || z >= n || taken[at(x, y, z)]) return;
    taken[at(x, y, z)] = true;
    cells.emplace_back(x, y, z);
  };
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        if (!object[at(x, y, z)]) continue;
        const Eigen::Vector3d centre =
            origin + (Eigen::Vector3d(x, y, z).array() + 0.5).matrix() * res;
        const PlanColumn col = LookupPlan(plan, centre);
        const int floor_cell =
            col.room >= 0 ? int(std::floor((col.floor_z - origin.z()) / res)) : z;
        const int z0 = std::max(std::min(floor_cell, z), 0) - margin_cells;
        // A hanging object: up to the cell holding the ceiling (its rod's points, below).
        const double top = origin.z() + (z + 1) * res;
        const int z1 = col.room >= 0 && col.ceiling_z - top <= ceiling_reach_m
                           ? std::max(z, int(std::floor((col.ceiling_z - origin.z()) / res)))
                           : z;
        for (int zz = z0; zz <= std::min(z1, n - 1) + margin_cells; ++zz)
          for (int dy = -margin_cells; dy <= margin_cells; ++dy)
            for (int dx = -margin_cells; dx <= margin_cells; ++dx) take(x + dx, y + dy, zz);
      }
  return ChunkRegion(depth, cells);
}

}  // namespace carvemap
