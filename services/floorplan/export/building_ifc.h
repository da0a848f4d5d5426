// building.ifc (docs/DESIGN.md §7): the floor plans of every level as one IFC 4 building model
// (ISO 10303-21 text, FILE_SCHEMA(('IFC4'))) for BIM programs:
//   IfcProject (SI units: metre, square metre, cubic metre, radian; a 3D 'Model' context with a
//   'Body' subcontext) ➜ IfcSite ➜ IfcBuilding ➜ one IfcBuildingStorey per level ("level <k>",
//   Elevation = the level's floor_z) ➜ one IfcSpace per room with triangles ("level <k> room
//   <r>": its polygons extruded from the room's floor_z to its ceiling_z (§3.3.4), one
//   IfcExtrudedAreaSolid per piece, holes as voids; Qto_SpaceBaseQuantities NetFloorArea, Height,
//   NetVolume);
//   IfcWall per straight run of the wall loops (room_polygons.h; "level <k> wall <w>"): a slab
//   of `wall_thickness_m` on the exterior side of the loop, from floor to ceiling of the room it
//   bounds;
//   IfcDoor per chain of borders between two rooms (RoomBorders, floorplan_dxf.h; "level <k>
//   door <d>") as wide as a door: §3.3 splits rooms where the interior narrows, at doorways.
//   Standalone, contained in the storey (building_ifc.cc says why). A chain narrower or wider
//   than a door is an IfcVirtualElement ("level <k> opening <d>"), the virtual boundary IFC
//   has for two spaces not separated by anything built;
//   IfcRelSpaceBoundary from each space to the walls and doors around it.
// Coordinates are the plans' (x, y in metres, z up); the model's y is what the job calls north
// (IfcGeometricRepresentationContext.TrueNorth is left at its default, +y).
//
// GlobalIds are derived from the SHA-256 of the plans and each entity's role ("level 2 room
// 5"), so the same plans give the same bytes and other buildings other ids; the header's time
// stamp is fixed for the same reason.
//
// Plain function over plain data: no logging.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"
#include "services/levels/level_split.h"

namespace carvemap {

struct BuildingIfcOptions {
  // The plans know where a wall's face is, not how thick the wall is: walls are drawn as slabs
  // this thick behind the face (both faces of a 10 cm partition then meet without crossing),
  // and doors as slabs this thick across the doorway, m.
  double wall_thickness_m = 0.05;
  // A door's height, or the room's when lower (the plans do not see the door's top), m.
  double door_height_m = 2.1;
  // Borders between two rooms this long (m) are doors; shorter ones (where three rooms meet)
  // and longer ones (a room opening wide onto a corridor, which §3.3 splits where the interior
  // narrows less than at a door) are the spaces' virtual boundaries.
  double min_door_width_m = 0.5;
  double max_door_width_m = 2.5;
};

struct BuildingIfcCounts {
  size_t storeys = 0;
  size_t spaces = 0;
  size_t walls = 0;
  size_t doors = 0;
  size_t openings = 0;  // IfcVirtualElement
  size_t entities = 0;  // instances in the DATA section
};

// Writes `path` (through "<path>.partial" and a rename). `plans`: each level with its floor
// plan, rooms' floor_z and ceiling_z filled (AssignRoomHeights). Errors: TraceFloorPlan's and
// InvalidArgument for a height or position that is not finite, naming the level (and room);
// InvalidArgument for options not positive; WriteFileAtomically's, naming the file. No file is
// left at either name on an error.
[[nodiscard]] absl::StatusOr<BuildingIfcCounts> WriteBuildingIfc(
    const std::string& path, std::span<const std::pair<Level, FloorPlan>> plans,
    const BuildingIfcOptions& options = {});

}  // namespace carvemap
