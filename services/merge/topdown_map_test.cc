#include "services/merge/topdown_map.h"

#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "services/merge/merge_test_util.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

using testing::FreshDir;
using testing::Leaf;

// k = 3: 25 cm leaves, 8 columns per chunk side.
constexpr int kK = 3;
constexpr double kRes = 0.25;

TileData Tile(const ChunkKey& chunk) {
  TileData t;
  t.chunk = chunk;
  t.grid.chunk_depth = kK;
  return t;
}

// A box of interior space 2 m tall (one chunk high) over x ∈ [-1.5, -0.5), y ∈ [0.5, 1.25),
// built from finest leaves with p = 1, plus a neighbouring chunk that is one coarse interior
// leaf, another stacked on it (4 m in total, clamped to white) and an exterior slab.
class TopdownMapTest : public ::testing::Test {
 protected:
  void SetUp() override {
    TileData box = Tile(ChunkKey(-1, 0, 0));  // x ∈ [-2, 0)
    for (int i = 2; i < 6; ++i) {             // x = -2 + i·0.25 ∈ [-1.5, -0.5)
      for (int j = 2; j < 5; ++j) {           // y ∈ [0.5, 1.25)
        for (int l = 0; l < 8; ++l) box.leaves.push_back(Leaf(kK, {i, j, l}, 1.0));
      }
    }
    TileData coarse = Tile(ChunkKey(0, 0, 0));
    coarse.leaves = {Leaf(0, {0, 0, 0}, 1.0)};
    TileData stacked = Tile(ChunkKey(0, 0, 1));
    stacked.leaves = {Leaf(0, {0, 0, 0}, 1.0)};
    TileData slab = Tile(ChunkKey(0, -1, 0));  // y ∈ [-2, 0): a 1 m cube of p = 0.2
    slab.leaves = {Leaf(1, {0, 0, 0}, 0.2)};
    tiles_ = {box, coarse, stacked, slab};
  }
  TopdownMap Build(const TopdownZRange& z_range = {}, bool occupancy = false) {
    std::vector<ChunkKey> chunks;
    for (const TileData& t : tiles_) chunks.push_back(t.chunk);
    TopdownMap map(OctreeGrid{kK}, chunks, z_range, occupancy);
    for (const TileData& t : tiles_) EXPECT_TRUE(map.AddTile(t).ok());
    return map;
  }
  // Pixel of the column holding (x, y) (lower-left origin).
  static std::pair<int, int> RowCol(const TopdownGeometry& g, double x, double y) {
    const int col = int(std::floor((x - g.origin_x_m) / g.resolution_m));
    const int up = int(std::floor((y - g.origin_y_m) / g.resolution_m));
    return {g.height - 1 - up, col};
  }
  std::vector<TileData> tiles_;
};

TEST_F(TopdownMapTest, FootprintAndGeometry) {
  TopdownMap map = Build();
  const TopdownGeometry& g = map.geometry();
  EXPECT_DOUBLE_EQ(g.resolution_m, kRes);
  EXPECT_DOUBLE_EQ(g.origin_x_m, -2.0);
  EXPECT_DOUBLE_EQ(g.origin_y_m, -2.0);
  EXPECT_EQ(g.width, 16);   // chunks x ∈ {-1, 0}
  EXPECT_EQ(g.height, 16);  // chunks y ∈ {-1, 0}
}

TEST_F(TopdownMapTest, BoxOfInteriorGivesItsHeightExactlyOnItsFootprint) {
  TopdownMap map = Build();
  const TopdownGeometry& g = map.geometry();
  int box_pixels = 0;
  for (int row = 0; row < g.height; ++row) {
    for (int col = 0; col < g.width; ++col) {
      const double x = g.origin_x_m + (col + 0.5) * kRes;
      const double y = g.origin_y_m + (g.height - 1 - row + 0.5) * kRes;
      double expected = 0;
      if (x > -1.5 && x < -0.5 && y > 0.5 && y < 1.25) expected = 2.0;  // the box
      if (x > 0 && y > 0) expected = 4.0;                               // two coarse chunks
      if (x > 0 && x < 1 && y > -2 && y < -1) expected = 0.2 * 1.0;     // the exterior slab
      EXPECT_NEAR(map.open_height_m(row, col), expected, 1e-6) << "row " << row << " col " << col;
      box_pixels += expected == 2.0;
    }
  }
  EXPECT_EQ(box_pixels, 4 * 3);
  auto [row, col] = RowCol(g, -1.4, 0.6);
  EXPECT_NEAR(map.open_height_m(row, col), 2.0, 1e-6);
  EXPECT_FLOAT_EQ(map.max_open_height_m(), 4.0f);

  const Image<uint8_t> gray = map.ToGray8(3.0);
  EXPECT_EQ(gray.at(row, col), 170);  // round(255 · 2 / 3)
  auto [r2, c2] = RowCol(g, 0.5, 0.5);
  EXPECT_EQ(gray.at(r2, c2), 255);  // 4 m clamps to ≥ 3 m
  auto [r3, c3] = RowCol(g, 0.5, -1.5);
  EXPECT_EQ(gray.at(r3, c3), 17);  // round(255 · 0.2 / 3)
  auto [r4, c4] = RowCol(g, -1.9, -1.9);
  EXPECT_EQ(gray.at(r4, c4), 0);
}

TEST_F(TopdownMapTest, WritesPngAndSidecar) {
  TopdownMap map = Build();
  const std::string dir = FreshDir();
  ASSERT_TRUE(map.Write(dir + "/topdown.png", dir + "/topdown.json", 3.0, 0).ok());
  absl::StatusOr<Image<uint8_t>> png = ReadPngGray8(dir + "/topdown.png");
  ASSERT_TRUE(png.ok()) << png.status();
  EXPECT_EQ(png->width, 16);
  EXPECT_EQ(png->height, 16);
  EXPECT_EQ(png->pixels, map.ToGray8(3.0).pixels);
  nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/topdown.json"));
  EXPECT_EQ(j["format"], "carvemap-topdown");
  EXPECT_EQ(j["level"], 0);
  EXPECT_DOUBLE_EQ(j["resolution_m"].get<double>(), kRes);
  EXPECT_DOUBLE_EQ(j["origin_m"][0].get<double>(), -2.0);
  EXPECT_DOUBLE_EQ(j["gray_scale"]["gray_255_m"].get<double>(), 3.0);
  EXPECT_EQ(j["image"], "topdown.png");
}

// A level's map (§5.2 split heights): leaves cut by [z_lo, z_hi) add the height of their part
// inside it.
TEST_F(TopdownMapTest, ZRangeIntegratesOnlyTheOverlap) {
  TopdownMap map = Build(TopdownZRange{0.3, 2.6});
  const TopdownGeometry& g = map.geometry();
  for (int row = 0; row < g.height; ++row) {
    for (int col = 0; col < g.width; ++col) {
      const double x = g.origin_x_m + (col + 0.5) * kRes;
      const double y = g.origin_y_m + (g.height - 1 - row + 0.5) * kRes;
      double expected = 0;
      // Box of 25 cm leaves over z ∈ [0, 2): the leaf [0.25, 0.5) adds 0.2, six more 1.5.
      if (x > -1.5 && x < -0.5 && y > 0.5 && y < 1.25) expected = 1.7;
      // 2 m leaves over [0, 2) and [2, 4): 1.7 + 0.6.
      if (x > 0 && y > 0) expected = 2.3;
      // The 1 m leaf over [0, 1) with p = 0.2: 0.7 m of it.
      if (x > 0 && x < 1 && y > -2 && y < -1) expected = 0.2 * 0.7;
      EXPECT_NEAR(map.open_height_m(row, col), expected, 1e-6) << "row " << row << " col " << col;
    }
  }
}

TEST_F(TopdownMapTest, ZRangesThatPartitionTheHeightSumToTheWholeMap) {
  const TopdownMap all = Build();
  const TopdownMap below = Build(TopdownZRange{-std::numeric_limits<double>::infinity(), 1.1});
  const TopdownMap above = Build(TopdownZRange{1.1, std::numeric_limits<double>::infinity()});
  const TopdownMap empty = Build(TopdownZRange{1.0, 1.0});
  const TopdownMap outside = Build(TopdownZRange{-5.0, -1.0});
  const TopdownGeometry& g = all.geometry();
  double total = 0;
  for (int row = 0; row < g.height; ++row) {
    for (int col = 0; col < g.width; ++col) {
      EXPECT_NEAR(below.open_height_m(row, col) + above.open_height_m(row, col),
                  all.open_height_m(row, col), 1e-6);
      EXPECT_EQ(empty.open_height_m(row, col), 0.0f);
      EXPECT_EQ(outside.open_height_m(row, col), 0.0f);
      total += below.open_height_m(row, col);
    }
  }
  EXPECT_GT(total, 0);
  EXPECT_FLOAT_EQ(below.max_open_height_m(), 1.1f);
}

TEST_F(TopdownMapTest, SidecarNamesTheZRange) {
  const std::string dir = FreshDir();
  ASSERT_TRUE(Build(TopdownZRange{0.3, 2.6})
                  .Write(dir + "/a.png", dir + "/a.json", 3.0, 1)
                  .ok());
  nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/a.json"));
  EXPECT_EQ(j["level"], 1);
  ASSERT_TRUE(j["z_range"].is_array());
  EXPECT_DOUBLE_EQ(j["z_range"][0].get<double>(), 0.3);
  EXPECT_DOUBLE_EQ(j["z_range"][1].get<double>(), 2.6);
  ASSERT_TRUE(Build(TopdownZRange{0.3, std::numeric_limits<double>::infinity()})
                  .Write(dir + "/b.png", dir + "/b.json", 3.0, 1)
                  .ok());
  j = nlohmann::json::parse(std::ifstream(dir + "/b.json"));
  EXPECT_TRUE(j["z_range"][1].is_null());
  ASSERT_TRUE(Build().Write(dir + "/c.png", dir + "/c.json", 3.0, 0).ok());
  j = nlohmann::json::parse(std::ifstream(dir + "/c.json"));
  EXPECT_EQ(j["z_range"], "all");
}

// The band 0.1–1.8 m over a floor at 0: the box's and the coarse chunks' columns are open
// through it (free), the exterior slab is 0.9 m of solid in it (occupied), and the rest was
// never observed (unknown). The PGM and YAML are what ROS's map_server reads.
TEST_F(TopdownMapTest, OccupancyOfABandIsFreeOccupiedOrUnknown) {
  TopdownMap map = Build(TopdownZRange{0.1, 1.8}, /*occupancy=*/true);
  const TopdownGeometry& g = map.geometry();
  const Image<uint8_t> occ = map.ToOccupancy(OccupancyThresholds{});
  int counts[3] = {0, 0, 0};
  for (int row = 0; row < g.height; ++row) {
    for (int col = 0; col < g.width; ++col) {
      const double x = g.origin_x_m + (col + 0.5) * kRes;
      const double y = g.origin_y_m + (g.height - 1 - row + 0.5) * kRes;
      uint8_t expected = kUnknownPixel;
      if ((x > -1.5 && x < -0.5 && y > 0.5 && y < 1.25) || (x > 0 && y > 0)) expected = kFreePixel;
      if (x > 0 && x < 1 && y > -2 && y < -1) expected = kOccupiedPixel;
      EXPECT_EQ(occ.at(row, col), expected) << "row " << row << " col " << col;
      counts[expected == kFreePixel ? 0 : expected == kOccupiedPixel ? 1 : 2]++;
    }
  }
  EXPECT_EQ(counts[0], 12 + 64);
  EXPECT_EQ(counts[1], 16);
  // More solid than the slab holds in the band: the slab is unknown (observed, not free).
  auto [r, c] = RowCol(g, 0.5, -1.5);
  EXPECT_EQ(map.ToOccupancy(OccupancyThresholds{1.0, 0.5}).at(r, c), kUnknownPixel);
  // A band mostly above what was observed: the box (0–2 m) covers too little of 1.5–4 m.
  const TopdownMap high = Build(TopdownZRange{1.5, 4.0}, true);
  auto [rb, cb] = RowCol(g, -1.0, 1.0);
  EXPECT_EQ(high.ToOccupancy(OccupancyThresholds{}).at(rb, cb), kUnknownPixel);

  const std::string dir = FreshDir();
  ASSERT_TRUE(map.WriteRosMap(dir + "/occupancy.pgm", dir + "/occupancy.yaml", {}, "a\nb").ok());
  std::ifstream pgm(dir + "/occupancy.pgm", std::ios::binary);
  std::string magic;
  int width = 0, height = 0, maxval = 0;
  pgm >> magic >> width >> height >> maxval;
  pgm.get();  // the one whitespace byte before the raster
  std::vector<uint8_t> raster(size_t(width) * height);
  pgm.read(reinterpret_cast<char*>(raster.data()), std::streamsize(raster.size()));
  EXPECT_TRUE(pgm && pgm.peek() == EOF);
  EXPECT_EQ(magic, "P5");
  EXPECT_EQ(width, 16);
  EXPECT_EQ(height, 16);
  EXPECT_EQ(maxval, 255);
  EXPECT_EQ(raster, occ.pixels);
  std::ifstream yaml_in(dir + "/occupancy.yaml");
  const std::string yaml((std::istreambuf_iterator<char>(yaml_in)), {});
  EXPECT_EQ(yaml,
            "# a\n# b\nimage: occupancy.pgm\nmode: trinary\nresolution: 0.25\n"
            "origin: [-2, -2, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n");
  // A map made without occupancy has none to write.
  EXPECT_EQ(Build().WriteRosMap(dir + "/x.pgm", dir + "/x.yaml", {}, "").code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST(TopdownMap, TileOutsideTheFootprintIsRejected) {
  TopdownMap map(OctreeGrid{kK}, {ChunkKey(0, 0, 0)});
  EXPECT_EQ(map.AddTile(Tile(ChunkKey(1, 0, 0))).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(map.AddTile(Tile(ChunkKey(0, 0, 5))).ok());  // any height is inside
}

}  // namespace
}  // namespace carvemap
