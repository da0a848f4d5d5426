// Small hand-made floor plans for the floor-plan parts' tests (simplification, polygons,
// extrusion, the writers): plain data with known rooms, borders and heights.
#pragma once

#include <cstdint>
#include <functional>

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

// A plan on a grid of nx × ny square cells of cell_m, two CCW triangles per cell, room =
// label(i, j) or -1 for none (`rooms` rooms, no seeds); floor at 0, ceiling at 3 m. Cells'
// vertices are shared, so the triangulation is manifold; cell sizes that are powers of two
// keep every coordinate exact in float.
inline FloorPlan GridPlan(int nx, int ny, double cell_m, const std::function<int(int, int)>& label,
                          int rooms) {
  FloorPlan plan;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      plan.vertices.emplace_back(i * cell_m, j * cell_m);
      plan.vertex_floor_z.push_back(0);
      plan.vertex_ceiling_z.push_back(3);
    }
  }
  auto v = [&](int i, int j) { return static_cast<uint32_t>(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int r = label(i, j);
      if (r < 0) continue;
      plan.triangles.push_back({v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      plan.triangles.push_back({v(i, j), v(i + 1, j + 1), v(i, j + 1)});
      plan.triangle_room.push_back(r);
      plan.triangle_room.push_back(r);
    }
  }
  plan.rooms.resize(rooms);
  return plan;
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
