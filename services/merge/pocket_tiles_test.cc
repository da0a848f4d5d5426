// FillPocketTiles: every chunk lands in the output folder, filled where it had a pocket and as
// the same file otherwise, the same bytes whatever the number of threads.
#include "services/merge/pocket_tiles.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "services/merge/merge_test_util.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using carvemap::testing::FreshDir;

std::string Bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Chunk `chunk` at 25 cm (8 cells a side): free air over a solid floor (z = 0), with, when
// `pocket`, the global cells x 2–13, y 2–5, z = 3 unobserved (a pocket across chunks x 0 and 1).
TileData Chunk(const ChunkKey& chunk, bool pocket) {
  TileData t;
  t.chunk = chunk;
  t.grid.chunk_depth = 3;
  for (int z = 0; z < 8; ++z)
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) {
        const int gx = chunk.x() * 8 + x, gy = chunk.y() * 8 + y, gz = chunk.z() * 8 + z;
        if (pocket && gz == 3 && gx >= 2 && gx <= 13 && gy >= 2 && gy <= 5) continue;
        LeafStats s;
        s.Add(gz == 0 ? 0.1 : 0.9, 1.0);
        t.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, z), 3}, s});
      }
  return t;
}

TEST(FillPocketTiles, FillsThePocketsAndLinksTheRest) {
  const std::string root = FreshDir();
  fs::create_directories(root + "/tiles");
  // Two chunks side by side with the pocket layer, one above them without.
  for (const auto& [key, pocket] :
       {std::pair{ChunkKey(0, 0, 0), true}, std::pair{ChunkKey(1, 0, 0), true},
        std::pair{ChunkKey(0, 0, 1), false}}) {
    ASSERT_TRUE(WriteTile(root + "/tiles", Chunk(key, pocket)).ok());
  }
  auto fill = [&](int threads, const std::string& out) {
    absl::StatusOr<std::unique_ptr<TileSet>> tiles = TileSet::Open(root + "/tiles", 0, 1 << 20);
    EXPECT_TRUE(tiles.ok()) << tiles.status();
    absl::StatusOr<PocketTilesResult> r =
        FillPocketTiles(**tiles, root + "/tiles", out, PocketFillOptions{}, nullptr, threads);
    EXPECT_TRUE(r.ok()) << r.status();
    return *r;
  };
  const PocketTilesResult one = fill(1, root + "/f1");
  EXPECT_EQ(one.chunks, 3u);
  EXPECT_EQ(one.filled_tiles, 2u);
  EXPECT_EQ(one.filled_cells, 12u * 4);
  for (const ChunkKey& key : {ChunkKey(0, 0, 0), ChunkKey(1, 0, 0)}) {
    absl::StatusOr<TileData> t = ReadTile(root + "/f1/" + TileFileName(key));
    ASSERT_TRUE(t.ok()) << t.status();
    EXPECT_EQ(t->leaves.size(), 8u * 8 * 8);  // the layer now has its leaves
  }
  // The chunk without a pocket is its own file, unchanged.
  const std::string above = TileFileName(ChunkKey(0, 0, 1));
  EXPECT_EQ(Bytes(root + "/f1/" + above), Bytes(root + "/tiles/" + above));
  const PocketTilesResult two = fill(2, root + "/f2");
  EXPECT_EQ(two.filled_cells, one.filled_cells);
  for (const ChunkKey& key : {ChunkKey(0, 0, 0), ChunkKey(1, 0, 0), ChunkKey(0, 0, 1)}) {
    EXPECT_EQ(Bytes(root + "/f2/" + TileFileName(key)), Bytes(root + "/f1/" + TileFileName(key)));
  }
}

TEST(FillPocketTiles, AnOutputThatCannotBeMadeIsNamed) {
  const std::string root = FreshDir();
  fs::create_directories(root + "/tiles");
  ASSERT_TRUE(WriteTile(root + "/tiles", Chunk(ChunkKey(0, 0, 0), true)).ok());
  std::ofstream(root + "/file") << "x";
  absl::StatusOr<std::unique_ptr<TileSet>> tiles = TileSet::Open(root + "/tiles", 0, 1 << 20);
  ASSERT_TRUE(tiles.ok()) << tiles.status();
  absl::StatusOr<PocketTilesResult> r = FillPocketTiles(
      **tiles, root + "/tiles", root + "/file/out", PocketFillOptions{}, nullptr, 1);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(r.status().message().find(root + "/file/out"), std::string::npos) << r.status();
}

}  // namespace
}  // namespace carvemap
