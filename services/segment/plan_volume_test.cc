#include "services/segment/plan_volume.h"

#include <cmath>

#include <gtest/gtest.h>

#include "services/segment/segment_test_util.h"

namespace carvemap {
namespace {

using testing::RectanglePlan;
using testing::TestRoom;

constexpr double kRes = 0.0625;

TEST(PlanVolume, ColumnsKnowTheirRoomHeightsAndDistanceToTheWalls) {
  // Two rooms side by side: [0,4]×[0,3] (floor 0, ceiling 2.5) and [4,6]×[0,3] (ceiling 3).
  const FloorPlan plan = RectanglePlan({{{0, 0}, {4, 3}, 0.0, 2.5}, {{4, 0}, {6, 3}, 0.0, 3.0}});
  const PlanLevelInput in{&plan, 0, -0.5, 3.5};
  absl::StatusOr<PlanVolume> vol = RasterizePlanVolume({&in, 1}, kRes, 1.0);
  ASSERT_TRUE(vol.ok()) << vol.status();
  ASSERT_EQ(vol->levels.size(), 1u);
  // Grid aligned: the origin is a multiple of the resolution.
  const Eigen::Vector2d o = vol->levels[0].origin / kRes;
  EXPECT_NEAR(o.x(), std::round(o.x()), 1e-9);

  PlanColumn c = LookupPlan(*vol, {2.03, 1.53, 1.0});
  EXPECT_EQ(c.level, 0);
  EXPECT_EQ(c.room, 0);
  EXPECT_DOUBLE_EQ(c.floor_z, 0.0);
  EXPECT_DOUBLE_EQ(c.ceiling_z, 2.5);
  // Nearest wall: y = 0 or y = 3, 1.5 m away (the border between the rooms is not a wall).
  EXPECT_NEAR(c.signed_distance_m, 1.5, kRes);

  c = LookupPlan(*vol, {5.03, 1.53, 1.0});
  EXPECT_EQ(c.room, 1);
  EXPECT_DOUBLE_EQ(c.ceiling_z, 3.0);
  EXPECT_NEAR(c.signed_distance_m, 0.97, kRes);

  c = LookupPlan(*vol, {3.97, 1.53, 1.0});  // next to the border between the rooms
  EXPECT_EQ(c.room, 0);
  EXPECT_GT(c.signed_distance_m, 1.4);

  c = LookupPlan(*vol, {-0.47, 1.53, 1.0});  // outside, 0.47 m from the west wall
  EXPECT_EQ(c.room, -1);
  EXPECT_NEAR(c.signed_distance_m, -0.47, kRes);

  c = LookupPlan(*vol, {-0.7, -0.7, 1.0});  // outside a corner: Euclidean, not city-block
  EXPECT_NEAR(c.signed_distance_m, -0.7 * std::sqrt(2.0), kRes);

  c = LookupPlan(*vol, {20, 20, 1.0});  // beyond the raster
  EXPECT_EQ(c.level, 0);
  EXPECT_EQ(c.room, -1);
  EXPECT_TRUE(std::isinf(c.signed_distance_m) && c.signed_distance_m < 0);

  c = LookupPlan(*vol, {2, 1.5, 5.0});  // above the level
  EXPECT_EQ(c.level, -1);
  EXPECT_EQ(c.room, -1);
}

TEST(PlanVolume, LevelsAreSeparateInZ) {
  const FloorPlan low = RectanglePlan({{{0, 0}, {4, 4}, 0.0, 2.5}});
  const FloorPlan high = RectanglePlan({{{10, 0}, {14, 4}, 3.0, 5.5}});
  const PlanLevelInput in[] = {{&low, 0, -0.5, 2.75}, {&high, 1, 2.75, 6.0}};
  absl::StatusOr<PlanVolume> vol = RasterizePlanVolume(in, kRes, 0.5);
  ASSERT_TRUE(vol.ok()) << vol.status();
  EXPECT_EQ(LookupPlan(*vol, {2, 2, 1}).room, 0);
  EXPECT_EQ(LookupPlan(*vol, {2, 2, 4}).room, -1);  // level 1 has no room there
  EXPECT_EQ(LookupPlan(*vol, {2, 2, 4}).level, 1);
  EXPECT_EQ(LookupPlan(*vol, {12, 2, 4}).room, 0);
  EXPECT_DOUBLE_EQ(LookupPlan(*vol, {12, 2, 4}).floor_z, 3.0);
}

TEST(PlanVolume, RejectsBadInput) {
  const FloorPlan plan = RectanglePlan({{{0, 0}, {4, 4}}});
  const PlanLevelInput good{&plan, 0, 0, 3};
  EXPECT_TRUE(absl::IsInvalidArgument(RasterizePlanVolume({&good, 1}, 0, 1).status()));
  EXPECT_TRUE(absl::IsInvalidArgument(RasterizePlanVolume({&good, 1}, kRes, -1).status()));
  const PlanLevelInput null_plan{nullptr, 0, 0, 3};
  EXPECT_TRUE(absl::IsInvalidArgument(RasterizePlanVolume({&null_plan, 1}, kRes, 1).status()));
  const PlanLevelInput flat{&plan, 0, 3, 3};
  EXPECT_TRUE(absl::IsInvalidArgument(RasterizePlanVolume({&flat, 1}, kRes, 1).status()));
  const PlanLevelInput overlapping[] = {{&plan, 0, 0, 3}, {&plan, 1, 2, 5}};
  absl::StatusOr<PlanVolume> v = RasterizePlanVolume(overlapping, kRes, 1);
  ASSERT_TRUE(absl::IsInvalidArgument(v.status()));
  EXPECT_NE(v.status().message().find("overlap"), std::string::npos);
  FloorPlan broken = plan;
  broken.triangles[0][1] = 99;
  const PlanLevelInput bad_index{&broken, 0, 0, 3};
  EXPECT_TRUE(absl::IsInvalidArgument(RasterizePlanVolume({&bad_index, 1}, kRes, 1).status()));
}

TEST(PlanVolume, EmptyPlanIsAllOutside) {
  const FloorPlan empty;
  const PlanLevelInput in{&empty, 0, 0, 3};
  absl::StatusOr<PlanVolume> vol = RasterizePlanVolume({&in, 1}, kRes, 1);
  ASSERT_TRUE(vol.ok());
  const PlanColumn c = LookupPlan(*vol, {0, 0, 1});
  EXPECT_EQ(c.level, 0);
  EXPECT_EQ(c.room, -1);
}

}  // namespace
}  // namespace carvemap
