// Room polygons and walls of a floor plan (§3.3; docs/DESIGN.md §7 floorplan.geojson): the
// boundary of each room's triangles traced into rings, and the interior/exterior boundary traced
// into wall polylines.
//
// Plain functions over plain data: no files, no logging. Thread-compatible.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"

namespace carvemap {

// One connected piece of a room. A room whose triangles fall into several pieces (edge-connected
// regions, e.g. after simplification or when two parts touch only at a vertex) gives several
// RoomPolygons with the same `room` (a MultiPolygon in GeoJSON), in tracing order (walks start at
// the room's lowest unused boundary edge, in triangle order): deterministic for a given plan.
struct RoomPolygon {
  int room = -1;                                    // index into FloorPlan::rooms
  std::vector<Eigen::Vector2d> outer;               // CCW, no repeated point, not closed
  std::vector<std::vector<Eigen::Vector2d>> holes;  // CW, no repeated point, not closed
  double area_m2 = 0;                               // outer minus holes (shoelace)
};

struct FloorPlanOutline {
  std::vector<RoomPolygon> rooms;  // sorted by room, then as RoomPolygon says
  // Closed loops along the interior/exterior boundary (not the borders between rooms), interior
  // on the left (outer walls CCW, walls around inner courts CW); each repeats its first point.
  std::vector<std::vector<Eigen::Vector2d>> walls;
};

// Structural check shared by the floor-plan geometry stages. InvalidArgument: per-vertex height
// arrays of the wrong size, a triangle index out of range or repeated, triangle_room of the
// wrong size or a room index out of range. FailedPrecondition: a non-manifold triangulation (an
// edge used by more than two triangles, or twice in the same direction), naming the edge.
[[nodiscard]] absl::Status ValidateFloorPlan(const FloorPlan& plan);

// Traces every room's boundary (the directed triangle edges whose reverse is not an edge of the
// same room) and the walls. Where a ring touches itself at a vertex it is split there into simple
// rings: the walk takes the tightest clockwise turn (keeps each interior wedge to itself), then
// any vertex still visited twice cuts the ring in two. Positive rings are outers; each negative
// ring is a hole of the smallest outer of the same room around it. Errors: ValidateFloorPlan's.
[[nodiscard]] absl::StatusOr<FloorPlanOutline> TraceFloorPlan(const FloorPlan& plan);

// Where a room's label goes: the centroid of its seed triangle (§3.3.2), or of its largest
// triangle when the seed is not one of its triangles; nullopt for a room without triangles.
[[nodiscard]] std::optional<Eigen::Vector2d> RoomLabelPoint(const FloorPlan& plan, int room);

// Shoelace signed area of a ring (not closed), m²: positive when CCW.
[[nodiscard]] double RingSignedArea(const std::vector<Eigen::Vector2d>& ring);

}  // namespace carvemap
