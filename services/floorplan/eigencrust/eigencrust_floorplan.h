// The Eigencrust floor plan (§3.2; docs/DESIGN.md §6 stage 5's second method), as a FloorPlan with
// rooms so that it gives the same outputs as the room-partitioning method (§3.3):
//   1. §3.2.1 smoothing (SmoothWallSamples, when on);
//   2. §3.2.2–§3.2.3 the Eigencrust labelling (LabelEigencrust);
//   3. rooms: §3.2 has none (§3.4.3: "these attributes are not present in the previous
//      method"), so §3.3.2 runs on the Eigencrust interior: LabelRoomsOfInterior triangulates the
//      same samples, takes a triangle as interior when its centroid lies in an inside
//      Eigencrust triangle (the two triangulations share every triangle away from the box
//      corners; where four samples are cocircular they may split a square differently), then
//      seeds, partitions, merges across borders that are no door and removes rooms the path
//      never entered, as for §3.3;
//   4. §3.2.4 lines and circles (FitWallCurves) on the Eigencrust boundary B; the plan's
//      vertices that are samples of B move onto their curves; triangles left flat on one line
//      are dropped, and a move that would turn any other triangle over is put back.
// floorplan_pipeline.h then removes the vertices left collinear on a line (a collapse with
// ~zero error) instead of §3.3.3's simplification, and extrudes with §3.3.4's heights.
//
// Plain function over plain data: no files, no logging.
#pragma once

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/floorplan/eigencrust/eigencrust.h"
#include "services/floorplan/eigencrust/wall_curve_fit.h"
#include "services/floorplan/floor_plan.h"
#include "services/floorplan/rooms/room_labeling.h"
#include "services/floorplan/wall_samples.h"

namespace carvemap {

struct EigencrustFloorPlanOptions {
  EigencrustOptions labeling;
  bool fit_curves = true;  // §3.2.4
  WallCurveFitOptions curves;
  [[nodiscard]] absl::Status Validate() const;
};

struct EigencrustFloorPlanReport {
  EigencrustReport labeling;
  WallCurveFitReport curves;
  size_t moved_vertices = 0;    // plan vertices moved onto their curves
  size_t refused_moves = 0;     // moves put back: they would have turned a triangle over
  size_t dropped_flat_triangles = 0;  // triangles left flat on one line, removed
  double seconds_smooth = 0, seconds_label = 0, seconds_rooms = 0, seconds_curves = 0;
};

// Errors: InvalidArgument for bad options or samples; LabelEigencrust's, LabelRoomsOfInterior's
// (FailedPrecondition when no triangle is inside, or the path enters no room) and
// FitWallCurves's, prefixed with the step.
[[nodiscard]] absl::StatusOr<FloorPlan> EigencrustFloorPlan(
    const WallSampleSet& samples, const EigencrustFloorPlanOptions& options,
    const RoomLabelingOptions& rooms, RoomLabelingReport* room_report = nullptr,
    EigencrustFloorPlanReport* report = nullptr);

}  // namespace carvemap
