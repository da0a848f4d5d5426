// One level's floor plan from its wall samples (docs/DESIGN.md §6 stage 5), the stages in the
// dissertation's order: interior and rooms (§3.3.1–§3.3.2, room_labeling.h), one floor and ceiling
// height per room (§3.3.4, extrusion.h), wall simplification that keeps doorways (§3.3.3,
// floorplan_simplify.h), room polygons and walls (room_polygons.h), and the 2.5D extrusion
// (§3.3.4). Shared by the merge (octree wall samples, §5.3) and `carvemap floorplan` (grid map
// wall samples, §3.1.2; point clouds, §3.1.1), so every route gives the same outputs.
//
// FloorPlanMethod::kEigencrust replaces the first step by the Eigencrust floor plan (§3.2,
// eigencrust_floorplan.h: its interior, §3.3.2's rooms on it, its lines and circles), and the
// simplification by removing only the vertices its line fitting left collinear (the curve
// fitting is §3.2's simplification); heights, outline and extrusion are the same.
//
// Plain functions over plain data: no files, no logging.
#pragma once

#include <nlohmann/json.hpp>

#include <string_view>

#include "absl/status/statusor.h"
#include "services/floorplan/eigencrust/eigencrust_floorplan.h"
#include "services/floorplan/floor_plan.h"
#include "services/floorplan/model/floorplan_simplify.h"
#include "services/floorplan/model/room_polygons.h"
#include "services/floorplan/rooms/room_labeling.h"
#include "services/floorplan/wall_samples.h"
#include "storage/ply_io.h"

namespace carvemap {

// Which floor-plan method makes the interior: §3.3's room partitioning ("rooms") or §3.2's
// Eigencrust ("eigencrust").
enum class FloorPlanMethod { kRooms, kEigencrust };
[[nodiscard]] std::string_view FloorPlanMethodName(FloorPlanMethod method);
// InvalidArgument naming the accepted names.
[[nodiscard]] absl::StatusOr<FloorPlanMethod> ParseFloorPlanMethod(std::string_view name);

struct FloorPlanOptions {
  FloorPlanMethod method = FloorPlanMethod::kRooms;
  RoomLabelingOptions rooms;
  EigencrustFloorPlanOptions eigencrust;  // method kEigencrust only
  // §3.3.3: simplify the walls, with error bound r = simplify_error_m (0 = the samples' spacing;
  // with kEigencrust 0 = collinear vertices only, 1 µm).
  bool simplify = true;
  double simplify_error_m = 0;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

struct LevelFloorPlan {
  FloorPlan plan;             // simplified, with room heights
  FloorPlanOutline outline;   // room polygons and walls
  TriangleMesh extruded;      // the 2.5D model, watertight
  FloorPlanMethod method = FloorPlanMethod::kRooms;
  RoomLabelingReport labeling;
  EigencrustFloorPlanReport eigencrust;  // method kEigencrust only
  SimplifyReport simplify;
  size_t wall_samples = 0;
  double seconds_rooms = 0, seconds_simplify = 0, seconds_outline = 0, seconds_extrude = 0;
};

// Errors: the stages' (LabelRooms: InvalidArgument for bad samples, FailedPrecondition when no
// triangle is interior; TraceFloorPlan / ExtrudeFloorPlan: FailedPrecondition for a broken
// triangulation), prefixed with the stage.
[[nodiscard]] absl::StatusOr<LevelFloorPlan> BuildLevelFloorPlan(const WallSampleSet& samples,
                                                                 int level,
                                                                 const FloorPlanOptions& options);

// job.json's "rooms" entries: one object per room {level, room, area_m2, floor_z,
// ceiling_z, centroid [x, y]} in room order.
[[nodiscard]] nlohmann::json RoomsToJson(const LevelFloorPlan& result);

}  // namespace carvemap
