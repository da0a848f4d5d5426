// Which scanner positions see which wall samples, on a 2D occupancy grid (§3.1, §3.3.1:
// "each sample is associated with the scanner pose that observed it"). Used by every wall-sample
// source: a grid map gives the grid directly (§3.1.2); the octree gives a horizontal slice of
// its exterior leaves (§5.3.1).
//
// Each kept pose casts a fan of rays like a 2D laser scanner; a ray stops at the first blocked
// cell, and the sample nearest its hit point (within match_distance) is seen from that pose.
// So a sample hidden behind another wall, or beyond max_range, is not seen.
//
// Plain functions over plain data: no files, no logging.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "services/floorplan/wall_samples.h"

namespace carvemap {

// Row-major cells from the lower-left corner: cell (ix, iy) covers
// [origin_x + ix·res, origin_x + (ix+1)·res) × [origin_y + iy·res, origin_y + (iy+1)·res) and is
// cells[iy·width + ix]. Non-zero = blocked (a wall, an object); zero = free or unknown.
struct OccupancyGrid2D {
  double origin_x_m = 0;
  double origin_y_m = 0;
  double resolution_m = 0.05;
  int width = 0;
  int height = 0;
  std::vector<uint8_t> cells;

  [[nodiscard]] bool Blocked(int ix, int iy) const {
    return ix >= 0 && iy >= 0 && ix < width && iy < height &&
           cells[static_cast<size_t>(iy) * width + ix] != 0;
  }
  // InvalidArgument: resolution not finite or ≤ 0, non-finite origin, negative sizes, or
  // cells.size() ≠ width·height.
  [[nodiscard]] absl::Status Validate() const;
};

struct VisibilityOptions {
  double max_range_m = 30.0;     // docs/DESIGN.md §4: the scanners' range
  double angle_step_deg = 0.25;  // docs/DESIGN.md §4: the scanners' angular step; 360° fans
  // Poses closer than this (along the path) to the previous kept pose are skipped; 0 keeps all.
  double min_pose_spacing_m = 0.25;
  // A hit point further than this from every sample sees none, m. 0 = 1.5 grid cells.
  double match_distance_m = 0;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

// Fills samples[i].poses (replacing what was there) with the indices of the poses of `set`
// that see sample i, ascending. Poses outside the grid see nothing. Deterministic.
// Errors: InvalidArgument for bad options, grid or set.
[[nodiscard]] absl::Status AssignVisiblePoses(const OccupancyGrid2D& grid,
                                              const VisibilityOptions& options,
                                              WallSampleSet& set);

}  // namespace carvemap
