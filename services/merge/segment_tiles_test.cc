// SegmentTiles: the tiles it writes do not depend on how many threads segment the chunks.
#include "services/merge/segment_tiles.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

#include "services/merge/merge_test_util.h"
#include "services/segment/plan_volume.h"
#include "services/segment/segment_test_util.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using carvemap::testing::FreshDir;
using carvemap::testing::RandomTile;
using carvemap::testing::RectanglePlan;

std::string Bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(SegmentTiles, ThreadsWriteTheSameTilesAsOne) {
  const std::string root = FreshDir();
  std::mt19937 rng(7);
  constexpr int kDepth = 3;  // 25 cm leaves, 8 per chunk side
  fs::create_directories(root + "/tiles");
  for (int x = 0; x < 3; ++x)
    for (int y = 0; y < 3; ++y)
      for (int z = 0; z < 2; ++z) {
        TileData tile = RandomTile(rng, kDepth, ChunkKey(x, y, z));
        absl::StatusOr<std::string> written = WriteTile(root + "/tiles", tile);
        ASSERT_TRUE(written.ok()) << written.status();
      }
  const FloorPlan plan = RectanglePlan({{{0.5, 0.5}, {5.5, 5.5}, 0.0, 3.0}});
  const PlanLevelInput level{&plan, 0, -1.0, 5.0};
  absl::StatusOr<PlanVolume> volume = RasterizePlanVolume({&level, 1}, 0.25, 0.5);
  ASSERT_TRUE(volume.ok()) << volume.status();

  auto segment = [&](int threads, const std::string& out) {
    absl::StatusOr<std::unique_ptr<TileSet>> tiles =
        TileSet::Open(root + "/tiles", 0, /*cache_budget_bytes=*/1 << 20);
    EXPECT_TRUE(tiles.ok()) << tiles.status();
    absl::StatusOr<SegmentTilesResult> r = SegmentTiles(
        **tiles, *volume, SegmentOptions{}, out + "/building", out + "/objects", nullptr, threads);
    EXPECT_TRUE(r.ok()) << r.status();
    return *r;
  };
  const SegmentTilesResult one = segment(1, root + "/t1");
  ASSERT_EQ(one.chunks, 18u);
  ASSERT_GT(one.object_cells, 0u);  // the comparison below must cover object tiles too
  for (int threads : {2, 3}) {
    const std::string out = root + "/t" + std::to_string(threads);
    const SegmentTilesResult many = segment(threads, out);
    EXPECT_EQ(many.object_chunks, one.object_chunks) << threads;
    EXPECT_EQ(many.object_cells, one.object_cells) << threads;
    EXPECT_EQ(many.unobserved_object_cells, one.unobserved_object_cells) << threads;
    EXPECT_EQ(many.trimmed_cells, one.trimmed_cells) << threads;
    for (const char* kind : {"building", "objects"}) {
      size_t files = 0;
      for (const fs::directory_entry& e : fs::directory_iterator(root + "/t1/" + kind)) {
        ++files;
        EXPECT_EQ(Bytes(fs::path(out) / kind / e.path().filename()), Bytes(e.path()))
            << kind << " " << e.path().filename() << " with " << threads << " threads";
      }
      EXPECT_EQ(files, size_t(std::distance(fs::directory_iterator(fs::path(out) / kind),
                                            fs::directory_iterator())))
          << kind;
      EXPECT_GT(files, 0u) << kind;
    }
  }
}

}  // namespace
}  // namespace carvemap
