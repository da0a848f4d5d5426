#include "services/levels/level_split.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Vector3d;

PlanarRegion Region(const Vector3d& normal, double z, double area_m2) {
  PlanarRegion r;
  r.normal = normal.normalized();
  r.centroid = Vector3d(1.0, 2.0, z);
  r.area_m2 = area_m2;
  return r;
}
PlanarRegion Floor(double z, double area) { return Region(Vector3d::UnitZ(), z, area); }
PlanarRegion Ceiling(double z, double area) { return Region(-Vector3d::UnitZ(), z, area); }
PlanarRegion Wall(double z, double area) { return Region(Vector3d::UnitX(), z, area); }

// Two stacked levels like the office2 preset: floors at 0 and 3.5 m, rooms with different
// ceilings (the level's ceiling_z is the highest, docs/DESIGN.md §4), walls in between.
std::vector<PlanarRegion> TwoLevels() {
  return {Floor(0.0, 55), Floor(0.0, 30), Ceiling(2.7, 40), Ceiling(3.2, 20), Ceiling(2.5, 15),
          Wall(1.3, 60),  Wall(4.9, 60),  Floor(3.5, 70),   Ceiling(6.6, 25), Ceiling(6.1, 45),
          Ceiling(6.2, 3)};
}

TEST(LevelSplit, TwoStackedLevelsHaveExactHeights) {
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(TwoLevels());
  ASSERT_TRUE(levels.ok()) << levels.status();
  ASSERT_EQ(levels->size(), 2u);
  const Level& a = (*levels)[0];
  const Level& b = (*levels)[1];
  EXPECT_EQ(a.index, 0);
  EXPECT_EQ(b.index, 1);
  EXPECT_NEAR(a.floor_z, 0.0, 1e-12);
  EXPECT_NEAR(a.ceiling_z, 3.2, 1e-12);
  EXPECT_NEAR(a.dominant_ceiling_z, 2.7, 1e-12);  // §2.5's "most populated"
  EXPECT_NEAR(a.floor_weight, 85, 1e-9);
  EXPECT_NEAR(b.floor_z, 3.5, 1e-12);
  EXPECT_NEAR(b.ceiling_z, 6.6, 1e-12);
  // The small 3 m² ceiling at 6.2 is within a peak window of the 6.1 peak: no peak of its
  // own, and too far to move the 6.1 peak's refined height.
  EXPECT_NEAR(b.dominant_ceiling_z, 6.1, 1e-12);
  EXPECT_TRUE(a.ceiling_found && b.ceiling_found);
  // §5.2: split halfway between the lower ceiling and the upper floor.
  EXPECT_NEAR(a.split_z_high, 3.35, 1e-12);
  EXPECT_NEAR(b.split_z_low, 3.35, 1e-12);
  EXPECT_NEAR(a.split_z_low, -0.5, 1e-12);
  EXPECT_NEAR(b.split_z_high, 7.1, 1e-12);
}

// Rooms of one level with ceilings 10 cm apart: the level's ceiling is the highest one,
// exactly (not averaged with its neighbours); the most populated one is reported apart.
TEST(LevelSplit, CeilingIsTheHighestRoomCeiling) {
  std::vector<PlanarRegion> regions = {Floor(0.0, 90), Ceiling(3.0, 40), Ceiling(3.1, 30),
                                       Ceiling(3.2, 10), Ceiling(2.9, 20)};
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(regions);
  ASSERT_TRUE(levels.ok());
  ASSERT_EQ(levels->size(), 1u);
  EXPECT_NEAR((*levels)[0].ceiling_z, 3.2, 1e-12);
  EXPECT_NEAR((*levels)[0].dominant_ceiling_z, 3.0, 1e-12);
}

TEST(LevelSplit, InputOrderDoesNotMatter) {
  std::vector<PlanarRegion> regions = TwoLevels();
  std::reverse(regions.begin(), regions.end());
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(regions);
  ASSERT_TRUE(levels.ok());
  ASSERT_EQ(levels->size(), 2u);
  EXPECT_NEAR((*levels)[1].floor_z, 3.5, 1e-12);
}

// Regions at slightly different heights (a floor plane fitted per room) give the
// area-weighted mean; tilted regions count within 5° only (§5.2).
TEST(LevelSplit, NearbyPlanesAverageAndTiltedPlanesAreDropped) {
  const Vector3d tilt4(std::sin(4 * M_PI / 180), 0, std::cos(4 * M_PI / 180));
  const Vector3d tilt8(std::sin(8 * M_PI / 180), 0, std::cos(8 * M_PI / 180));
  std::vector<PlanarRegion> regions = {Floor(0.01, 30), Floor(0.02, 10), Region(tilt4, 0.0, 20),
                                       Region(tilt8, 1.0, 500), Ceiling(2.8, 50)};
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(regions);
  ASSERT_TRUE(levels.ok());
  ASSERT_EQ(levels->size(), 1u);
  EXPECT_NEAR((*levels)[0].floor_z, (0.01 * 30 + 0.02 * 10) / 60, 1e-12);
  EXPECT_NEAR((*levels)[0].floor_weight, 60, 1e-9);
  EXPECT_NEAR((*levels)[0].ceiling_z, 2.8, 1e-12);
}

// A table top is not a level: a small one is below the area threshold, a big one (and any
// with the threshold off) lies within min_level_height_m of the floor. Its underside is no
// ceiling either.
TEST(LevelSplit, TableTopIsNotALevel) {
  for (const double table_area : {1.5, 4.0}) {
    for (const double min_area : {2.0, 0.0}) {
      LevelSplitOptions o;
      o.min_region_area_m2 = min_area;
      std::vector<PlanarRegion> regions = {Floor(0.0, 60), Floor(0.75, table_area),
                                           Ceiling(0.72, table_area), Ceiling(2.7, 55)};
      absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(regions, o);
      ASSERT_TRUE(levels.ok());
      ASSERT_EQ(levels->size(), 1u) << table_area << " " << min_area;
      EXPECT_NEAR((*levels)[0].floor_z, 0.0, 1e-12);
      EXPECT_NEAR((*levels)[0].ceiling_z, 2.7, 1e-12);
      EXPECT_NEAR((*levels)[0].floor_weight, 60, 1e-9);
    }
  }
}

// The office2 stair: 20 risers of 0.175 m and 19 treads of 0.28 × 1.2 m between levels 3.5 m
// apart, a 2.4 m² landing halfway, the flight's sloped underside (32°) and the landing's
// underside. None of it may create a level or move the levels' heights.
TEST(LevelSplit, StairsDoNotCreateSpuriousLevels) {
  std::vector<PlanarRegion> regions = TwoLevels();
  for (int i = 1; i <= 19; ++i) regions.push_back(Floor(0.175 * i, 0.28 * 1.2));
  regions.push_back(Floor(1.75, 2.4));
  regions.push_back(Ceiling(1.6, 2.4));
  const double a = 32 * M_PI / 180;
  regions.push_back(Region(Vector3d(std::sin(a), 0, -std::cos(a)), 1.5, 8.0));
  for (const double min_area : {2.0, 0.0}) {
    LevelSplitOptions o;
    o.min_region_area_m2 = min_area;
    absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(regions, o);
    ASSERT_TRUE(levels.ok());
    ASSERT_EQ(levels->size(), 2u) << "min area " << min_area;
    EXPECT_NEAR((*levels)[0].floor_z, 0.0, 1e-12);
    EXPECT_NEAR((*levels)[0].ceiling_z, 3.2, 1e-12);
    EXPECT_NEAR((*levels)[1].floor_z, 3.5, 1e-12);
    EXPECT_NEAR((*levels)[1].ceiling_z, 6.6, 1e-12);
  }
}

TEST(LevelSplit, MissingCeilingFallsBack) {
  absl::StatusOr<std::vector<Level>> levels =
      SplitLevelsFromRegions(std::vector<PlanarRegion>{Floor(0, 40), Floor(3.0, 40)});
  ASSERT_TRUE(levels.ok());
  ASSERT_EQ(levels->size(), 2u);
  EXPECT_FALSE((*levels)[0].ceiling_found);
  EXPECT_NEAR((*levels)[0].ceiling_z, 3.0, 1e-12);  // the next floor
  EXPECT_NEAR((*levels)[1].ceiling_z, 3.0 + LevelSplitOptions{}.default_ceiling_height_m, 1e-12);
}

// A floor peak without a ceiling above it, over a level whose ceiling was seen, is carved
// space over that ceiling (drifted rays through the slab), not a level.
TEST(LevelSplit, FloorOverASeenCeilingWithoutItsOwnIsNoLevel) {
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(std::vector<PlanarRegion>{
      Floor(0, 700), Ceiling(2.61, 700), Floor(2.80, 40), Ceiling(2.91, 35)});
  ASSERT_TRUE(levels.ok());
  ASSERT_EQ(levels->size(), 1u);
  EXPECT_NEAR((*levels)[0].floor_z, 0.0, 1e-12);
  EXPECT_NEAR((*levels)[0].ceiling_z, 2.61, 1e-12);
  EXPECT_TRUE((*levels)[0].ceiling_found);
  // With a ceiling of its own (≥ min_ceiling_height_m above it) it is a level.
  levels = SplitLevelsFromRegions(std::vector<PlanarRegion>{
      Floor(0, 700), Ceiling(2.61, 700), Floor(2.80, 40), Ceiling(5.2, 35)});
  ASSERT_TRUE(levels.ok());
  EXPECT_EQ(levels->size(), 2u);
}

TEST(LevelSplit, NoFloorsNoLevels) {
  absl::StatusOr<std::vector<Level>> levels =
      SplitLevelsFromRegions(std::vector<PlanarRegion>{Ceiling(2.5, 40), Wall(1, 30)});
  ASSERT_TRUE(levels.ok());
  EXPECT_TRUE(levels->empty());
  levels = SplitLevelsFromRegions({});
  ASSERT_TRUE(levels.ok());
  EXPECT_TRUE(levels->empty());
}

// §2.5 on point heights: points seen from above on the floors (and the tops of furniture,
// and walls), points seen from below on the ceilings; seeded noise.
struct PointCloud {
  std::vector<double> down, up;  // seen from above / from below
};
PointCloud TwoLevelPoints(uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 0.01);
  std::uniform_real_distribution<double> wall(0.0, 6.4);
  PointCloud pc;
  for (int i = 0; i < 8000; ++i) pc.down.push_back(0.0 + noise(rng));
  for (int i = 0; i < 3000; ++i) pc.down.push_back(3.5 + noise(rng));  // scanned faster
  for (int i = 0; i < 600; ++i) pc.down.push_back(0.75 + noise(rng));  // tables
  for (int i = 0; i < 5000; ++i) pc.up.push_back(2.9 + noise(rng));
  for (int i = 0; i < 2500; ++i) pc.up.push_back(6.4 + noise(rng));
  for (int i = 0; i < 20000; ++i) {
    (i % 2 ? pc.up : pc.down).push_back(wall(rng));  // walls: a flat background
  }
  return pc;
}

TEST(LevelSplit, PointHistogramFallback) {
  const PointCloud pc = TwoLevelPoints(301);
  absl::StatusOr<HeightHistogram> hist = BuildHeightHistogram(pc.down, pc.up, 0.02);
  ASSERT_TRUE(hist.ok()) << hist.status();
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromHistogram(*hist);
  ASSERT_TRUE(levels.ok()) << levels.status();
  ASSERT_EQ(levels->size(), 2u);
  // Within one 2 cm bin: bins are refined from their centres, and the flat wall background
  // adds a small bias.
  EXPECT_NEAR((*levels)[0].floor_z, 0.0, 0.02);
  EXPECT_NEAR((*levels)[0].ceiling_z, 2.9, 0.02);
  EXPECT_NEAR((*levels)[1].floor_z, 3.5, 0.02);
  EXPECT_NEAR((*levels)[1].ceiling_z, 6.4, 0.02);
  EXPECT_NEAR((*levels)[0].split_z_high, 3.2, 0.02);

  // SplitLevels uses the points only when the regions give no level.
  std::vector<PlanarRegion> walls_only = {Wall(1, 50), Ceiling(2.9, 30)};
  absl::StatusOr<LevelSplit> split = SplitLevels(walls_only, &*hist);
  ASSERT_TRUE(split.ok());
  EXPECT_EQ(split->source, "points");
  EXPECT_EQ(split->levels.size(), 2u);
  split = SplitLevels(TwoLevels(), &*hist);
  ASSERT_TRUE(split.ok());
  EXPECT_EQ(split->source, "regions");
  EXPECT_NEAR(split->levels[0].ceiling_z, 3.2, 1e-12);
  split = SplitLevels(walls_only, nullptr);
  ASSERT_TRUE(split.ok());
  EXPECT_EQ(split->source, "none");
  EXPECT_TRUE(split->levels.empty());
}

TEST(LevelSplit, PrebuiltHistogram) {
  HeightHistogram h;
  h.z0_m = -1.0;
  h.bin_m = 0.05;
  h.floor.assign(200, 1.0);
  h.ceiling.assign(200, 1.0);
  h.floor[20] = 500;    // bin [0.00, 0.05): centre 0.025
  h.ceiling[76] = 400;  // [2.80, 2.85)
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromHistogram(h);
  ASSERT_TRUE(levels.ok());
  ASSERT_EQ(levels->size(), 1u);
  EXPECT_NEAR((*levels)[0].floor_z, 0.025, 0.002);
  EXPECT_NEAR((*levels)[0].ceiling_z, 2.825, 0.002);
  h.ceiling.pop_back();
  EXPECT_EQ(SplitLevelsFromHistogram(h).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(LevelSplit, JsonHasTheDesignFields) {
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(TwoLevels());
  ASSERT_TRUE(levels.ok());
  const nlohmann::json j = LevelsToJson(*levels);
  ASSERT_TRUE(j.is_array());
  ASSERT_EQ(j.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(j[i]["index"].get<int>(), int(i));
    EXPECT_DOUBLE_EQ(j[i]["floor_z"].get<double>(), (*levels)[i].floor_z);
    EXPECT_DOUBLE_EQ(j[i]["ceiling_z"].get<double>(), (*levels)[i].ceiling_z);
    EXPECT_DOUBLE_EQ(j[i]["split_z"].get<double>(), (*levels)[i].split_z_low);
    EXPECT_DOUBLE_EQ(j[i]["split_z_high"].get<double>(), (*levels)[i].split_z_high);
  }
  EXPECT_DOUBLE_EQ(j[1]["split_z"].get<double>(), j[0]["split_z_high"].get<double>());
  EXPECT_EQ(LevelsToJson({}).dump(), "[]");
}

TEST(LevelSplit, RejectsBadOptionsAndSamples) {
  LevelSplitOptions o;
  o.max_tilt_deg = 91;
  EXPECT_EQ(SplitLevelsFromRegions(TwoLevels(), o).status().code(),
            absl::StatusCode::kInvalidArgument);
  o = {};
  o.bin_m = 0;
  EXPECT_EQ(SplitLevelsFromRegions(TwoLevels(), o).status().code(),
            absl::StatusCode::kInvalidArgument);
  const std::vector<HeightSample> bad = {{NAN, 1.0}};
  EXPECT_EQ(SplitLevelsFromSamples(bad, {}).status().code(), absl::StatusCode::kInvalidArgument);
  const std::vector<HeightSample> far = {{0, 1}, {1e9, 1}};
  EXPECT_EQ(SplitLevelsFromSamples(far, {}).status().code(), absl::StatusCode::kInvalidArgument);
  const std::vector<double> nan_z = {0.0, NAN};
  EXPECT_EQ(BuildHeightHistogram(nan_z, {}, 0.02).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap
