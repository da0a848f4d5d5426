// Wall samples (§3.1; docs/DESIGN.md §6 stage 4): the 2D input of floor-plan generation. Each
// sample is a point in the horizontal plane where a wall stands, with the floor and ceiling heights
// there and the scanner positions that saw it (line of sight). Every source makes the same
// structure: the octree's vertical regions (§5.3.1, octree_wall_samples.h), 2D occupancy grid
// maps (§3.1.2, gridmap_wall_samples.h), point clouds (§3.1.1).
//
// Plain data; no files, no logging.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"

namespace carvemap {

struct WallSample {
  Eigen::Vector2d position = Eigen::Vector2d::Zero();  // world x, y, m
  // Unit wall normal towards the scanners that saw it (§3.1.1: "flipped to point towards the
  // laser scanner"); zero when the source has none.
  Eigen::Vector2d normal = Eigen::Vector2d::Zero();
  // §3.3.4 / §5.3.3: floor and ceiling elevation at this sample, m (floor_z < ceiling_z).
  double floor_z = 0;
  double ceiling_z = 0;
  // Indices into WallSampleSet::poses of the scanner positions with a line of sight to this
  // sample, ascending.
  std::vector<uint32_t> poses;
};

struct WallSampleSet {
  // d_s: the grid the samples were made on (§3.1.1, typically 5 cm). The floor plan uses it as
  // the diameter of the occlusion ball (§3.3.1) and the simplification error bound r (§3.3.3).
  double spacing_m = 0.05;
  // Scanner positions in time order (the recorded path of this level, subsampled). Consecutive
  // poses are the scanner-to-scanner segments of §3.3.1 and the path of the unentered-room test
  // (§3.3.2); a pose whose index is in `path_breaks` starts a new piece (the walk left the
  // level and came back), so no segment joins it to the pose before.
  std::vector<Eigen::Vector2d> poses;
  std::vector<uint32_t> path_breaks;  // ascending
  std::vector<WallSample> samples;

  // InvalidArgument naming the first bad element: spacing not finite or ≤ 0, a non-finite
  // position / pose / height, floor_z ≥ ceiling_z, a normal neither zero nor unit (±1e-6), a
  // pose index out of range or not ascending, path_breaks out of range or not ascending.
  [[nodiscard]] absl::Status Validate() const;
};

}  // namespace carvemap
