#include "services/floorplan/model/room_polygons.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>

#include "services/floorplan/test_plans.h"

namespace carvemap {
namespace {

TEST(RoomPolygonsTest, TwoRoomsAndWalls) {
  // 4 × 2 m, split at x = 2 into rooms 0 and 1.
  FloorPlan plan = GridPlan(
      4, 2, 1.0, [](int i, int) { return i < 2 ? 0 : 1; }, 2);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok()) << outline.status();
  ASSERT_EQ(outline->rooms.size(), 2u);
  for (int r = 0; r < 2; ++r) {
    const RoomPolygon& p = outline->rooms[r];
    EXPECT_EQ(p.room, r);
    EXPECT_NEAR(p.area_m2, 4.0, 1e-12);
    EXPECT_NEAR(RingSignedArea(p.outer), 4.0, 1e-12);
    EXPECT_EQ(p.outer.size(), 8u);  // 2×2 cells: 8 boundary vertices, collinear ones kept
    EXPECT_TRUE(p.holes.empty());
  }
  // One wall loop around the whole plan (12 boundary vertices), closed, CCW; no wall at x = 2.
  ASSERT_EQ(outline->walls.size(), 1u);
  const auto& wall = outline->walls[0];
  ASSERT_EQ(wall.size(), 13u);
  EXPECT_EQ(wall.front(), wall.back());
  std::vector<Eigen::Vector2d> open(wall.begin(), wall.end() - 1);
  EXPECT_NEAR(RingSignedArea(open), 8.0, 1e-12);
  for (const auto& p : open) {
    const bool on_border = p.x() == 0 || p.x() == 4 || p.y() == 0 || p.y() == 2;
    EXPECT_TRUE(on_border) << p.transpose();
  }
}

TEST(RoomPolygonsTest, RoomWithColumnHasCwHole) {
  // 5 × 5 cells with the middle cell missing (a column).
  FloorPlan plan = GridPlan(
      5, 5, 1.0, [](int i, int j) { return i == 2 && j == 2 ? -1 : 0; }, 1);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok()) << outline.status();
  ASSERT_EQ(outline->rooms.size(), 1u);
  const RoomPolygon& p = outline->rooms[0];
  ASSERT_EQ(p.holes.size(), 1u);
  EXPECT_NEAR(RingSignedArea(p.holes[0]), -1.0, 1e-12);
  EXPECT_NEAR(p.area_m2, 24.0, 1e-12);
  EXPECT_EQ(outline->walls.size(), 2u);
}

TEST(RoomPolygonsTest, TouchingAtVertexSplitsIntoSimpleRings) {
  // Room 0 is two cells touching only at the vertex (1, 1): two pieces, each a simple ring.
  FloorPlan plan = GridPlan(
      2, 2, 1.0, [](int i, int j) { return (i == 0 && j == 0) || (i == 1 && j == 1) ? 0 : -1; }, 1);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok()) << outline.status();
  ASSERT_EQ(outline->rooms.size(), 2u);
  for (const RoomPolygon& p : outline->rooms) {
    EXPECT_EQ(p.room, 0);
    EXPECT_EQ(p.outer.size(), 4u);
    EXPECT_NEAR(p.area_m2, 1.0, 1e-12);
  }
  EXPECT_EQ(outline->walls.size(), 2u);
  for (const auto& w : outline->walls) EXPECT_EQ(w.size(), 5u);
}

TEST(RoomPolygonsTest, HoleTouchingOuterIsSplitOff) {
  // 3 × 3 cells without the middle one and without the corner cell (2, 2): the missing middle
  // touches the missing corner at vertex (2, 2), so the traced ring visits (2, 2) twice and is
  // cut there into a CCW outer and a CW hole.
  FloorPlan plan = GridPlan(
      3, 3, 1.0, [](int i, int j) { return (i == 1 && j == 1) || (i == 2 && j == 2) ? -1 : 0; }, 1);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok()) << outline.status();
  ASSERT_EQ(outline->rooms.size(), 1u);
  const RoomPolygon& p = outline->rooms[0];
  EXPECT_NEAR(p.area_m2, 7.0, 1e-12);
  ASSERT_EQ(p.holes.size(), 1u);
  EXPECT_NEAR(RingSignedArea(p.holes[0]), -1.0, 1e-12);
  EXPECT_NEAR(RingSignedArea(p.outer), 8.0, 1e-12);
  for (const auto* ring : {&p.outer, &p.holes[0]}) {
    for (size_t i = 0; i < ring->size(); ++i) {
      for (size_t j = i + 1; j < ring->size(); ++j) EXPECT_NE((*ring)[i], (*ring)[j]);
    }
  }
}

TEST(RoomPolygonsTest, NonManifoldEdgeIsFailedPrecondition) {
  FloorPlan plan = GridPlan(
      1, 1, 1.0, [](int, int) { return 0; }, 1);
  plan.triangles.push_back(plan.triangles[0]);  // the same directed edges again
  plan.triangle_room.push_back(0);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_EQ(outline.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(outline.status().message().find("edge (0, 1)"), std::string::npos) << outline.status();
}

TEST(RoomPolygonsTest, BadRoomIndexIsInvalidArgument) {
  FloorPlan plan = GridPlan(
      1, 1, 1.0, [](int, int) { return 0; }, 1);
  plan.triangle_room[1] = 3;
  EXPECT_EQ(TraceFloorPlan(plan).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap
