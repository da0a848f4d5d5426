// Synthetic octrees for the meshing tests: tiles keyed by chunk, leaves placed by global cell,
// the 27-tile neighbourhood of a chunk, random octrees with known statistics.
#pragma once

#include <functional>
#include <map>
#include <random>

#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"
#include "storage/tile_store.h"

namespace carvemap::testing {

using Tiles = std::map<ChunkKey, TileData, ChunkKeyLess>;

inline LeafStats StatsWithP(double p) {
  LeafStats s;
  for (int i = 0; i < 3; ++i) s.Add(p, 0.5);
  return s;
}

// Adds a leaf at global node (min_cell, depth) to the tile of its chunk.
inline void AddLeaf(Tiles& tiles, const OctreeGrid& grid, const LeafKey& min_cell, int depth,
                    double p) {
  const int n = grid.leaves_per_side();
  const ChunkKey chunk = ChunkOfLeaf(grid, min_cell);
  TileData& t = tiles[chunk];
  t.chunk = chunk;
  t.grid = grid;
  const int s = 1 << (grid.chunk_depth - depth);
  t.leaves.push_back(TileLeaf{ChunkNode{(min_cell - chunk * n) / s, depth}, StatsWithP(p)});
}

inline ChunkNeighbourhood HoodOf(const Tiles& tiles, const OctreeGrid& grid,
                                 const ChunkKey& chunk) {
  ChunkNeighbourhood hood;
  hood.grid = grid;
  hood.chunk = chunk;
  for (int j = 0; j < 27; ++j) {
    const ChunkKey d(j % 3 - 1, (j / 3) % 3 - 1, j / 9 - 1);
    auto it = tiles.find(chunk + d);
    if (it != tiles.end()) hood.tiles[j] = &it->second;
  }
  return hood;
}

// A random octree in `chunk`: a node becomes a leaf with probability `stop_root` (the chunk)
// or `stop` (below), or always at the grid's depth; a leaf is left unobserved with probability
// `unobserved`, else gets a p among interior and exterior values, 0.5 included.
inline void GrowRandomTile(std::mt19937& rng, const OctreeGrid& grid, const ChunkKey& chunk,
                           double stop_root, double stop, double unobserved, Tiles& tiles) {
  std::uniform_real_distribution<double> u(0, 1);
  std::function<void(const ChunkNode&)> grow = [&](const ChunkNode& node) {
    if (node.depth == grid.chunk_depth || u(rng) < (node.depth == 0 ? stop_root : stop)) {
      if (u(rng) < unobserved) return;
      static constexpr double kPs[] = {0.05, 0.3, 0.5, 0.51, 0.7, 0.95};
      TileData& t = tiles[chunk];
      t.chunk = chunk;
      t.grid = grid;
      t.leaves.push_back(TileLeaf{node, StatsWithP(kPs[rng() % 6])});
      return;
    }
    for (int i = 0; i < 8; ++i) {
      grow(ChunkNode{node.local * 2 + Eigen::Vector3i(i & 1, (i >> 1) & 1, (i >> 2) & 1),
                     node.depth + 1});
    }
  };
  grow(ChunkNode{});
}

}  // namespace carvemap::testing
