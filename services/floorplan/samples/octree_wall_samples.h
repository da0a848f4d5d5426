// Wall samples from the carved octree (§5.3.1, §5.3.3; docs/DESIGN.md §6 stage 4): the vertical
// planar regions of the boundary faces are the walls; each is sampled on a d_s grid over the 2D
// convex hull of its faces (in wall coordinates u, z), where furniture hid it too; every column
// of kept points becomes one 2D WallSample, with the floor and ceiling heights of the nearest
// large horizontal regions (§5.3.3) and the scanner poses that see it (§3.1, grid_visibility.h).
//
// Plain function over plain data: no files, no logging. The octree is read through
// `OctreeLabelFn`, which the caller wraps around TileSet::Query.
#pragma once

#include <cstddef>
#include <functional>
#include <span>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"
#include "services/floorplan/samples/grid_visibility.h"
#include "services/floorplan/wall_samples.h"
#include "services/levels/level_split.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/planar_regions.h"

namespace carvemap {

// A point's state in the octree: exterior = observed with p ≤ 0.5 (solid), interior = observed
// p > 0.5, unobserved = no ray spoke about it.
enum class OctreeLabel { kUnobserved, kInterior, kExterior };
// Keeps the stage free of files: the caller wraps TileSet::Query. Errors are passed on.
using OctreeLabelFn = std::function<absl::StatusOr<OctreeLabel>(const Eigen::Vector3d&)>;

// A leaf's label for OctreeLabelFn: the caller's wrapper is LabelFromStats(query.stats), and
// kUnobserved for a point with no stored leaf. min_weight_sum (eq 4.8's Σw) can demote barely
// touched leaves to unobserved; 0 by default because measured on the carved presets the
// exterior leaves right behind real walls have Σw ≈ 0 too (median 0.000 on the room preset),
// so any threshold that removes ghost surfaces also removes the walls.
inline constexpr double kMinLabelWeightSum = 0;
[[nodiscard]] inline OctreeLabel LabelFromStats(const LeafStats& stats,
                                                double min_weight_sum = kMinLabelWeightSum) {
  if (!stats.observed() || stats.sum_w < min_weight_sum) return OctreeLabel::kUnobserved;
  return stats.p() > 0.5 ? OctreeLabel::kInterior : OctreeLabel::kExterior;
}

struct OctreeWallSampleOptions {
  // §5.3.1: a wall region's normal is within this of horizontal ("5 degrees").
  double max_tilt_deg = 5;
  // §5.3.1: smaller regions (area of their faces on this level) are not walls.
  double min_area_m2 = 0.05;
  // §5.3.1: regions whose faces on this level span less height than this are not walls. The
  // dissertation says 1 m; filing cabinets and sideboards are 1.0–1.1 m (the simulator's 1.05 m),
  // and once a cabinet's front is carved whole (rays carrying their share of the gaps between them)
  // it passes 1 m and the plan cuts the cabinet out of its room: on the whole office walk,
  // 1.2 m finds 28 % of the objects against 19 % at 1 m, with the same 15 rooms.
  double min_height_m = 1.2;
  // d_s (§3.1.1), m: the sampling grid along each wall and the result's spacing. 0 = the octree
  // resolution.
  double spacing_m = 0;
  // §5.3.3 "large horizontal surfaces": floors and ceilings for the samples' heights. 1 m²
  // (half of level_split's 2 m²): a small room's floor, cut by furniture into pieces, still
  // counts; table tops (≈ 1–1.5 m²) are kept out by height, not area (a floor must lie at or
  // below the wall's bottom, a ceiling at or above its top).
  double min_horizontal_area_m2 = 1.0;
  // A column whose kept points all lie above this fraction of its hull's height is the lintel
  // over a doorway, not a wall: it makes no sample, so doors stay open for §3.3.2. A window
  // (wall below the sill) and a wall hidden behind furniture (filled) both reach lower.
  double lintel_fraction = 0.5;
  // Lintel columns count as a doorway only in runs at least this wide, m; shorter runs are wall
  // whose lower part the region and the fill missed (noisy leaves at the wall). Doors are
  // ≥ 0.8 m (§3.3.2, ADA), but noise breaks a doorway's run into pieces: measured on the
  // presets, 0.25 m leaves no gaps in the room preset's walls and 57 samples in the office's
  // 14 doorways (0.5 m: 87; 0: 42 but 20 one-column gaps in the room's walls).
  double min_opening_m = 0.25;
  // §5.3.1 fill: a wall point with nothing observed behind it is filled when the first
  // observed point in front of it, within this distance, is solid (furniture hiding it), m.
  // Deeper than a bookshelf or wardrobe; shallower than a room, so a barely seen part of the
  // level does not fill.
  double max_occluder_depth_m = 1.0;
  // Floors and ceilings further (horizontally) than this from a column are not searched; the
  // level's floor_z / ceiling_z are used instead, m.
  double max_height_search_m = 3.0;
  VisibilityOptions visibility;
  // InvalidArgument naming the first bad field (including visibility's).
  [[nodiscard]] absl::Status Validate() const;
};

struct OctreeWallSampleReport {
  size_t wall_regions = 0;          // regions kept as walls on this level (§5.3.1 filters)
  size_t horizontal_regions = 0;    // floor + ceiling candidates on this level (§5.3.3)
  size_t grid_points = 0;           // d_s grid points inside the walls' hulls
  size_t on_region = 0;             // of those, on a face of the region
  size_t filled_behind_occlusion = 0;  // of those, filled: the wall hidden behind something
  size_t columns = 0;               // columns with a kept point
  size_t lintel_columns = 0;        // of those, dropped as lintels over doorways (≥ min_opening_m)
  size_t samples = 0;               // after merging samples in the same d_s cell
  size_t floor_fallbacks = 0;       // samples with no floor region found: level.floor_z
  size_t ceiling_fallbacks = 0;     // same for the ceiling
  size_t poses = 0;                 // path positions kept on this level (subsampled)
  size_t samples_with_poses = 0;    // samples seen from at least one pose
  double scanner_z = 0;             // height of the visibility slice, m
};

// The wall samples of `level` (§5.3.1): see the file comment. `faces` and `regions` are those of
// the whole octree (or of this level), `regions` fitted on `faces` (its face indices index
// `faces`). `path_positions` is the recorded system path in world frame, time order; the
// positions whose z lies in [split_z_low, split_z_high) are the poses, subsampled every
// visibility.min_pose_spacing_m, with a path break wherever the walk left the level and came
// back. Deterministic. Errors: InvalidArgument for bad options, level or path, or a region's
// face index out of range; label_at's errors are passed on.
[[nodiscard]] absl::StatusOr<WallSampleSet> OctreeWallSamples(
    std::span<const BoundaryFace> faces, const PlanarRegionSet& regions, const OctreeGrid& grid,
    const Level& level, std::span<const Eigen::Vector3d> path_positions,
    const OctreeLabelFn& label_at, const OctreeWallSampleOptions& options,
    OctreeWallSampleReport* report = nullptr);

}  // namespace carvemap
