// Test support for the segmentation tests: a floor plan of axis-aligned rectangular rooms.
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "geometry/octree_keys.h"
#include "services/floorplan/floor_plan.h"
#include "storage/tile_store.h"

namespace carvemap::testing {

struct TestRoom {
  Eigen::Vector2d lo, hi;
  double floor_z = 0, ceiling_z = 2.5;
};

// Each room is two counter-clockwise triangles of its own four vertices.
inline FloorPlan RectanglePlan(const std::vector<TestRoom>& rooms) {
  FloorPlan plan;
  for (const TestRoom& r : rooms) {
    const uint32_t b = static_cast<uint32_t>(plan.vertices.size());
    for (const Eigen::Vector2d& v : {r.lo, Eigen::Vector2d(r.hi.x(), r.lo.y()), r.hi,
                                     Eigen::Vector2d(r.lo.x(), r.hi.y())}) {
      plan.vertices.push_back(v);
      plan.vertex_floor_z.push_back(r.floor_z);
      plan.vertex_ceiling_z.push_back(r.ceiling_z);
    }
    const int room = static_cast<int>(plan.rooms.size());
    plan.triangles.push_back({b, b + 1, b + 2});
    plan.triangles.push_back({b, b + 2, b + 3});
    plan.triangle_room.insert(plan.triangle_room.end(), 2, room);
    FloorPlanRoom fr;
    fr.area_m2 = (r.hi - r.lo).prod();
    fr.floor_z = r.floor_z;
    fr.ceiling_z = r.ceiling_z;
    plan.rooms.push_back(fr);
  }
  return plan;
}

// The tile of `chunk` at the finest depth: one leaf per cell with p = p_at(its global cell),
// or none (unobserved) where p_at is negative.
inline TileData FinestTileOfChunk(const OctreeGrid& grid, const ChunkKey& chunk,
                                  const std::function<double(const LeafKey&)>& p_at) {
  TileData t;
  t.chunk = chunk;
  t.grid = grid;
  const int n = grid.leaves_per_side();
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double p = p_at(chunk * n + LeafKey(x, y, z));
        if (p < 0) continue;
        LeafStats s;
        s.Add(p, 0.5);
        s.Add(p, 0.25);
        t.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, z), grid.chunk_depth}, s});
      }
  return t;
}

// The tile of chunk (0, 0, 0) at the finest depth: one leaf per cell with p = p_at(its centre),
// or none (unobserved) where p_at is negative.
inline TileData FinestTile(const OctreeGrid& grid,
                           const std::function<double(const Eigen::Vector3d&)>& p_at) {
  return FinestTileOfChunk(grid, ChunkKey::Zero(),
                           [&](const LeafKey& cell) { return p_at(LeafCenter(grid, cell)); });
}

// Whether `c` lies inside the open box (lo, hi).
inline bool Inside(const Eigen::Vector3d& c, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  return (c.array() > lo.array()).all() && (c.array() < hi.array()).all();
}

}  // namespace carvemap::testing
