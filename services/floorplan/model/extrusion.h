// 2.5D extrusion of a floor plan (§3.3.4, §5.3.3; docs/DESIGN.md §7 level_<k>/extruded.ply): each
// room gets one floor and one ceiling height, and the plan becomes the closed solid of the
// interior.
//
// Plain functions over plain data: no files, no logging. Thread-compatible.
#pragma once

#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"
#include "storage/ply_io.h"

namespace carvemap {

// §3.3.4: sets each room's floor_z / ceiling_z to the median of vertex_floor_z /
// vertex_ceiling_z over the distinct vertices of its triangles (mean of the two middle values
// for an even count). Rooms without triangles are left as they are. REQUIRES: a plan that
// passes ValidateFloorPlan (room_polygons.h).
void AssignRoomHeights(FloorPlan& plan);

// The closed interior solid, outward normals (triangles counter-clockwise seen from outside):
// per room its triangles as floor (facing down) at floor_z and ceiling (facing up) at
// ceiling_z; vertical walls on every interior/exterior edge; on a border between rooms R and S
// vertical step faces over [R.floor, R.ceiling] minus [S.floor, S.ceiling], facing S (and the
// same from S's side). Rooms with equal heights share their vertices, so no faces separate them.
// No T-junctions: every 2D vertex has a column of 3D vertices at the distinct heights of the
// rooms around it, and every vertical face is fanned through all the column vertices in its
// height range. Where the plan's boundary touches itself at a vertex (two fans of triangles
// meeting only there), each fan gets its own column, moved 1 mm into the fan, so the solid is
// neither pinched nor touching itself (no self-intersection there). Watertight (CheckMesh) unless the cross-section at some height touches itself
// within one fan: four rooms around a vertex whose diagonal pairs alone span some height, or a
// room's ceiling exactly at a neighbour's floor, give non-manifold edges.
// Vertices are float (PLY): coordinates carry float rounding (~1e-7 relative).
// Errors: ValidateFloorPlan's; InvalidArgument for a room (used by a triangle) whose heights are
// not finite or whose floor_z ≥ ceiling_z, naming the room.
[[nodiscard]] absl::StatusOr<TriangleMesh> ExtrudeFloorPlan(const FloorPlan& plan);

// One room's closed solid alone (its triangles extruded from its floor_z to its ceiling_z, as
// ExtrudeFloorPlan would a plan of that room only): a room as a model of its own (mesh/
// model.glb). Only the room's own vertices get columns, as in ExtrudeFloorPlan.
// Errors: ExtrudeFloorPlan's; OutOfRange for a room the plan lacks.
[[nodiscard]] absl::StatusOr<TriangleMesh> ExtrudeRoom(const FloorPlan& plan, int room);

}  // namespace carvemap
