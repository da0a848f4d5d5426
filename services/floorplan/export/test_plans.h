// Small hand-made floor plans for the tests of the floor-plan writers (DXF, IFC): plain data
// with known rooms, borders and heights.
#pragma once

#include <cstdint>

#include "services/floorplan/floor_plan.h"

namespace carvemap {

// Every vertex and room of `plan` at these heights, m.
inline void SetPlanHeights(FloorPlan& plan, double floor_z, double ceiling_z) {
  plan.vertex_floor_z.assign(plan.vertices.size(), floor_z);
  plan.vertex_ceiling_z.assign(plan.vertices.size(), ceiling_z);
  for (FloorPlanRoom& room : plan.rooms) {
    room.floor_z = floor_z;
    room.ceiling_z = ceiling_z;
  }
}

// A 2 × 1 m strip cut into two rooms by the line x = 1 (one open border: a doorway).
inline FloorPlan TwoRoomsPlan(double floor_z = 0.0, double ceiling_z = 2.5) {
  FloorPlan plan;
  plan.vertices = {{0, 0}, {1, 0}, {2, 0}, {0, 1}, {1, 1}, {2, 1}};
  plan.triangles = {{0, 1, 4}, {0, 4, 3}, {1, 2, 5}, {1, 5, 4}};
  plan.triangle_room = {0, 0, 1, 1};
  plan.rooms.resize(2);
  plan.rooms[0].seed_triangle = 0;
  plan.rooms[1].seed_triangle = 2;
  SetPlanHeights(plan, floor_z, ceiling_z);
  return plan;
}

// A 3 × 3 m room (0, a ring: an outline with a hole) around a 1 × 1 m room (1) in its middle
// (a closed border).
inline FloorPlan RoomInRoomPlan(double floor_z = 0.0, double ceiling_z = 2.5) {
  FloorPlan plan;
  plan.vertices = {{0, 0}, {3, 0}, {3, 3}, {0, 3}, {1, 1}, {2, 1}, {2, 2}, {1, 2}};
  for (uint32_t i = 0; i < 4; ++i) {
    const uint32_t j = (i + 1) % 4;
    plan.triangles.push_back({i, j, 4 + j});
    plan.triangles.push_back({i, 4 + j, 4 + i});
  }
  plan.triangles.push_back({4, 5, 6});
  plan.triangles.push_back({4, 6, 7});
  plan.triangle_room = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1};
  plan.rooms.resize(2);
  plan.rooms[0].seed_triangle = 0;
  plan.rooms[1].seed_triangle = 8;
  SetPlanHeights(plan, floor_z, ceiling_z);
  return plan;
}

}  // namespace carvemap
