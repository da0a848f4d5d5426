// Floor-plan outputs of docs/DESIGN.md §7: level_<k>/floorplan.geojson, floorplan.svg and
// extruded.ply. The builders are pure; the Write* functions are the file writers (each file is
// written through storage/atomic_file.h, so a crash leaves no half file).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "absl/status/status.h"
#include "services/floorplan/floor_plan.h"
#include "services/floorplan/model/room_polygons.h"
#include "storage/ply_io.h"

namespace carvemap {

// A GeoJSON FeatureCollection in the plan's local metres (x, y; +y north when the job turned to
// north, §2.3): GeoJSON's structure, not RFC 7946's WGS 84 longitude/latitude, and no `crs`
// member (docs/DESIGN.md §7). One Feature per room that has polygons, in
// room order — a Polygon, or a MultiPolygon when the room is in several pieces; rings closed by
// repeating the first point, exterior CCW, holes CW — with properties {room (its index), level,
// floor_z, ceiling_z, area_m2 (Σ of its pieces' areas)}; then one LineString Feature per wall
// loop with properties {kind: "wall", level}.
[[nodiscard]] nlohmann::json FloorPlanGeoJson(const FloorPlan& plan,
                                              const FloorPlanOutline& outline);

// The same drawn as SVG (1 px = 1 cm, y flipped so north is up): one <path> per room filled from
// a fixed palette (even-odd fill, all its pieces and holes), walls as black <polyline>s, one
// <text> per room with its area ("12.3 m²") at the centroid of its seed triangle (or of its
// largest triangle when the seed is not one of its triangles), and a 1 m scale bar (5 m when the
// plan is wider than 20 m).
[[nodiscard]] std::string FloorPlanSvg(const FloorPlan& plan, const FloorPlanOutline& outline);

// Writes dir/floorplan.geojson, dir/floorplan.svg and dir/floorplan.dxf (floorplan_dxf.h),
// creating dir. Errors name the file.
[[nodiscard]] absl::Status WriteFloorPlanFiles(const std::string& dir, const FloorPlan& plan,
                                               const FloorPlanOutline& outline);

// Writes the extruded model (ExtrudeFloorPlan) as docs/DESIGN.md §7 PLY.
[[nodiscard]] absl::Status WriteExtrudedPly(const std::string& path, const TriangleMesh& mesh);

}  // namespace carvemap
