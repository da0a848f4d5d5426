// A floor plan of one level (§3.3; docs/DESIGN.md §6 stage 5): the interior triangles of the 2D
// Delaunay triangulation of the wall samples, each labelled with its room. Made by
// room_labeling.h (§3.3.1–§3.3.2), simplified by floorplan_simplify.h (§3.3.3), turned into room
// polygons and walls by room_polygons.h, extruded by extrusion.h (§3.3.4).
//
// Plain data; no files, no logging.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace carvemap {

struct FloorPlanRoom {
  int seed_triangle = -1;      // index into FloorPlan::triangles (§3.3.2 room seed)
  double seed_radius_m = 0;    // its circumradius
  double area_m2 = 0;          // Σ of its triangles' areas
  // §3.3.4: the median floor and ceiling heights of the room's vertices (extrusion.h fills
  // them with AssignRoomHeights; 0 until then), m.
  double floor_z = 0;
  double ceiling_z = 0;
};

struct FloorPlan {
  int level = 0;
  // Triangulation vertices (the wall samples' positions; simplification moves and removes
  // some) with the sample's floor and ceiling heights, m.
  std::vector<Eigen::Vector2d> vertices;
  std::vector<double> vertex_floor_z;
  std::vector<double> vertex_ceiling_z;
  // Interior triangles only, counter-clockwise, as vertex indices. Exterior triangles are not
  // kept: the boundary between interior and exterior is the walls.
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<int> triangle_room;  // per triangle: index into rooms
  std::vector<FloorPlanRoom> rooms;
};

}  // namespace carvemap
