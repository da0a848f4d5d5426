#include "services/floorplan/export/floorplan_dxf.h"

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <dxflib/dl_creationadapter.h>
#include <dxflib/dl_dxf.h>
#include <gtest/gtest.h>

#include "services/floorplan/model/room_polygons.h"
#include "services/floorplan/test_plans.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Eigen::Vector2d;

FloorPlan RoomInRoom() { return RoomInRoomPlan(); }
FloorPlan TwoRooms() { return TwoRoomsPlan(); }

TEST(RoomBorders, AnOpenBorderRunsFromWallToWall) {
  const auto borders = RoomBorders(TwoRooms());
  ASSERT_EQ(borders.size(), 1u);
  EXPECT_EQ(borders[0], (std::vector<Vector2d>{{1, 0}, {1, 1}}));
}

TEST(RoomBorders, ARoomInsideAnotherHasAClosedBorder) {
  const auto borders = RoomBorders(RoomInRoom());
  ASSERT_EQ(borders.size(), 1u);
  EXPECT_EQ(borders[0], (std::vector<Vector2d>{{1, 1}, {2, 1}, {2, 2}, {1, 2}, {1, 1}}));
}

TEST(RoomBorders, OneRoomHasNone) {
  FloorPlan plan = TwoRooms();
  plan.triangle_room = {0, 0, 0, 0};
  plan.rooms.resize(1);
  EXPECT_TRUE(RoomBorders(plan).empty());
}

// What dxflib's reader sees of a file: entities per layer, the vertices of each polyline, the
// texts and the header's units.
struct Seen : DL_CreationAdapter {
  std::map<std::string, int> polylines, closed;
  std::map<std::string, std::vector<std::vector<Vector2d>>> points;
  std::vector<std::string> texts;
  int units = -1;
  void addPolyline(const DL_PolylineData& d) override {
    const std::string layer = attributes.getLayer();
    ++polylines[layer];
    closed[layer] += (d.flags & 1) != 0;
    points[layer].emplace_back();
  }
  void addVertex(const DL_VertexData& v) override {
    points[attributes.getLayer()].back().emplace_back(v.x, v.y);
  }
  void addText(const DL_TextData& t) override {
    EXPECT_EQ(attributes.getLayer(), "LABELS");
    texts.push_back(t.text);
  }
  void setVariableInt(const std::string& name, int value, int) override {
    if (name == "$INSUNITS") units = value;
  }
};

TEST(FloorPlanDxf, LayersHoldTheRoomsWallsBordersAndLabels) {
  const FloorPlan plan = RoomInRoom();
  const absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok()) << outline.status();
  const std::string dir = ::testing::TempDir() + "/floorplan_dxf";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string path = dir + "/floorplan.dxf";
  ASSERT_TRUE(WriteFloorPlanDxf(path, plan, *outline).ok());
  EXPECT_FALSE(fs::exists(PartialPath(path)));

  Seen seen;
  DL_Dxf reader;
  ASSERT_TRUE(reader.in(path, &seen));
  EXPECT_EQ(seen.units, 6);  // metres
  // Room 0 is a ring with a hole, room 1 a square: three closed rings.
  EXPECT_EQ(seen.polylines["ROOMS"], 3);
  EXPECT_EQ(seen.closed["ROOMS"], 3);
  double area = 0;
  for (const auto& ring : seen.points["ROOMS"]) area += RingSignedArea(ring);
  EXPECT_NEAR(area, 9.0, 1e-9);  // 8 (ring, less its hole) + 1
  // The walls: the outer boundary only, closed, its first point not repeated.
  ASSERT_EQ(seen.polylines["WALLS"], 1);
  EXPECT_EQ(seen.closed["WALLS"], 1);
  EXPECT_EQ(seen.points["WALLS"][0].size(), 4u);
  EXPECT_NEAR(RingSignedArea(seen.points["WALLS"][0]), 9.0, 1e-9);
  ASSERT_EQ(seen.polylines["DOORS"], 1);
  EXPECT_EQ(seen.closed["DOORS"], 1);
  EXPECT_EQ(seen.points["DOORS"][0].size(), 4u);
  EXPECT_EQ(seen.texts, (std::vector<std::string>{"room 0, 8.0 m2", "room 1, 1.0 m2"}));
}

TEST(FloorPlanDxf, AFolderThatCannotBeWrittenIsUnavailableAndLeavesNothing) {
  const FloorPlan plan = TwoRooms();
  const absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  const std::string path = ::testing::TempDir() + "/no_such_folder/floorplan.dxf";
  const absl::Status s = WriteFloorPlanDxf(path, plan, *outline);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << s;
  EXPECT_NE(s.message().find(path), std::string::npos) << s;
  EXPECT_FALSE(fs::exists(PartialPath(path)));
}

}  // namespace
}  // namespace carvemap
