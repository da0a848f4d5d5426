#include "services/floorplan/model/extrusion.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <chrono>
#include <functional>
#include <random>

#include "services/floorplan/model/floorplan_simplify.h"
#include "services/floorplan/test_plans.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/self_intersections.h"

namespace carvemap {
namespace {

// Σ over rooms of area × height, from the plan's triangles.
double ExpectedVolume(const FloorPlan& plan) {
  double sum = 0;
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    const Eigen::Vector2d a = plan.vertices[tri[1]] - plan.vertices[tri[0]];
    const Eigen::Vector2d b = plan.vertices[tri[2]] - plan.vertices[tri[0]];
    const FloorPlanRoom& room = plan.rooms[plan.triangle_room[t]];
    sum += 0.5 * (a.x() * b.y() - a.y() * b.x()) * (room.ceiling_z - room.floor_z);
  }
  return sum;
}

// Divergence theorem: V = Σ v0 · (v1 × v2) / 6, positive for outward normals.
double SignedVolume(const TriangleMesh& mesh) {
  double sum = 0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[t[2]].cast<double>();
    sum += a.dot(b.cross(c));
  }
  return sum / 6;
}

void ExpectClosedSolid(const FloorPlan& plan, double relative = 1e-9) {
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  const MeshCheck check = CheckMesh(*mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  const double expected = ExpectedVolume(plan);
  ASSERT_GT(expected, 0);
  EXPECT_NEAR(SignedVolume(*mesh), expected, relative * expected);
}

TEST(ExtrusionTest, TwoRoomsWithDifferentHeights) {
  FloorPlan plan = GridPlan(
      4, 2, 1.0, [](int i, int) { return i < 2 ? 0 : 1; }, 2);
  plan.rooms[0].floor_z = 0;
  plan.rooms[0].ceiling_z = 2.5;
  plan.rooms[1].floor_z = 0.25;
  plan.rooms[1].ceiling_z = 3.0;
  ExpectClosedSolid(plan);
  EXPECT_NEAR(ExpectedVolume(plan), 4 * 2.5 + 4 * 2.75, 1e-12);
}

TEST(ExtrusionTest, ThreeRoomsMeetingAtAVertex) {
  // Rooms 0 and 1 below, room 2 above; they meet at (1, 1) with three different ranges, so its
  // column has six heights and every vertical face there is split at the others' heights.
  FloorPlan plan = GridPlan(
      2, 2, 1.0, [](int i, int j) { return j == 1 ? 2 : i; }, 3);
  plan.rooms[0] = {.floor_z = 0, .ceiling_z = 2.5};
  plan.rooms[1] = {.floor_z = 0.5, .ceiling_z = 3.0};
  plan.rooms[2] = {.floor_z = 0.25, .ceiling_z = 2.75};
  ExpectClosedSolid(plan);
  // Disjoint ranges too (room 1 entirely above room 0: a step of a full wall).
  plan.rooms[1] = {.floor_z = 2.875, .ceiling_z = 5.0};
  ExpectClosedSolid(plan);
}

// Each room alone is a closed solid of its own area and height, and the rooms' volumes sum to
// the whole plan's.
TEST(ExtrusionTest, EachRoomAloneIsAClosedSolid) {
  FloorPlan plan = GridPlan(
      2, 2, 1.0, [](int i, int j) { return j == 1 ? 2 : i; }, 3);
  plan.rooms[0] = {.floor_z = 0, .ceiling_z = 2.5};
  plan.rooms[1] = {.floor_z = 0.5, .ceiling_z = 3.0};
  plan.rooms[2] = {.floor_z = 0.25, .ceiling_z = 2.75};
  const double heights[3] = {2.5, 2.5, 2.5};
  const double areas[3] = {1, 1, 2};
  double sum = 0;
  for (int r = 0; r < 3; ++r) {
    absl::StatusOr<TriangleMesh> room = ExtrudeRoom(plan, r);
    ASSERT_TRUE(room.ok()) << room.status();
    EXPECT_TRUE(CheckMesh(*room).watertight()) << r << ": " << CheckMesh(*room).ToString();
    EXPECT_NEAR(SignedVolume(*room), areas[r] * heights[r], 1e-9) << r;
    for (const Eigen::Vector3i& t : room->triangles) {
      for (int k = 0; k < 3; ++k) {
        EXPECT_GE(room->vertices[t[k]].z(), plan.rooms[r].floor_z - 1e-6);
        EXPECT_LE(room->vertices[t[k]].z(), plan.rooms[r].ceiling_z + 1e-6);
      }
    }
    sum += SignedVolume(*room);
  }
  EXPECT_NEAR(sum, ExpectedVolume(plan), 1e-9);
  EXPECT_EQ(ExtrudeRoom(plan, 3).status().code(), absl::StatusCode::kOutOfRange);
}

TEST(ExtrusionTest, RoomWithColumn) {
  FloorPlan plan = GridPlan(
      5, 5, 1.0, [](int i, int j) { return i == 2 && j == 2 ? -1 : 0; }, 1);
  plan.rooms[0] = {.floor_z = 0.5, .ceiling_z = 3.0};
  ExpectClosedSolid(plan);
  EXPECT_NEAR(ExpectedVolume(plan), 24 * 2.5, 1e-12);
}

TEST(ExtrusionTest, PlanTouchingItselfAtAVertex) {
  // One cell of room 0 and one of room 1 meeting only at (1, 1) across the exterior: the
  // vertex's fans get separate columns, 1 mm into each fan, so the solid does not touch itself.
  FloorPlan plan = GridPlan(
      2, 2, 1.0, [](int i, int j) { return i == j ? (i == 0 ? 0 : 1) : -1; }, 2);
  plan.rooms[0] = {.floor_z = 0, .ceiling_z = 2.5};
  plan.rooms[1] = {.floor_z = 0.5, .ceiling_z = 2.0};
  for (int same = 0; same < 2; ++same) {
    if (same) plan.rooms[1] = plan.rooms[0];
    ExpectClosedSolid(plan, /*relative=*/1e-3);  // the moved columns change the volume by ~1e-4
    absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
    ASSERT_TRUE(mesh.ok());
    const SelfIntersections si = CountSelfIntersections(*mesh);
    EXPECT_EQ(si.pairs, 0u) << "same heights: " << same;
    EXPECT_EQ(si.unchecked, 0u);
    // Each fan's column at (1, 1) lies 1 mm from it, toward its own cell's centre.
    int near_pinch = 0;
    for (const Eigen::Vector3f& v : mesh->vertices) {
      const Eigen::Vector2d d(v.x() - 1.0, v.y() - 1.0);
      if (d.norm() > 0.01) continue;
      ++near_pinch;
      EXPECT_NEAR(d.norm(), 1e-3, 1e-6);
      EXPECT_NEAR(std::abs(d.x()), std::abs(d.y()), 1e-6);  // along the diagonal
    }
    EXPECT_EQ(near_pinch, 4);  // two heights in each of the two columns
  }
}

TEST(ExtrusionTest, EqualHeightsShareVerticesWithoutSteps) {
  FloorPlan plan = GridPlan(
      4, 2, 1.0, [](int i, int) { return i < 2 ? 0 : 1; }, 2);
  plan.rooms[0] = {.floor_z = 0, .ceiling_z = 2.5};
  plan.rooms[1] = {.floor_z = 0, .ceiling_z = 2.5};
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
  ASSERT_TRUE(mesh.ok());
  EXPECT_EQ(mesh->vertices.size(), 2u * 15);             // two heights per 2D vertex
  EXPECT_EQ(mesh->triangles.size(), 2u * 16 + 2u * 12);  // floor+ceiling, 12 wall quads
  EXPECT_TRUE(CheckMesh(*mesh).watertight());
}

TEST(ExtrusionTest, SimplifiedNoisyPlanIsWatertight) {
  // Six rooms in blocks with a few columns, ±1 cm noise, simplified, then extruded with a
  // different range per room (monotonic, so no cross-section touches itself at a vertex).
  std::mt19937 rng(301);
  FloorPlan plan = GridPlan(
      60, 40, 0.05,
      [](int i, int j) {
        if ((i / 4 == 5 && j / 4 == 3) || (i / 4 == 11 && j / 4 == 6)) return -1;
        return (i / 20) + 3 * (j / 20);
      },
      6);
  std::uniform_real_distribution<double> noise(-0.01, 0.01);
  for (auto& p : plan.vertices) p += Eigen::Vector2d(noise(rng), noise(rng));
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}).ok());
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    plan.rooms[r].floor_z = 0.1 * r;
    plan.rooms[r].ceiling_z = 2.5 + 0.1 * r;
  }
  // Coordinates are not float-exact here: the volume holds to float rounding.
  ExpectClosedSolid(plan, 1e-5);
}

TEST(ExtrusionTest, AssignRoomHeightsTakesMedians) {
  FloorPlan plan = GridPlan(
      2, 1, 1.0, [](int i, int) { return i; }, 2);
  // Room 0 has vertices 0, 1, 3, 4; room 1 has 1, 2, 4, 5.
  plan.vertex_floor_z = {0.0, 0.1, 0.9, 0.2, 0.3, 1.0};
  plan.vertex_ceiling_z = {2.0, 2.4, 2.9, 9.0, 2.6, 3.1};
  AssignRoomHeights(plan);
  EXPECT_DOUBLE_EQ(plan.rooms[0].floor_z, 0.15);    // {0, .1, .2, .3}
  EXPECT_DOUBLE_EQ(plan.rooms[0].ceiling_z, 2.5);   // {2, 2.4, 2.6, 9}
  EXPECT_DOUBLE_EQ(plan.rooms[1].floor_z, 0.6);     // {.1, .3, .9, 1}
  EXPECT_DOUBLE_EQ(plan.rooms[1].ceiling_z, 2.75);  // {2.4, 2.6, 2.9, 3.1}
}

TEST(ExtrusionTest, RejectsBadHeights) {
  FloorPlan plan = GridPlan(
      1, 1, 1.0, [](int, int) { return 0; }, 2);
  plan.rooms[0] = {.floor_z = 3, .ceiling_z = 3};
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
  EXPECT_EQ(mesh.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(mesh.status().message().find("room 0"), std::string::npos);
}

TEST(ExtrusionTest, SixtyThousandTrianglesIsFast) {
  FloorPlan plan = GridPlan(
      200, 150, 0.0625, [](int i, int j) { return (i / 100) + 2 * (j / 75); }, 4);
  for (size_t r = 0; r < 4; ++r) plan.rooms[r] = {.floor_z = 0.25 * r, .ceiling_z = 2.5 + 0.25 * r};
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(mesh.ok());
  std::cout << "extrude 60k triangles: " << seconds * 1000 << " ms, " << mesh->triangles.size()
            << " mesh triangles\n";
  EXPECT_TRUE(CheckMesh(*mesh).watertight());
  EXPECT_NEAR(SignedVolume(*mesh), ExpectedVolume(plan), 1e-9 * ExpectedVolume(plan));
  EXPECT_LT(seconds, 1.0);
}

}  // namespace
}  // namespace carvemap
