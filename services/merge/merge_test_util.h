// Synthetic tiles for the merge tests (seeded, with known ground truth).
#pragma once

#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"
#include "storage/tile_store.h"

namespace carvemap::testing {

inline LeafStats StatsWithP(double p, int rays = 3) {
  LeafStats s;
  for (int i = 0; i < rays; ++i) s.Add(p, 0.5);
  return s;
}

inline TileLeaf Leaf(int depth, const Eigen::Vector3i& local, double p) {
  return TileLeaf{ChunkNode{local, depth}, StatsWithP(p)};
}

// Random non-overlapping leaves of one chunk: each node is left unobserved, made a leaf with
// a random p (interior or not), or split, so coarse leaves, finest leaves and holes all occur.
inline void GrowRandomLeaves(std::mt19937& rng, int k, const ChunkNode& node,
                             std::vector<TileLeaf>& out) {
  std::uniform_real_distribution<double> u(0, 1);
  const double stop = node.depth == 0 ? 0.1 : 0.35;
  if (node.depth == k || u(rng) < stop) {
    if (u(rng) < 0.25) return;  // unobserved
    static constexpr double kPs[] = {0.05, 0.3, 0.5, 0.51, 0.7, 0.95};
    out.push_back(TileLeaf{node, StatsWithP(kPs[rng() % 6])});
    return;
  }
  for (int i = 0; i < 8; ++i) {
    ChunkNode child;
    child.depth = node.depth + 1;
    child.local = node.local * 2 + Eigen::Vector3i(i & 1, (i >> 1) & 1, (i >> 2) & 1);
    GrowRandomLeaves(rng, k, child, out);
  }
}

inline TileData RandomTile(std::mt19937& rng, int k, const ChunkKey& chunk) {
  TileData tile;
  tile.chunk = chunk;
  tile.grid.chunk_depth = k;
  GrowRandomLeaves(rng, k, ChunkNode{}, tile.leaves);
  return tile;
}

// A fresh empty directory under the test temp dir, named after the running test.
inline std::string FreshDir(const std::string& suffix = "") {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string(info->test_suite_name()) + "_" + info->name() + suffix;
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

}  // namespace carvemap::testing
