// A building with known truth (docs/DESIGN.md §4): solids for the ray caster, the ground-truth
// levels/rooms/doors/objects, and what the walk needs to plan a route. Made by the presets
// (building_presets.h) or by extruding a 2D floor map (floormap_building.h).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "storage/ply_io.h"

namespace carvemap {

// A vertical prism: a convex footprint (counter-clockwise, no repeated first point) extruded
// from z0 to z1. Every solid in a building is one (walls, slabs, steps, furniture parts), so
// geometry is closed and "inside a solid" is well defined.
struct Prism {
  std::vector<Eigen::Vector2d> footprint;
  double z0 = 0, z1 = 0;  // m, z0 < z1
};

struct LevelTruth {
  int index = 0;
  double floor_z = 0, ceiling_z = 0;  // ceiling_z: the level's highest room ceiling
};

struct RoomTruth {
  int id = 0;
  int level = 0;
  std::vector<Eigen::Vector2d> polygon;             // CCW ring, no repeated first point
  std::vector<std::vector<Eigen::Vector2d>> holes;  // CW rings (columns inside the room)
  double floor_z = 0, ceiling_z = 0;
  bool entered = true;  // the walk enters it (false: only seen through its door)
};

struct DoorTruth {
  int id = 0;
  int level = 0;
  int room_a = -1, room_b = -1;  // room ids; -1 = outside the building
  Eigen::Vector2d p0, p1;        // the door's segment across the opening
  double width = 0;              // m
};

struct ObjectTruth {
  int id = 0;
  std::string kind;  // "desk", "table", "chair", "shelf", "cabinet", "ceiling_light", …
  int level = 0;
  std::vector<Prism> parts;  // the solids it is made of
  [[nodiscard]] Eigen::AlignedBox3d Aabb() const;
};

// A 2D grid of where a person can walk on one level (floor free, clearance kept).
struct NavGrid {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  // world x, y of cell (0, 0)'s corner
  double resolution_m = 0.1;
  int width = 0, height = 0;   // cells along x, y
  std::vector<uint8_t> free;   // width·height, index = iy·width + ix; 1 = walkable
  [[nodiscard]] bool IsFree(int ix, int iy) const {
    return ix >= 0 && iy >= 0 && ix < width && iy < height && free[size_t(iy) * width + ix];
  }
  // Added: the cell holding world point `p` (may be outside the grid) and a cell's centre.
  [[nodiscard]] Eigen::Vector2i CellOf(const Eigen::Vector2d& p) const;
  [[nodiscard]] Eigen::Vector2d CellCenter(int ix, int iy) const;
};

// Stairs between two levels: the centre line a walker follows, bottom landing to top landing.
struct StairTruth {
  int from_level = 0, to_level = 1;
  std::vector<Eigen::Vector3d> centerline;  // floor-contact points, z rising
};

struct Building {
  std::string name;
  std::vector<LevelTruth> levels;
  std::vector<RoomTruth> rooms;
  std::vector<DoorTruth> doors;
  std::vector<ObjectTruth> objects;
  std::vector<Prism> structure;  // walls, floors, ceilings, columns, stairs: the building alone
  std::vector<NavGrid> nav;      // one per level, same index as `levels`
  // Per room (same index as `rooms`): a point on its floor the walk goes to; NaN if not entered.
  std::vector<Eigen::Vector2d> visit_points;
  std::vector<StairTruth> stairs;
};

// Closed triangle meshes of prisms (side quads + convex caps), outward normals.
[[nodiscard]] TriangleMesh PrismMesh(const Prism& prism);
[[nodiscard]] TriangleMesh StructureMesh(const Building& building);
// All objects; `object_of_triangle` (optional) receives the object id of each triangle.
[[nodiscard]] TriangleMesh ObjectsMesh(const Building& building,
                                       std::vector<int>* object_of_triangle = nullptr);

// ---- Added helpers (polygons and nav-grid rasterization), shared by the generators and tests.

// Shoelace area of a ring: > 0 for counter-clockwise.
[[nodiscard]] double SignedArea(const std::vector<Eigen::Vector2d>& ring);
// Even-odd point-in-ring test (points exactly on the boundary may go either way).
[[nodiscard]] bool RingContains(const std::vector<Eigen::Vector2d>& ring, const Eigen::Vector2d& p);
// Inside the room's outer ring and outside all its holes.
[[nodiscard]] bool RoomContains(const RoomTruth& room, const Eigen::Vector2d& p);
// Free-space area of the room: outer ring minus holes, m².
[[nodiscard]] double RoomArea(const RoomTruth& room);

// Cells (same layout as `frame`) touched by the footprint of any solid (structure or object
// part) that overlaps the height band [z_lo, z_hi] (m): what a walker's body would hit.
[[nodiscard]] std::vector<uint8_t> BlockedCells(const NavGrid& frame, const Building& building,
                                                double z_lo, double z_hi);
// Euclidean distance (in cells, between cell centres) from every cell to the nearest cell with
// blocked != 0 (Felzenszwalb–Huttenlocher); +inf-like (1e9) when nothing is blocked.
[[nodiscard]] std::vector<float> DistanceToBlocked(const std::vector<uint8_t>& blocked, int width,
                                                   int height);

}  // namespace carvemap
