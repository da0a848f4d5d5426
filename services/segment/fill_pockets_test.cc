#include "services/segment/fill_pockets.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <set>
#include <span>
#include <vector>

namespace carvemap {
namespace {

// A tile of `chunk` at the finest depth: one leaf per cell with p = p_at(its global cell), or
// none (unobserved) where p_at is negative.
TileData Tile(const OctreeGrid& grid, const ChunkKey& chunk,
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

// The filled cells of `filled` (the leaves `input` did not have), by global cell, with their p.
std::map<std::array<int, 3>, double> Filled(const TileData& input, const FilledChunk& filled) {
  std::set<std::array<int, 3>> had;
  for (const TileLeaf& l : input.leaves)
    had.insert({l.node.local.x(), l.node.local.y(), l.node.local.z()});
  std::map<std::array<int, 3>, double> out;
  const int n = filled.tile.grid.leaves_per_side();
  for (const TileLeaf& l : filled.tile.leaves) {
    if (had.count({l.node.local.x(), l.node.local.y(), l.node.local.z()})) continue;
    const LeafKey g = filled.tile.chunk * n + l.node.local;
    out[{g.x(), g.y(), g.z()}] = l.stats.p();
  }
  return out;
}

class FillPocketsTest : public ::testing::Test {
 protected:
  // 12.5 cm cells: 16 per chunk side.
  OctreeGrid grid_ = *OctreeGrid::FromResolution(0.125);
  ChunkNeighbourhood Hood(const ChunkKey& chunk, std::span<const TileData> tiles) const {
    ChunkNeighbourhood hood;
    hood.grid = grid_;
    hood.chunk = chunk;
    for (const TileData& t : tiles) {
      const ChunkKey d = t.chunk - chunk;
      if ((d.array().abs() <= 1).all())
        hood.tiles[ChunkNeighbourhood::Index(d.x(), d.y(), d.z())] = &t;
    }
    return hood;
  }
};

TEST_F(FillPocketsTest, FillsAThinUnobservedLayerBetweenFreeSpace) {
  // Free air (p 0.9 below, 0.8 above) with a layer of three unobserved cells at z 6–8 (0.375 m).
  const TileData in = Tile(grid_, ChunkKey(0, 0, 0), [](const LeafKey& c) {
    if (c.z() >= 6 && c.z() <= 8) return -1.0;
    return c.z() < 6 ? 0.9 : 0.8;
  });
  absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}));
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(out->filled_cells, 3u * 16 * 16);
  const auto filled = Filled(in, *out);
  ASSERT_EQ(filled.size(), 3u * 16 * 16);
  for (const auto& [cell, p] : filled) {
    EXPECT_GE(cell[2], 6);
    EXPECT_LE(cell[2], 8);
    EXPECT_DOUBLE_EQ(p, 0.8);  // the lower of the two ends
  }
  // The filled tile is a valid tile: no overlaps, sums consistent.
  EXPECT_TRUE(EncodeTile(::testing::TempDir(), out->tile).ok());
}

TEST_F(FillPocketsTest, KeepsPocketsThickerThanTheLimit) {
  // Five unobserved cells (0.625 m) between free space: thicker than the default 0.5 m.
  const TileData in = Tile(grid_, ChunkKey(0, 0, 0),
                           [](const LeafKey& c) { return c.z() >= 6 && c.z() <= 10 ? -1.0 : 0.9; });
  absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}));
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(out->filled_cells, 0u);
  EXPECT_EQ(out->tile.leaves.size(), in.leaves.size());
  // With a 0.7 m limit (five cells fit) they are filled.
  out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}), PocketFillOptions{0.7});
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(out->filled_cells, 5u * 16 * 16);
}

TEST_F(FillPocketsTest, LeavesSpaceThatEndsAtASolidSurface) {
  // Unobserved cells behind a solid wall (x 8, p 0.2) and the hidden inside of a 3-cell thick
  // wall between two solid faces: neither has free space at both ends.
  const TileData in = Tile(grid_, ChunkKey(0, 0, 0), [](const LeafKey& c) {
    if (c.x() == 4 || c.x() == 8) return 0.2;    // the wall's two observed faces
    if (c.x() >= 5 && c.x() <= 7) return -1.0;   // its unobserved inside
    if (c.x() >= 9 && c.x() <= 10) return -1.0;  // unswept air in front of it
    return 0.9;
  });
  absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}));
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(out->filled_cells, 0u);
}

TEST_F(FillPocketsTest, ScanPointsEndAPocketAsASurfaceDoes) {
  // Two unobserved cells between free space, and a stored leaf no ray observed (scan points
  // only) in the middle of the column x = y = 0: that column is not filled.
  TileData in = Tile(grid_, ChunkKey(0, 0, 0),
                     [](const LeafKey& c) { return c.z() >= 6 && c.z() <= 7 ? -1.0 : 0.9; });
  LeafStats points_only;
  points_only.points = 3;
  in.leaves.push_back(
      TileLeaf{ChunkNode{Eigen::Vector3i(0, 0, 6), grid_.chunk_depth}, points_only});
  absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}));
  ASSERT_TRUE(out.ok()) << out.status();
  const auto filled = Filled(in, *out);
  EXPECT_EQ(filled.count({0, 0, 6}), 0u);
  // (0, 0, 7) is one cell between the points and free space: not free at both ends along z,
  // but along x and y its neighbours are free.
  EXPECT_EQ(filled.count({0, 0, 7}), 0u) << "x and y: its run reaches the chunk's face";
  EXPECT_EQ(filled.count({1, 1, 7}), 1u);
}

TEST_F(FillPocketsTest, RunsCrossChunkFaces) {
  // The pocket spans the top face of chunk (0, 0, 0): cells z 14–15 below it and 16 above
  // (global), free beyond both. Each chunk fills its own part.
  const auto p_at = [](const LeafKey& c) { return c.z() >= 14 && c.z() <= 16 ? -1.0 : 0.9; };
  const std::vector<TileData> tiles = {Tile(grid_, ChunkKey(0, 0, 0), p_at),
                                       Tile(grid_, ChunkKey(0, 0, 1), p_at)};
  absl::StatusOr<FilledChunk> low = FillPockets(Hood(ChunkKey(0, 0, 0), tiles));
  absl::StatusOr<FilledChunk> high = FillPockets(Hood(ChunkKey(0, 0, 1), tiles));
  ASSERT_TRUE(low.ok()) << low.status();
  ASSERT_TRUE(high.ok()) << high.status();
  EXPECT_EQ(low->filled_cells, 2u * 16 * 16);
  EXPECT_EQ(high->filled_cells, 1u * 16 * 16);
  // Without the neighbour, the lower chunk cannot see the run's far end: nothing filled.
  absl::StatusOr<FilledChunk> alone = FillPockets(Hood(ChunkKey(0, 0, 0), {&tiles[0], 1}));
  ASSERT_TRUE(alone.ok()) << alone.status();
  EXPECT_EQ(alone->filled_cells, 0u);
}

TEST_F(FillPocketsTest, CoarseLeavesCountForEveryCellTheyCover) {
  // The chunk's lower half one free leaf of depth 1 (p 0.9) … as simplification leaves it;
  // cells z 8–9 unobserved; above them free finest cells.
  TileData in;
  in.chunk = ChunkKey(0, 0, 0);
  in.grid = grid_;
  LeafStats free_stats;
  free_stats.Add(0.9, 1.0);
  for (int x = 0; x < 2; ++x)
    for (int y = 0; y < 2; ++y)
      in.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, 0), 1}, free_stats});
  for (int z = 10; z < 16; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x)
        in.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, z), 4}, free_stats});
  absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}));
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(out->filled_cells, 2u * 16 * 16);
  EXPECT_TRUE(EncodeTile(::testing::TempDir(), out->tile).ok());
}

TEST_F(FillPocketsTest, NoTileNoLeaves) {
  absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(2, 0, 0), {}));
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(out->filled_cells, 0u);
  EXPECT_TRUE(out->tile.leaves.empty());
  EXPECT_EQ(out->tile.chunk, ChunkKey(2, 0, 0));
}

TEST_F(FillPocketsTest, BadInputIsAnError) {
  const TileData in = Tile(grid_, ChunkKey(0, 0, 0), [](const LeafKey&) { return 0.9; });
  for (double bad : {0.0, -1.0, std::nan("")}) {
    absl::StatusOr<FilledChunk> out = FillPockets(Hood(ChunkKey(0, 0, 0), {&in, 1}), {bad});
    ASSERT_FALSE(out.ok());
    EXPECT_EQ(out.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(out.status().message().find("max_thickness_m"), std::string::npos);
  }
  // A tile in the wrong slot.
  ChunkNeighbourhood hood = Hood(ChunkKey(0, 0, 0), {&in, 1});
  hood.tiles[ChunkNeighbourhood::Index(1, 0, 0)] = &in;
  absl::StatusOr<FilledChunk> out = FillPockets(hood);
  ASSERT_FALSE(out.ok());
  EXPECT_NE(out.status().message().find("neighbour slot 1,0,0"), std::string::npos) << out.status();
}

}  // namespace
}  // namespace carvemap
