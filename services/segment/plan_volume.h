// The extruded floor plans as a volume the octree can be compared with, cell by cell (§5.5,
// §5.6; docs/DESIGN.md §6 stages 6–7): per level, a 2D raster at the octree's finest resolution
// holding each column's room, the room's floor and ceiling heights (§3.3.4) and the signed 2D
// distance to the plan's walls. Segmentation (segment_chunk.h) asks it, for every finest cell, "is
// this column inside the plan, how far from a wall, and between which floor and ceiling?".
//
// Why a raster and not point-in-polygon tests: a chunk has up to 2^21 finest cells and each
// question must cost a lookup; the raster of a 50 m × 50 m level at 6.25 cm is 640 k columns.
//
// Plain data; no files, no logging.
#pragma once

#include <limits>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"

namespace carvemap {

// One level's plan. Column (i, j) covers x ∈ [origin.x + i·res, origin.x + (i+1)·res) and
// y likewise with j; index j·width + i. Cells are aligned with the octree's finest cells when
// origin is a multiple of res (RasterizePlanVolume makes it so).
struct PlanLevelRaster {
  int level = 0;
  double z_low = 0, z_high = 0;  // the level's split range (levels.json split_z ..)
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  double res = 0;
  int width = 0, height = 0;
  std::vector<int> room;             // index into the plan's rooms; −1 outside the plan
  std::vector<double> room_floor_z;   // per room of the plan (§3.3.4 medians), m
  std::vector<double> room_ceiling_z; // m
  // Signed distance from the column's centre to the plan's boundary, m: positive inside (the
  // distance to the nearest outside column centre minus res/2), negative outside (minus the
  // distance to the nearest inside column centre plus res/2). Exact Euclidean distances between
  // column centres (Felzenszwalb–Huttenlocher), so within res/2 of the true boundary distance.
  std::vector<float> signed_distance;
};

struct PlanVolume {
  std::vector<PlanLevelRaster> levels;  // in level order; z ranges do not overlap
};

// One level's input: its floor plan (with room heights, extrusion.h AssignRoomHeights) and
// its split range.
struct PlanLevelInput {
  const FloorPlan* plan = nullptr;
  int level = 0;
  double z_low = 0, z_high = 0;
};

// Rasterizes every level at `res_m` over the plan's bounding box grown by `margin_m` (columns
// farther out read as outside, at −infinity). InvalidArgument: res_m ≤ 0, margin_m < 0, a null
// plan, z_low ≥ z_high, or overlapping level ranges. A level whose plan has no triangles gives
// an empty raster (everything outside).
[[nodiscard]] absl::StatusOr<PlanVolume> RasterizePlanVolume(std::span<const PlanLevelInput> levels,
                                                             double res_m, double margin_m);

// What the plan says about the column of a point.
struct PlanColumn {
  int level = -1;   // −1: the point's z is in no level's range
  int room = -1;    // −1: outside the plan
  double floor_z = 0, ceiling_z = 0;
  double signed_distance_m = -std::numeric_limits<double>::infinity();
};
[[nodiscard]] PlanColumn LookupPlan(const PlanVolume& volume, const Eigen::Vector3d& x);

// §5.5: a point (or an octree cell's centre) in `col` lies outside the scanned area, seen
// through a window or an open door, when it is on a level and farther than trim_distance_m
// (2D) from that level's plan interior ("any points that are at least some distance d meters
// from any interior area of the floor plan"). Above or below every level: kept (no plan there
// to judge by).
[[nodiscard]] inline bool TrimmedByPlan(const PlanColumn& col, double trim_distance_m) {
  return col.level >= 0 && col.signed_distance_m < -trim_distance_m;
}

// The unit 2D direction in which the signed distance grows fastest at x's column (away from
// the nearest wall, into the room; central differences over the neighbouring columns), or zero
// where it is flat, undefined, or x is in no level's raster.
[[nodiscard]] Eigen::Vector2d PlanAwayFromWalls(const PlanVolume& volume,
                                                const Eigen::Vector3d& x);

}  // namespace carvemap
