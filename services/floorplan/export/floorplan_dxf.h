// level_<k>/floorplan.dxf (docs/DESIGN.md §7): a level's floor plan for CAD programs, in the
// plan's local metres ($INSUNITS 6), one layer per kind:
//   ROOMS   one closed LWPOLYLINE per ring of each room (outer rings and holes)
//   WALLS   one closed LWPOLYLINE per wall loop (the interior/exterior boundary, §3.3)
//   DOORS   one LWPOLYLINE per chain of borders between two rooms: §3.3 splits the interior
//           where it narrows, at doorways and openings
//   LABELS  one TEXT per room: its index and area ("room 3, 12.3 m2")
// Written with dxflib (Debian's libdxflib), DXF R2000 (AC1015).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "services/floorplan/floor_plan.h"
#include "services/floorplan/model/room_polygons.h"

namespace carvemap {

// The borders between two rooms of `plan` (the triangle edges whose two triangles are in
// different rooms), joined into polylines: each chain runs between vertices where borders meet
// walls or each other (or closes on itself, then repeating its first point). Deterministic:
// chains start at their lowest vertex index. REQUIRES: ValidateFloorPlan(plan) is OK.
[[nodiscard]] std::vector<std::vector<Eigen::Vector2d>> RoomBorders(const FloorPlan& plan);

// Writes `path` (through "<path>.partial" and a rename). Errors name the file: Unavailable when
// it cannot be created, DataLoss when the writer did not finish it (a full disk); no file is
// left at either name then.
[[nodiscard]] absl::Status WriteFloorPlanDxf(const std::string& path, const FloorPlan& plan,
                                             const FloorPlanOutline& outline);

}  // namespace carvemap
