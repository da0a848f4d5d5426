#include "services/segment/fill_pockets.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <set>
#include <span>
#include <vector>

#include "services/segment/segment_test_util.h"

namespace carvemap {
namespace {

using testing::FinestTileOfChunk;

// The cells filled when `chunks` are the whole job: every chunk's candidates, then whole
// pockets, by global cell (x, y, z) with their p. The candidates kept per chunk, less the
// tainted pockets inside one chunk (DropInnerTaintedPockets, KeepFillablePocketCells: as the
// merge does), must give the same cells as all at once.
std::map<std::array<int, 3>, double> Filled(const OctreeGrid& grid, std::span<const TileData> tiles,
                                            std::span<const ChunkKey> chunks,
                                            const PocketFillOptions& options = {}) {
  std::vector<PocketCell> candidates;
  std::vector<std::pair<ChunkKey, std::vector<PocketCell>>> per_chunk;
  for (const ChunkKey& chunk : chunks) {
    ChunkNeighbourhood hood;
    hood.grid = grid;
    hood.chunk = chunk;
    for (const TileData& t : tiles) {
      const ChunkKey d = t.chunk - chunk;
      if ((d.array().abs() <= 1).all()) {
        hood.tiles[ChunkNeighbourhood::Index(d.x(), d.y(), d.z())] = &t;
      }
    }
    absl::StatusOr<std::vector<PocketCell>> c = PocketCandidates(hood, options);
    EXPECT_TRUE(c.ok()) << c.status();
    if (c.ok()) {
      candidates.insert(candidates.end(), c->begin(), c->end());
      per_chunk.emplace_back(chunk, *c);
      DropInnerTaintedPockets(per_chunk.back().second, chunk, grid);
    }
  }
  std::map<std::array<int, 3>, double> out;
  for (const PocketCell& c : FillablePocketCells(candidates)) {
    out[{c.cell.x(), c.cell.y(), c.cell.z()}] = c.p;
  }
  std::reverse(per_chunk.begin(), per_chunk.end());  // any order of chunks
  const absl::Status kept = KeepFillablePocketCells(per_chunk, grid);
  EXPECT_TRUE(kept.ok()) << kept;
  std::map<std::array<int, 3>, double> by_chunk;
  for (size_t i = 0; i < per_chunk.size(); ++i) {
    if (i > 0) {
      EXPECT_TRUE(ChunkKeyLess{}(per_chunk[i - 1].first, per_chunk[i].first));
    }
    for (const PocketCell& c : per_chunk[i].second) {
      by_chunk[{c.cell.x(), c.cell.y(), c.cell.z()}] = c.p;
    }
  }
  EXPECT_EQ(by_chunk, out);
  return out;
}

bool InSlab(const LeafKey& c, int x0, int x1, int z0, int z1) {
  return c.x() >= x0 && c.x() <= x1 && c.y() >= 2 && c.y() <= 13 && c.z() >= z0 && c.z() <= z1;
}

class FillPocketsTest : public ::testing::Test {
 protected:
  // 12.5 cm cells: 16 per chunk side; 0.5 m is 4 cells.
  OctreeGrid grid_ = *OctreeGrid::FromResolution(0.125);
  const ChunkKey origin_ = ChunkKey::Zero();
};

TEST_F(FillPocketsTest, FillsAThinUnobservedSlabInsideFreeSpace) {
  // Free air (p 0.9 below, 0.8 above) around a slab of unobserved cells x, y 2–13, z 6–8
  // (0.375 m thick).
  const TileData in = FinestTileOfChunk(grid_, origin_, [](const LeafKey& c) {
    if (InSlab(c, 2, 13, 6, 8)) return -1.0;
    return c.z() < 6 ? 0.9 : 0.8;
  });
  const auto filled = Filled(grid_, {&in, 1}, {&origin_, 1});
  ASSERT_EQ(filled.size(), 12u * 12 * 3);
  for (const auto& [cell, p] : filled) {
    EXPECT_TRUE(InSlab(LeafKey(cell[0], cell[1], cell[2]), 2, 13, 6, 8));
    EXPECT_DOUBLE_EQ(p, 0.8);  // the lower of the two ends
  }
  // The tile with them is a valid tile: no overlaps, sums consistent.
  std::vector<PocketCell> cells;
  for (const auto& [cell, p] : filled) {
    cells.push_back({LeafKey(cell[0], cell[1], cell[2]), false, p});
  }
  absl::StatusOr<TileData> with = WithFilledCells(in, cells);
  ASSERT_TRUE(with.ok()) << with.status();
  EXPECT_EQ(with->leaves.size(), in.leaves.size() + cells.size());
  EXPECT_TRUE(EncodeTile(::testing::TempDir(), *with).ok());
}

TEST_F(FillPocketsTest, KeepsPocketsThickerThanTheLimit) {
  // Five cells (0.625 m) thick: more than the default 0.5 m.
  const TileData in = FinestTileOfChunk(
      grid_, origin_, [](const LeafKey& c) { return InSlab(c, 2, 13, 6, 10) ? -1.0 : 0.9; });
  EXPECT_TRUE(Filled(grid_, {&in, 1}, {&origin_, 1}).empty());
  // With a 0.7 m limit (five cells fit) it is filled.
  EXPECT_EQ(Filled(grid_, {&in, 1}, {&origin_, 1}, PocketFillOptions{0.7}).size(), 12u * 12 * 5);
}

TEST_F(FillPocketsTest, FillsOnlyWholePockets) {
  // One unobserved region, two cells thick for x 2–7 and six (0.75 m) for x 8–13: its thin
  // part alone would be a pocket, but filling it would leave a wall of our own at x = 8.
  const TileData in = FinestTileOfChunk(grid_, origin_, [](const LeafKey& c) {
    return InSlab(c, 2, 7, 6, 7) || InSlab(c, 8, 13, 6, 11) ? -1.0 : 0.9;
  });
  EXPECT_TRUE(Filled(grid_, {&in, 1}, {&origin_, 1}).empty());
  // Its candidates, inside the chunk and tainted, are dropped before the chunks are joined.
  ChunkNeighbourhood hood;
  hood.grid = grid_;
  hood.chunk = origin_;
  hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)] = &in;
  absl::StatusOr<std::vector<PocketCell>> candidates = PocketCandidates(hood);
  ASSERT_TRUE(candidates.ok()) << candidates.status();
  EXPECT_FALSE(candidates->empty());
  DropInnerTaintedPockets(*candidates, origin_, grid_);
  EXPECT_TRUE(candidates->empty());
  // The thin part with a free column between it and the thick part: a pocket of its own.
  const TileData apart = FinestTileOfChunk(grid_, origin_, [](const LeafKey& c) {
    return InSlab(c, 2, 6, 6, 7) || InSlab(c, 8, 13, 6, 11) ? -1.0 : 0.9;
  });
  EXPECT_EQ(Filled(grid_, {&apart, 1}, {&origin_, 1}).size(), 5u * 12 * 2);
}

TEST_F(FillPocketsTest, LeavesSpaceThatEndsAtASolidSurface) {
  // The unobserved inside of a wall three cells thick between its two observed faces (x 4 and
  // 8, p 0.2), and unswept air between its face and free space (x 9–10).
  const TileData in = FinestTileOfChunk(grid_, origin_, [](const LeafKey& c) {
    if (c.x() == 4 || c.x() == 8) return 0.2;
    if ((c.x() >= 5 && c.x() <= 7) || (c.x() >= 9 && c.x() <= 10)) return -1.0;
    return 0.9;
  });
  EXPECT_TRUE(Filled(grid_, {&in, 1}, {&origin_, 1}).empty());
}

TEST_F(FillPocketsTest, ScanPointsInAPocketKeepItUnobserved) {
  // A two-cell slab with a stored leaf no ray observed (scan points only) inside it: a
  // surface may be there, so the pocket is not filled.
  TileData in = FinestTileOfChunk(
      grid_, origin_, [](const LeafKey& c) { return InSlab(c, 2, 13, 6, 7) ? -1.0 : 0.9; });
  EXPECT_EQ(Filled(grid_, {&in, 1}, {&origin_, 1}).size(), 12u * 12 * 2);
  LeafStats points_only;
  points_only.points = 3;
  in.leaves.push_back(
      TileLeaf{ChunkNode{Eigen::Vector3i(5, 5, 6), grid_.chunk_depth}, points_only});
  EXPECT_TRUE(Filled(grid_, {&in, 1}, {&origin_, 1}).empty());
}

TEST_F(FillPocketsTest, PocketsSpanChunks) {
  // A slab across the top face of chunk (0, 0, 0): global z 14–16, free around it.
  const auto across_z = [](const LeafKey& c) { return InSlab(c, 2, 13, 14, 16) ? -1.0 : 0.9; };
  const std::vector<TileData> tiles = {FinestTileOfChunk(grid_, ChunkKey(0, 0, 0), across_z),
                                       FinestTileOfChunk(grid_, ChunkKey(0, 0, 1), across_z)};
  const std::vector<ChunkKey> both = {ChunkKey(0, 0, 0), ChunkKey(0, 0, 1)};
  EXPECT_EQ(Filled(grid_, tiles, both).size(), 12u * 12 * 3);
  // Without the upper chunk's tile the slab opens on unobserved space: nothing filled.
  EXPECT_TRUE(Filled(grid_, {&tiles[0], 1}, {&origin_, 1}).empty());
  // A slab across the +x face, two cells thick in chunk (0, 0, 0) and six in chunk (1, 0, 0)
  // beyond x = 26: the thick end, 10 cells into the next chunk, keeps both parts unobserved.
  const auto across_x = [](const LeafKey& c) {
    if (c.y() < 2 || c.y() > 13 || c.x() < 4 || c.x() > 29) return 0.9;
    if (c.x() >= 26) return c.z() >= 6 && c.z() <= 11 ? -1.0 : 0.9;
    return c.z() >= 6 && c.z() <= 7 ? -1.0 : 0.9;
  };
  const std::vector<TileData> side = {FinestTileOfChunk(grid_, ChunkKey(0, 0, 0), across_x),
                                      FinestTileOfChunk(grid_, ChunkKey(1, 0, 0), across_x)};
  const std::vector<ChunkKey> pair = {ChunkKey(0, 0, 0), ChunkKey(1, 0, 0)};
  EXPECT_TRUE(Filled(grid_, side, pair).empty());
}

TEST_F(FillPocketsTest, CoarseLeavesCountForEveryCellTheyCover) {
  // The chunk's lower half four free leaves of depth 1 (as simplification leaves them), cells
  // x, y 2–13, z 8–9 unobserved, every other cell above a free finest leaf.
  TileData in;
  in.chunk = origin_;
  in.grid = grid_;
  LeafStats free_stats;
  free_stats.Add(0.9, 1.0);
  for (int x = 0; x < 2; ++x)
    for (int y = 0; y < 2; ++y)
      in.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, 0), 1}, free_stats});
  for (int z = 8; z < 16; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) {
        if (InSlab(LeafKey(x, y, z), 2, 13, 8, 9)) continue;
        in.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, z), 4}, free_stats});
      }
  EXPECT_EQ(Filled(grid_, {&in, 1}, {&origin_, 1}).size(), 12u * 12 * 2);
}

TEST_F(FillPocketsTest, NoTileNoCandidates) {
  ChunkNeighbourhood hood;
  hood.grid = grid_;
  hood.chunk = ChunkKey(2, 0, 0);
  absl::StatusOr<std::vector<PocketCell>> out = PocketCandidates(hood);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_TRUE(out->empty());
}

TEST_F(FillPocketsTest, BadInputIsAnError) {
  const TileData in = FinestTileOfChunk(grid_, origin_, [](const LeafKey&) { return 0.9; });
  ChunkNeighbourhood hood;
  hood.grid = grid_;
  hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)] = &in;
  for (double bad : {0.0, -1.0, std::nan("")}) {
    absl::StatusOr<std::vector<PocketCell>> out = PocketCandidates(hood, {bad});
    ASSERT_FALSE(out.ok());
    EXPECT_EQ(out.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(out.status().message().find("max_thickness_m"), std::string::npos);
  }
  // A tile in the wrong slot.
  hood.tiles[ChunkNeighbourhood::Index(1, 0, 0)] = &in;
  absl::StatusOr<std::vector<PocketCell>> out = PocketCandidates(hood);
  ASSERT_FALSE(out.ok());
  EXPECT_NE(out.status().message().find("slot (1, 0, 0)"), std::string::npos) << out.status();
  // A cell outside the tile's chunk.
  const PocketCell outside{LeafKey(16, 0, 0), false, 0.9};
  absl::StatusOr<TileData> with = WithFilledCells(in, {&outside, 1});
  ASSERT_FALSE(with.ok());
  EXPECT_NE(with.status().message().find("cell 16,0,0 is not in chunk 0,0,0"), std::string::npos)
      << with.status();
  // Candidates kept per chunk: a cell in another chunk than its list's, a chunk listed twice.
  std::vector<std::pair<ChunkKey, std::vector<PocketCell>>> lists = {{origin_, {outside}}};
  absl::Status kept = KeepFillablePocketCells(lists, grid_);
  EXPECT_EQ(kept.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(kept.message().find("cell 16,0,0 is not in chunk 0,0,0"), std::string::npos) << kept;
  const PocketCell inside{LeafKey(3, 0, 0), false, 0.9};
  lists = {{origin_, {inside}}, {origin_, {inside}}};
  kept = KeepFillablePocketCells(lists, grid_);
  EXPECT_EQ(kept.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(kept.message().find("given twice"), std::string::npos) << kept;
}

}  // namespace
}  // namespace carvemap
