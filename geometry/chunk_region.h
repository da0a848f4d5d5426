// A part of one 2 m chunk, as a set of its cells at one depth (cells of 2 m / 2^depth): what a
// second carving pass is limited to. Seed §5.6.1: "we can recarve the nodes of the octree
// containing object geometry" at a finer resolution; carving whole chunks finer costs the
// whole chunk's volume (on the simulated office, ~7 s and ~10 MB per chunk at 1.5625 cm),
// carving only the nodes around the objects a small part of that.
//
// Queries for a node of any depth are O(1): the region keeps, for every coarser depth, which
// nodes hold a set cell.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"

namespace carvemap {

class ChunkRegion {
 public:
  // Depths a region may have: 32³ cells at 5 (6.25 cm, the job's usual grid) is 4 KiB.
  static constexpr int kMaxDepth = 7;

  // The empty region (contains nothing).
  ChunkRegion() = default;
  // The cells of `depth` listed in `cells` (local coordinates in [0, 2^depth)³; others are
  // ignored). REQUIRES: 0 ≤ depth ≤ kMaxDepth.
  ChunkRegion(int depth, const std::vector<Eigen::Vector3i>& cells);

  [[nodiscard]] int depth() const { return depth_; }
  [[nodiscard]] bool empty() const { return count_ == 0; }
  [[nodiscard]] uint64_t count() const { return count_; }  // cells set at depth()
  // The heap the region's tables hold (a second pass's carver counts it in its budget).
  [[nodiscard]] size_t memory_bytes() const;
  // True when some cell of the region lies in `node` (a node of this chunk at any depth).
  [[nodiscard]] bool Intersects(const ChunkNode& node) const;
  // True when some cell of the region meets the closed box [lo, hi] (m, relative to the
  // chunk's lowest corner; cells are 2 m / 2^depth() wide). O(1): the box's cells are clipped
  // to the region's bounding box and counted with a summed-volume table over it.
  [[nodiscard]] bool IntersectsBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const;
  // The region's cells along `axis` (0 x, 1 y, 2 z) in the row of cells at depth() whose other
  // coordinates are u (axis + 1 mod 3) and v (axis + 2 mod 3), as maximal runs of cell indices,
  // ascending: a raster of rows intersects these instead of asking cell by cell.
  // REQUIRES: 0 ≤ u, v < 2^depth().
  struct CellRun {
    uint16_t first, last;
  };
  [[nodiscard]] std::span<const CellRun> RowRuns(int axis, int u, int v) const;
  // The set cells' bounding box, inclusive cell indices at depth(); lo > hi when empty.
  [[nodiscard]] const Eigen::Vector3i& cells_lo() const { return lo_; }
  [[nodiscard]] const Eigen::Vector3i& cells_hi() const { return hi_; }
  // The cells as bits, x fastest, then y, then z; bit i is bit (i % 8) of byte i / 8.
  [[nodiscard]] std::string Encode() const;
  // InvalidArgument for a depth outside [0, kMaxDepth] or a size that is not (2^depth)³ / 8
  // bytes (rounded up).
  static absl::StatusOr<ChunkRegion> Decode(int depth, std::string_view bits);
  // Decode's checks alone, without building the region's tables.
  static absl::Status CheckEncoding(int depth, std::string_view bits);

 private:
  void Build(std::vector<bool> cells);

  int depth_ = 0;
  uint64_t count_ = 0;
  // any_[d]: the nodes of depth d holding a cell, indexed like Encode; any_[depth_] = cells.
  std::vector<std::vector<bool>> any_;
  // The set cells' bounding box (inclusive cell indices; empty region: lo_ > hi_) and, over
  // it, the summed-volume table: sums_ at (i, j, k) counts the set cells of the box's first
  // i × j × k cells, (size + 1)³ entries. IntersectsBox is called for every wedge and chunk of
  // a second pass, where a descent through any_ cost as much as the carve's own votes.
  Eigen::Vector3i lo_ = Eigen::Vector3i::Ones(), hi_ = Eigen::Vector3i::Zero();
  std::vector<uint32_t> sums_;
  // Per axis: the runs of each row (v · 2^depth + u), row r's at [row_start_[r], row_start_[r+1]).
  std::array<std::vector<uint32_t>, 3> row_start_;
  std::array<std::vector<CellRun>, 3> row_runs_;
};

// One chunk of a second carving pass and the part of it to carve, as ChunkRegion::Encode's
// bits. Regions are passed and kept in this form (from the merge to the coordinator, into the
// pass's regions file, and while the merge waits for the pass) and decoded only by the one
// working on the chunk: a decoded region's tables (the summed-volume table over its bounding
// box, the rows' runs) take up to ~40 times its 4 KiB of bits at depth 5, and a large
// building's pass has thousands of chunks.
struct RecarveChunk {
  ChunkKey chunk = ChunkKey::Zero();
  int depth = 0;
  std::string cells;  // ChunkRegion::Encode() of the region

  static RecarveChunk Of(const ChunkKey& chunk, const ChunkRegion& region) {
    return RecarveChunk{chunk, region.depth(), region.Encode()};
  }
  [[nodiscard]] absl::StatusOr<ChunkRegion> Decode() const {
    return ChunkRegion::Decode(depth, cells);
  }
};

// A second pass's chunks and their regions, encoded.
using RecarveRegionMap = std::map<ChunkKey, RecarveChunk, ChunkKeyLess>;

}  // namespace carvemap
