// Test-only: a hand-built box room Building (voxblox SimulationWorld style) whose surfaces
// are known exactly: the interior is [0, size.x] × [0, size.y] × [0, size.z].
#pragma once

#include <cmath>
#include <limits>

#include "services/building/building.h"

namespace carvemap::testing {

inline Prism BoxPrism(double x0, double y0, double x1, double y1, double z0, double z1) {
  Prism p;
  p.footprint = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  p.z0 = z0;
  p.z1 = z1;
  return p;
}

// Walls, floor and ceiling 0.2 m thick; a nav grid with 0.3 m clearance from the walls; one
// room entered, its visit point at the centre. With `table`, a 1×0.6×0.75 m object sits in
// a corner.
inline Building MakeBoxRoom(const Eigen::Vector3d& size = Eigen::Vector3d(6, 4, 2.6),
                            bool table = true) {
  const double W = size.x(), D = size.y(), H = size.z(), t = 0.2;
  Building b;
  b.name = "box_room";
  b.levels = {LevelTruth{0, 0.0, H}};
  RoomTruth room;
  room.id = 0;
  room.polygon = {{0, 0}, {W, 0}, {W, D}, {0, D}};
  room.floor_z = 0;
  room.ceiling_z = H;
  b.rooms = {room};
  b.structure = {BoxPrism(-t, -t, W + t, D + t, -t, 0),      // floor
                 BoxPrism(-t, -t, W + t, D + t, H, H + t),   // ceiling
                 BoxPrism(-t, -t, 0, D + t, 0, H),           // west wall
                 BoxPrism(W, -t, W + t, D + t, 0, H),        // east wall
                 BoxPrism(0, -t, W, 0, 0, H),                // south wall
                 BoxPrism(0, D, W, D + t, 0, H)};            // north wall
  if (table) {
    ObjectTruth obj;
    obj.id = 1;
    obj.kind = "table";
    obj.parts = {BoxPrism(W - 1.2, D - 0.8, W - 0.2, D - 0.2, 0, 0.75)};
    b.objects = {obj};
  }
  NavGrid g;
  g.origin = Eigen::Vector2d(0, 0);
  g.resolution_m = 0.1;
  g.width = static_cast<int>(std::round(W / g.resolution_m));
  g.height = static_cast<int>(std::round(D / g.resolution_m));
  g.free.assign(static_cast<size_t>(g.width) * g.height, 0);
  for (int iy = 0; iy < g.height; ++iy) {
    for (int ix = 0; ix < g.width; ++ix) {
      const double x = (ix + 0.5) * g.resolution_m, y = (iy + 0.5) * g.resolution_m;
      bool ok = x > 0.3 && y > 0.3 && x < W - 0.3 && y < D - 0.3;
      if (table) ok = ok && !(x > W - 1.5 && y > D - 1.1);
      g.free[static_cast<size_t>(iy) * g.width + ix] = ok;
    }
  }
  b.nav = {g};
  b.visit_points = {Eigen::Vector2d(W / 2, D / 2)};
  return b;
}

}  // namespace carvemap::testing
