// The Eigencrust floor plan through the whole pipeline (BuildLevelFloorPlan with
// FloorPlanMethod::kEigencrust: §3.2 + §3.3.2's rooms + §3.3.4's extrusion) on synthetic
// wall samples (synthetic_walls_test_util.h).
#include "services/floorplan/eigencrust/eigencrust_floorplan.h"

#include <cmath>
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "services/floorplan/eigencrust/synthetic_walls_test_util.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/mesh/mesh_checks.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;
using testing::Face;
using testing::MakeSamples;
using testing::Scene;

FloorPlanOptions EigencrustOptionsForTest() {
  FloorPlanOptions o;
  o.method = FloorPlanMethod::kEigencrust;
  return o;
}

size_t OutlineVertices(const FloorPlanOutline& outline) {
  size_t n = 0;
  for (const RoomPolygon& r : outline.rooms) n += r.outer.size();
  return n;
}

void Print(const char* name, const LevelFloorPlan& r) {
  const EigencrustFloorPlanReport& e = r.eigencrust;
  std::printf("[%s] %zu samples: inside %zu triangles, |B| %zu; curves: %zu lines %zu circles, "
              "%zu of %zu boundary samples assigned, %zu corners; moved %zu (refused %zu); rooms "
              "%zu (removed %zu); outline vertices %zu; %.3f s label, %.3f s rooms, %.3f s curves\n",
              name, r.wall_samples, e.labeling.inside, e.labeling.boundary_edges, e.curves.lines,
              e.curves.circles, e.curves.assigned, e.curves.boundary_samples, e.curves.corners,
              e.moved_vertices, e.refused_moves, r.plan.rooms.size(), r.labeling.removed_rooms,
              OutlineVertices(r.outline), e.seconds_label, e.seconds_rooms, e.seconds_curves);
}

TEST(EigencrustFloorPlan, MethodNames) {
  EXPECT_EQ(*ParseFloorPlanMethod("eigencrust"), FloorPlanMethod::kEigencrust);
  EXPECT_EQ(*ParseFloorPlanMethod("rooms"), FloorPlanMethod::kRooms);
  EXPECT_EQ(FloorPlanMethodName(FloorPlanMethod::kEigencrust), "eigencrust");
  EXPECT_EQ(ParseFloorPlanMethod("powercrust").status().code(),
            absl::StatusCode::kInvalidArgument);
}

// Two rooms and a door: two rooms of 20 m² each, straight walls (few outline vertices), a
// watertight extrusion.
TEST(EigencrustFloorPlan, TwoRoomsWithADoor) {
  const WallSampleSet samples = MakeSamples(testing::TwoRoomsWithDoor());
  absl::StatusOr<LevelFloorPlan> r = BuildLevelFloorPlan(samples, 0, EigencrustOptionsForTest());
  ASSERT_TRUE(r.ok()) << r.status();
  Print("two rooms", *r);
  ASSERT_EQ(r->plan.rooms.size(), 2u);
  for (const FloorPlanRoom& room : r->plan.rooms) EXPECT_NEAR(room.area_m2, 20.0, 0.5);
  EXPECT_TRUE(CheckMesh(r->extruded).watertight());
  // Each room is a rectangle with a doorway; the samples' ~700 vertices are gone.
  EXPECT_LT(OutlineVertices(r->outline), 40u);

  // The walls stay where they are: every outline vertex within 1 cm of a true wall line.
  const std::vector<double> xs = {0, 5, 5.15, 10.15}, ys = {0, 1.5, 2.4, 4};
  for (const RoomPolygon& room : r->outline.rooms) {
    for (const Vector2d& p : room.outer) {
      double best = 1e9;
      for (double x : xs) best = std::min(best, std::abs(p.x() - x));
      for (double y : ys) best = std::min(best, std::abs(p.y() - y));
      EXPECT_LT(best, 0.01) << p.transpose();
    }
  }
  // The curve fitting is what straightened them: without it the outline keeps its samples.
  FloorPlanOptions no_fit = EigencrustOptionsForTest();
  no_fit.eigencrust.fit_curves = false;
  absl::StatusOr<LevelFloorPlan> raw = BuildLevelFloorPlan(samples, 0, no_fit);
  ASSERT_TRUE(raw.ok()) << raw.status();
  EXPECT_GT(OutlineVertices(raw->outline), 200u);
}

// A storage room off room B is seen through its open door but never entered: the Eigencrust
// interior holds it, §3.3.2 removes it.
TEST(EigencrustFloorPlan, UnenteredRoomIsRemoved) {
  Scene scene = testing::TwoRoomsWithDoor();
  // Room B's north face gets a 0.9 m door (x ∈ [8, 8.9]) to a 3 × 2 m storage room
  // [7, 10] × [4.15, 6.15] behind a 0.15 m wall.
  std::vector<Face>& f = scene.faces;
  std::erase_if(f, [](const Face& face) { return face.a == Vector2d(10.15, 4); });
  f.push_back({{10.15, 4}, {8.9, 4}});
  f.push_back({{8.0, 4}, {5.15, 4}});
  f.push_back({{8.9, 4}, {8.9, 4.15}});
  f.push_back({{8.0, 4.15}, {8.0, 4}});
  f.push_back({{8.0, 4.15}, {7, 4.15}});
  f.push_back({{7, 4.15}, {7, 6.15}});
  f.push_back({{7, 6.15}, {10, 6.15}});
  f.push_back({{10, 6.15}, {10, 4.15}});
  f.push_back({{10, 4.15}, {8.9, 4.15}});
  scene.path = {{1, 1}, {4, 1}, {4, 2}, {6, 2}, {9.5, 2}, {9.5, 3.2}, {6, 3.2}};
  const WallSampleSet samples = MakeSamples(scene);
  absl::StatusOr<LevelFloorPlan> r = BuildLevelFloorPlan(samples, 0, EigencrustOptionsForTest());
  ASSERT_TRUE(r.ok()) << r.status();
  Print("unentered", *r);
  EXPECT_EQ(r->plan.rooms.size(), 2u);
  EXPECT_GE(r->labeling.removed_rooms, 1u);
  EXPECT_NEAR(r->labeling.removed_area_m2, 6.0, 1.0);
  FloorPlanOptions keep = EigencrustOptionsForTest();
  keep.rooms.remove_unentered_rooms = false;
  absl::StatusOr<LevelFloorPlan> kept = BuildLevelFloorPlan(samples, 0, keep);
  ASSERT_TRUE(kept.ok()) << kept.status();
  EXPECT_EQ(kept->plan.rooms.size(), 3u);
}

// A round room (r = 3 m) joined to a square one: the round wall is fitted by a circle, so its
// outline vertices lie on the true circle.
TEST(EigencrustFloorPlan, RoundWallIsACircle) {
  Scene scene;
  const int n = 72;
  // The circle (centre 0, r = 3) open on the east between ±10°, a 2.2 m × 1 m corridor east.
  const double open = 10 * M_PI / 180;
  for (int k = 0; k < n; ++k) {
    const double a0 = open + (2 * M_PI - 2 * open) * k / n;
    const double a1 = open + (2 * M_PI - 2 * open) * (k + 1) / n;
    scene.faces.push_back({{3 * std::cos(a0), 3 * std::sin(a0)}, {3 * std::cos(a1), 3 * std::sin(a1)}});
  }
  const double yo = 3 * std::sin(open), xo = 3 * std::cos(open);
  scene.faces.push_back({{xo, -yo}, {6, -yo}});
  scene.faces.push_back({{6, -yo}, {6, yo}});
  scene.faces.push_back({{6, yo}, {xo, yo}});
  scene.path = {{-1.5, 0}, {1.5, 1}, {0, -1.5}, {5.5, 0}};
  const WallSampleSet samples = MakeSamples(scene);
  absl::StatusOr<LevelFloorPlan> r = BuildLevelFloorPlan(samples, 0, EigencrustOptionsForTest());
  ASSERT_TRUE(r.ok()) << r.status();
  Print("round", *r);
  EXPECT_GE(r->eigencrust.curves.circles, 1u);
  size_t on_circle = 0, round = 0;
  for (const RoomPolygon& room : r->outline.rooms) {
    for (const Vector2d& p : room.outer) {
      if (p.x() > xo - 0.05) continue;  // the corridor
      ++round;
      on_circle += std::abs(p.norm() - 3) < 0.005 ? 1 : 0;
    }
  }
  EXPECT_GT(round, 50u);
  EXPECT_GE(on_circle, round * 9 / 10);
  EXPECT_TRUE(CheckMesh(r->extruded).watertight());
}

}  // namespace
}  // namespace carvemap
