// Tests of LabelRooms (§3.3.1–§3.3.2) on synthetic wall samples made here: walls are 2D
// segments sampled every d_s = 5 cm with ±2 mm noise, the path is a polyline sampled every
// 0.25 m, and a pose sees a sample when the segment between them crosses no other wall (exact
// segment tests, 30 m range). Independent of grid_visibility.cc.
#include "services/floorplan/rooms/room_labeling.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "services/floorplan/floorplan_pipeline.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

constexpr double kSpacing = 0.05;

struct Wall {
  Vector2d a, b;
};

// Proper crossing of segments (p, q) and (a, b) (touching does not block).
bool Crosses(const Vector2d& p, const Vector2d& q, const Vector2d& a, const Vector2d& b) {
  auto cross = [](const Vector2d& u, const Vector2d& v, const Vector2d& w) {
    return (v - u).x() * (w - u).y() - (v - u).y() * (w - u).x();
  };
  const double d1 = cross(p, q, a), d2 = cross(p, q, b), d3 = cross(a, b, p), d4 = cross(a, b, q);
  return ((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0));
}

std::vector<Vector2d> SamplePath(const std::vector<Vector2d>& polyline, double step = 0.25) {
  std::vector<Vector2d> out{polyline.front()};
  double carry = 0;
  for (size_t i = 1; i < polyline.size(); ++i) {
    const Vector2d d = polyline[i] - polyline[i - 1];
    const double len = d.norm();
    double t = step - carry;
    for (; t <= len; t += step) out.push_back(polyline[i - 1] + d * (t / len));
    carry = len - (t - step);
  }
  return out;
}

struct Scene {
  std::vector<Wall> walls;
  std::vector<std::vector<Vector2d>> paths;  // pieces; each after the first is a path break
  double noise_m = 0.002;
  uint32_t seed = 7;
};

// The wall samples (sample k of wall w at (k + ½)·len/n, n = ⌈len / d_s⌉) with their
// visibility; wall_of[i] is the wall of sample i.
WallSampleSet MakeSamples(const Scene& scene, std::vector<int>* wall_of = nullptr) {
  std::mt19937 rng(scene.seed);
  std::uniform_real_distribution<double> noise(-scene.noise_m, scene.noise_m);
  WallSampleSet set;
  set.spacing_m = kSpacing;
  std::vector<int> owner;
  for (size_t w = 0; w < scene.walls.size(); ++w) {
    const Wall& wall = scene.walls[w];
    const double len = (wall.b - wall.a).norm();
    const int n = static_cast<int>(std::ceil(len / kSpacing - 1e-9));
    for (int k = 0; k < n; ++k) {
      WallSample s;
      s.position = wall.a + (wall.b - wall.a) * ((k + 0.5) / n) + Vector2d(noise(rng), noise(rng));
      s.floor_z = 0;
      s.ceiling_z = 2.5;
      set.samples.push_back(s);
      owner.push_back(static_cast<int>(w));
    }
  }
  for (const auto& piece : scene.paths) {
    if (!set.poses.empty()) set.path_breaks.push_back(static_cast<uint32_t>(set.poses.size()));
    for (const Vector2d& p : SamplePath(piece)) set.poses.push_back(p);
  }
  for (size_t i = 0; i < set.samples.size(); ++i) {
    for (size_t j = 0; j < set.poses.size(); ++j) {
      const Vector2d& p = set.samples[i].position;
      const Vector2d& s = set.poses[j];
      if ((p - s).norm() > 30.0) continue;
      bool blocked = false;
      for (size_t w = 0; w < scene.walls.size() && !blocked; ++w) {
        if (static_cast<int>(w) != owner[i]) {
          blocked = Crosses(s, p, scene.walls[w].a, scene.walls[w].b);
        }
      }
      if (!blocked) set.samples[i].poses.push_back(static_cast<uint32_t>(j));
    }
  }
  if (wall_of != nullptr) *wall_of = owner;
  return set;
}

void AddRect(std::vector<Wall>& walls, double x0, double y0, double x1, double y1) {
  walls.push_back({{x0, y0}, {x1, y0}});
  walls.push_back({{x1, y0}, {x1, y1}});
  walls.push_back({{x1, y1}, {x0, y1}});
  walls.push_back({{x0, y1}, {x0, y0}});
}

double TriangleArea(const FloorPlan& plan, size_t t) {
  const Vector2d& a = plan.vertices[plan.triangles[t][0]];
  const Vector2d& b = plan.vertices[plan.triangles[t][1]];
  const Vector2d& c = plan.vertices[plan.triangles[t][2]];
  return 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
}

Vector2d Centroid(const FloorPlan& plan, size_t t) {
  return (plan.vertices[plan.triangles[t][0]] + plan.vertices[plan.triangles[t][1]] +
          plan.vertices[plan.triangles[t][2]]) /
         3;
}

// Σ of the lengths of edges shared by a triangle of room a and one of room b, and their
// midpoints.
double BorderLength(const FloorPlan& plan, int a, int b, std::vector<Vector2d>* mids = nullptr) {
  std::map<std::pair<uint32_t, uint32_t>, int> edge_room;
  double len = 0;
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    for (int i = 0; i < 3; ++i) {
      uint32_t u = plan.triangles[t][i], v = plan.triangles[t][(i + 1) % 3];
      if (u > v) std::swap(u, v);
      const auto [it, inserted] = edge_room.emplace(std::make_pair(u, v), plan.triangle_room[t]);
      if (inserted) continue;
      const int r1 = it->second, r2 = plan.triangle_room[t];
      if ((r1 == a && r2 == b) || (r1 == b && r2 == a)) {
        len += (plan.vertices[u] - plan.vertices[v]).norm();
        if (mids) mids->push_back(0.5 * (plan.vertices[u] + plan.vertices[v]));
      }
    }
  }
  return len;
}

// Checks the invariants every plan must keep.
void CheckPlan(const FloorPlan& plan) {

  ASSERT_EQ(plan.triangle_room.size(), plan.triangles.size());
  ASSERT_EQ(plan.vertex_floor_z.size(), plan.vertices.size());
  std::vector<double> area(plan.rooms.size(), 0);
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    EXPECT_GT(TriangleArea(plan, t), 0) << "triangle " << t << " not CCW";
    ASSERT_GE(plan.triangle_room[t], 0);
    ASSERT_LT(plan.triangle_room[t], static_cast<int>(plan.rooms.size()));
    area[plan.triangle_room[t]] += TriangleArea(plan, t);
  }
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    const FloorPlanRoom& room = plan.rooms[r];
    ASSERT_GE(room.seed_triangle, 0);
    EXPECT_EQ(plan.triangle_room[room.seed_triangle], static_cast<int>(r));
    EXPECT_NEAR(room.area_m2, area[r], 1e-9);
    if (r > 0) {
      EXPECT_GE(plan.rooms[r - 1].area_m2, room.area_m2);  // largest first
    }
  }
}

TEST(RoomLabelingTest, OneRectangularRoom) {
  Scene scene;
  AddRect(scene.walls, 0, 0, 6, 4);
  scene.paths = {{{1, 1}, {5, 1}, {5, 3}, {1, 3}, {1, 1.5}}};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 1u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 24.0, 0.02 * 24.0);
  // Carving stays inside the walls (±2 d_s).
  for (const auto& tri : plan->triangles) {
    for (uint32_t v : tri) {
      const Vector2d& p = plan->vertices[v];
      EXPECT_GE(p.x(), -2 * kSpacing);
      EXPECT_LE(p.x(), 6 + 2 * kSpacing);
      EXPECT_GE(p.y(), -2 * kSpacing);
      EXPECT_LE(p.y(), 4 + 2 * kSpacing);
    }
  }
  EXPECT_EQ(report.samples, set.samples.size());
  EXPECT_GT(report.sight_segments, 1000u);
  EXPECT_TRUE(report.converged);
  // Only slivers go: triangles between three consecutive samples of a noisy wall that a line of
  // sight grazed, cut off from the room by edges under 2.1 d_s (thin walls), never entered.
  EXPECT_LT(report.removed_area_m2, 0.05);
}

// The walk starts outside the building and enters through a 0.9 m door: poses outside the
// triangulation's hull carve by clipped walks (not the per-pose sweep), and so do path segments
// that enter the hull.
TEST(RoomLabelingTest, PosesOutsideTheHullAreClipped) {
  Scene scene;
  scene.walls = {{{0, 0}, {6, 0}}, {{6, 0}, {6, 4}}, {{6, 4}, {0, 4}}, {{0, 4}, {0, 2.4}},
                 {{0, 1.5}, {0, 0}}};
  scene.paths = {{{-3, 1.95}, {1, 1.95}, {5, 1}, {5, 3}, {1, 3}}};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 1u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 24.0, 0.02 * 24.0);
  for (const auto& tri : plan->triangles) {
    for (uint32_t v : tri) EXPECT_GE(plan->vertices[v].x(), -2 * kSpacing);
  }
}

// The wall between rooms A = [0, 4.95]×[0, 4] and B = [5.05, 10]×[0, 4]: 10 cm thick (both
// faces and the door jambs are walls), with a 0.9 m door at y ∈ [0.4, 1.3].
void AddWallAB(std::vector<Wall>& walls, double top) {
  walls.push_back({{4.95, 0}, {4.95, 0.4}});
  walls.push_back({{4.95, 0.4}, {5.05, 0.4}});
  walls.push_back({{5.05, 0.4}, {5.05, 0}});
  walls.push_back({{4.95, 1.3}, {4.95, top}});
  walls.push_back({{4.95, 1.3}, {5.05, 1.3}});
  walls.push_back({{5.05, 1.3}, {5.05, 4}});
}

Scene TwoRooms() {
  Scene scene;
  scene.walls = {{{0, 0}, {10, 0}}, {{10, 0}, {10, 4}}, {{10, 4}, {0, 4}}, {{0, 4}, {0, 0}}};
  AddWallAB(scene.walls, 4);
  scene.paths = {{{1, 1}, {4, 1}, {4, 3}, {1, 3}, {1, 2}, {4, 0.85}, {6, 0.85}, {9, 1}, {9, 3},
                  {6, 3}}};
  return scene;
}

TEST(RoomLabelingTest, TwoRoomsJoinedByADoor) {
  const WallSampleSet set = MakeSamples(TwoRooms());
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {});
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 2u);
  for (const FloorPlanRoom& room : plan->rooms) EXPECT_NEAR(room.area_m2, 19.8, 0.03 * 19.8);
  // One room on each side of the wall.
  std::vector<int> left(2, 0), right(2, 0);
  for (size_t t = 0; t < plan->triangles.size(); ++t) {
    const Vector2d c = Centroid(*plan, t);
    if (c.x() < 4.9) ++left[plan->triangle_room[t]];
    if (c.x() > 5.1) ++right[plan->triangle_room[t]];
  }
  EXPECT_TRUE((left[0] == 0 && right[1] == 0) || (left[1] == 0 && right[0] == 0))
      << "left " << left[0] << "/" << left[1] << " right " << right[0] << "/" << right[1];
  // The border is the door.
  std::vector<Vector2d> mids;
  const double border = BorderLength(*plan, 0, 1, &mids);
  EXPECT_GT(border, 0.85);
  EXPECT_LT(border, 1.2);
  for (const Vector2d& m : mids) {
    EXPECT_NEAR(m.x(), 5.0, 0.1);
    EXPECT_GT(m.y(), 0.35);
    EXPECT_LT(m.y(), 1.35);
  }
}

// 2.6 m wide: the borders between the corridor's pieces are its width, wider than a double door
// (2.44 m, §3.3.2), so they are merged. A 2 m corridor: NarrowCorridorIsOneRoom… below.
TEST(RoomLabelingTest, CorridorIsOneRoom) {
  Scene scene;
  AddRect(scene.walls, 0, 0, 20, 2.6);
  scene.paths = {{{0.5, 1.3}, {19.5, 1.3}}};
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(MakeSamples(scene), {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  EXPECT_EQ(plan->rooms.size(), 1u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 52.0, 0.03 * 52.0);
  // The merge rule did the work: there were several seeds at first.
  EXPECT_GT(report.initial_seeds, 1u);
  EXPECT_GT(report.merged_seeds, 0u);
  EXPECT_TRUE(report.converged);
}

// A 2 m corridor [0, 20]×[4.1, 6.1] with three 4 m × 4 m rooms below it (x ∈ [1, 5], [8, 12],
// [15, 19], y ∈ [0, 4]) behind 10 cm walls, each with a 0.9 m door; the path walks the corridor
// and loops through each room. The corridor's pieces share borders as wide as the corridor, under
// §3.3.2's 2.44 m, so only the door-narrowing extension merges them; the doors narrow the space
// (0.9 m against 2 m and 4 m) and stay.
Scene NarrowCorridor() {
  Scene scene;
  scene.walls = {{{0, 6.1}, {20, 6.1}}, {{0, 4.1}, {0, 6.1}}, {{20, 4.1}, {20, 6.1}}};
  double x = 0;
  std::vector<Vector2d> path = {{0.5, 5.1}};
  for (double x0 : {1.0, 8.0, 15.0}) {
    const double x1 = x0 + 4, d0 = x0 + 1.5, d1 = d0 + 0.9;  // the door
    scene.walls.push_back({{x, 4.1}, {d0, 4.1}});              // corridor face
    scene.walls.push_back({{x0, 4.0}, {d0, 4.0}});             // room face
    scene.walls.push_back({{d0, 4.0}, {d0, 4.1}});             // jambs
    scene.walls.push_back({{d1, 4.0}, {d1, 4.1}});
    scene.walls.push_back({{d1, 4.0}, {x1, 4.0}});
    x = d1;
    scene.walls.push_back({{x0, 0}, {x1, 0}});
    scene.walls.push_back({{x0, 0}, {x0, 4.0}});
    scene.walls.push_back({{x1, 0}, {x1, 4.0}});
    for (const Vector2d& p : std::vector<Vector2d>{{d0 + 0.45, 5.1}, {d0 + 0.45, 3}, {x0 + 1, 1},
                                                   {x1 - 1, 1}, {d0 + 0.45, 3},
                                                   {d0 + 0.45, 5.1}}) {
      path.push_back(p);
    }
  }
  scene.walls.push_back({{x, 4.1}, {20, 4.1}});
  path.push_back({19.5, 5.1});
  scene.paths = {path};
  return scene;
}

TEST(RoomLabelingTest, NarrowCorridorIsOneRoomAndItsRoomsStay) {
  const WallSampleSet set = MakeSamples(NarrowCorridor());
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 4u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 40.0, 0.03 * 40.0);  // the corridor, largest
  for (size_t r = 1; r < 4; ++r) EXPECT_NEAR(plan->rooms[r].area_m2, 16.0, 0.03 * 16.0);
  EXPECT_GT(report.narrow_merged_seeds, 0u);
  EXPECT_TRUE(report.converged);

  RoomLabelingOptions seed_only;  // §3.3.2's 2.44 m rule alone
  seed_only.door_narrowing = 0;
  absl::StatusOr<FloorPlan> split = LabelRooms(set, seed_only);
  ASSERT_TRUE(split.ok()) << split.status();
  EXPECT_GT(split->rooms.size(), 4u);  // the corridor stays in pieces
}

// Rooms A = [0, 5]×[0, 4] and B = [5, 10]×[0, 4] split by a wall one sample thick at x = 5
// (samples d_s apart, seen from both sides) with a 0.9 m door at y ∈ [0.4, 1.3]. Without the
// thin-wall rule, the triangles on both sides meet along the wall and the rooms share a 3.5 m
// border, so §3.3.2 merges them.
TEST(RoomLabelingTest, ThinWallSeparatesRooms) {
  Scene scene;
  AddRect(scene.walls, 0, 0, 10, 4);
  scene.walls.push_back({{5, 0}, {5, 0.4}});
  scene.walls.push_back({{5, 1.3}, {5, 4}});
  scene.paths = {{{1, 1}, {4, 1}, {4, 3}, {1, 3}, {1, 2}, {4, 0.85}, {6, 0.85}, {9, 1}, {9, 3},
                  {6, 3}}};
  const WallSampleSet set = MakeSamples(scene);
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {});
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 2u);
  for (const FloorPlanRoom& room : plan->rooms) EXPECT_NEAR(room.area_m2, 20.0, 0.03 * 20.0);
  std::vector<int> left(2, 0), right(2, 0);  // one room on each side
  for (size_t t = 0; t < plan->triangles.size(); ++t) {
    const Vector2d c = Centroid(*plan, t);
    if (c.x() < 4.95) ++left[plan->triangle_room[t]];
    if (c.x() > 5.05) ++right[plan->triangle_room[t]];
  }
  EXPECT_TRUE((left[0] == 0 && right[1] == 0) || (left[1] == 0 && right[0] == 0))
      << "left " << left[0] << "/" << left[1] << " right " << right[0] << "/" << right[1];

  RoomLabelingOptions no_thin;
  no_thin.thin_wall_spacings = 0;
  absl::StatusOr<FloorPlan> merged = LabelRooms(set, no_thin);
  ASSERT_TRUE(merged.ok()) << merged.status();
  EXPECT_EQ(merged->rooms.size(), 1u);
}

// TwoRooms' wall with two 1.3 m doors (y ∈ [0.4, 1.7] and [2.3, 3.6]): 2.6 m of border in all,
// more than 2.44 m, but each border is one door.
TEST(RoomLabelingTest, TwoDoorsBetweenTheSameRoomsAreTwoBorders) {
  Scene scene;
  scene.walls = {{{0, 0}, {10, 0}}, {{10, 0}, {10, 4}}, {{10, 4}, {0, 4}}, {{0, 4}, {0, 0}}};
  for (const auto& [y0, y1] : {std::pair{0.0, 0.4}, std::pair{1.7, 2.3}, std::pair{3.6, 4.0}}) {
    scene.walls.push_back({{4.95, y0}, {4.95, y1}});
    scene.walls.push_back({{5.05, y0}, {5.05, y1}});
    if (y0 > 0) scene.walls.push_back({{4.95, y0}, {5.05, y0}});
    if (y1 < 4) scene.walls.push_back({{4.95, y1}, {5.05, y1}});
  }
  scene.paths = {{{1, 1}, {4, 1}, {4, 3}, {1, 3}, {1, 2}, {4, 1.05}, {6, 1.05}, {9, 1}, {9, 3},
                  {6, 3}, {4, 2.95}}};
  const WallSampleSet set = MakeSamples(scene);
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {});
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 2u);
  for (const FloorPlanRoom& room : plan->rooms) EXPECT_NEAR(room.area_m2, 19.8, 0.03 * 19.8);
  EXPECT_GT(BorderLength(*plan, 0, 1), 2.44);  // both doors, in two pieces
}

// Two equal 4 m × 4 m rooms joined by a door in the middle of their shared 10 cm wall. Each
// room's largest circle touches the wall at the door, so the two bulge into each other by a few
// cm through it; with the dissertation's literal "intersects" the one that sorts first suppresses
// the other's seed and the rooms merge.
TEST(RoomLabelingTest, EqualRoomsJoinedByACentredDoorKeepTheirSeeds) {
  Scene scene;
  scene.walls = {{{0, 0}, {8, 0}}, {{8, 0}, {8, 4}}, {{8, 4}, {0, 4}}, {{0, 4}, {0, 0}},
                 {{3.95, 0}, {3.95, 1.55}}, {{4.05, 0}, {4.05, 1.55}},
                 {{3.95, 2.45}, {3.95, 4}}, {{4.05, 2.45}, {4.05, 4}},
                 {{3.95, 1.55}, {4.05, 1.55}}, {{3.95, 2.45}, {4.05, 2.45}}};
  scene.paths = {{{1, 1}, {3, 1}, {3, 3}, {1, 3}, {1, 2}, {7, 2}, {7, 1}, {5, 1}, {5, 3}, {7, 3}}};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 2u);
  for (const FloorPlanRoom& room : plan->rooms) EXPECT_NEAR(room.area_m2, 15.8, 0.03 * 15.8);
  EXPECT_EQ(report.initial_seeds, 2u);

  RoomLabelingOptions literal;  // any overlap suppresses
  literal.seed_min_overlap = 0;
  literal.open_side_max_m = 0;  // which would cut the merged room at the door again
  absl::StatusOr<FloorPlan> shared = LabelRooms(set, literal);
  ASSERT_TRUE(shared.ok()) << shared.status();
  EXPECT_EQ(shared->rooms.size(), 1u);
}

// A 3 m corridor [0, 16]×[3, 6] with three bays below it, 3 m wide and 3 m deep (x ∈ [2, 5],
// [5.1, 8.1], [8.2, 11.2], y ∈ [0, 3]), open to the corridor over their whole width, between
// 10 cm partitions (as on lab_c's map). The largest circles sit in the bays' openings, across
// bay and corridor, so §3.3.2 leaves no seed inside a bay and the corridor takes them; the open
// sides cut each bay off at the line between its partitions' tips.
TEST(RoomLabelingTest, BaysOpenToACorridorAreRooms) {
  Scene scene;
  scene.walls = {{{0, 6}, {16, 6}}, {{0, 3}, {0, 6}},      {{16, 3}, {16, 6}},
                 {{0, 3}, {2, 3}},  {{11.2, 3}, {16, 3}},  {{2, 0}, {11.2, 0}},
                 {{2, 0}, {2, 3}},  {{11.2, 0}, {11.2, 3}}};
  std::vector<Vector2d> path = {{0.5, 4.5}};
  for (double x : {5.0, 8.1}) {  // the partitions' faces and tips
    scene.walls.push_back({{x, 0}, {x, 3}});
    scene.walls.push_back({{x + 0.1, 0}, {x + 0.1, 3}});
    scene.walls.push_back({{x, 3}, {x + 0.1, 3}});
  }
  for (double x : {3.5, 6.6, 9.7}) {
    for (const Vector2d& p : std::vector<Vector2d>{{x, 4.5}, {x, 1}, {x, 4.5}}) path.push_back(p);
  }
  path.push_back({15.5, 4.5});
  scene.paths = {path};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 4u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 48.0, 0.03 * 48.0);  // the corridor, largest
  for (size_t r = 1; r < 4; ++r) EXPECT_NEAR(plan->rooms[r].area_m2, 9.0, 0.05 * 9.0);
  EXPECT_EQ(report.open_sides_split, 3u);

  RoomLabelingOptions off;
  off.open_side_max_m = 0;
  absl::StatusOr<FloorPlan> merged = LabelRooms(set, off);
  ASSERT_TRUE(merged.ok()) << merged.status();
  EXPECT_LT(merged->rooms.size(), 4u);
}

// A corridor [0, 16]×[4, 6] with a 2.5 m branch [7, 9.5]×[0, 4] off it, both walked, and a
// 4 m × 3.9 m room [9.6, 13.6]×[0, 3.9] behind a 10 cm wall with a 0.9 m door off the branch.
// The branch's mouth is wider than a double door, but it runs between two corners, no wall's
// tip, and the branch leads on to the room: it stays part of the corridor.
TEST(RoomLabelingTest, CorridorBranchWithADoorIsNoOpenSide) {
  Scene scene;
  scene.walls = {{{0, 6}, {16, 6}},        {{0, 4}, {0, 6}},          {{16, 4}, {16, 6}},
                 {{0, 4}, {7, 4}},         {{9.5, 4}, {16, 4}},       {{7, 0}, {7, 4}},
                 {{7, 0}, {13.6, 0}},      {{9.5, 1.9}, {9.5, 4}},    {{9.6, 1.9}, {9.6, 3.9}},
                 {{9.5, 0}, {9.5, 1}},     {{9.6, 0}, {9.6, 1}},      {{9.5, 1}, {9.6, 1}},
                 {{9.5, 1.9}, {9.6, 1.9}}, {{9.6, 3.9}, {13.6, 3.9}}, {{13.6, 0}, {13.6, 3.9}}};
  scene.paths = {{{0.5, 5},
                  {8.25, 5},
                  {8.25, 1.45},
                  {11.6, 1.45},
                  {11.6, 3},
                  {8.25, 1.45},
                  {8.25, 5},
                  {15.5, 5}}};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 2u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 32.0 + 10.0, 0.03 * 42.0);  // corridor and branch
  EXPECT_NEAR(plan->rooms[1].area_m2, 15.6, 0.03 * 15.6);
  EXPECT_EQ(report.open_sides_split, 0u);
}

// BaysOpenToACorridorAreRooms' middle bay with a 0.9 m door in its back wall (10 cm thick) to a
// 3 m × 3 m room behind it, walked through: that bay leads on, so it is no dead end and stays
// with the corridor; the bays either side are cut off as before.
TEST(RoomLabelingTest, BayThatLeadsOnIsNoOpenSide) {
  Scene scene;
  scene.walls = {{{0, 6}, {16, 6}},
                 {{0, 3}, {0, 6}},
                 {{16, 3}, {16, 6}},
                 {{0, 3}, {2, 3}},
                 {{11.2, 3}, {16, 3}},
                 {{2, 0}, {5.1, 0}},
                 {{8.1, 0}, {11.2, 0}},
                 {{2, 0}, {2, 3}},
                 {{11.2, 0}, {11.2, 3}},
                 // the middle bay's back wall, its door at x ∈ [6.15, 7.05], the room behind
                 {{5.1, 0}, {6.15, 0}},
                 {{7.05, 0}, {8.1, 0}},
                 {{5.1, -0.1}, {6.15, -0.1}},
                 {{7.05, -0.1}, {8.1, -0.1}},
                 {{6.15, -0.1}, {6.15, 0}},
                 {{7.05, -0.1}, {7.05, 0}},
                 {{5.1, -3.1}, {8.1, -3.1}},
                 {{5.1, -3.1}, {5.1, -0.1}},
                 {{8.1, -3.1}, {8.1, -0.1}}};
  std::vector<Vector2d> path = {{0.5, 4.5}};
  for (double x : {5.0, 8.1}) {
    scene.walls.push_back({{x, 0}, {x, 3}});
    scene.walls.push_back({{x + 0.1, 0}, {x + 0.1, 3}});
    scene.walls.push_back({{x, 3}, {x + 0.1, 3}});
  }
  for (const Vector2d& p : std::vector<Vector2d>{{3.5, 4.5},
                                                 {3.5, 1},
                                                 {3.5, 4.5},
                                                 {6.6, 4.5},
                                                 {6.6, -1.6},
                                                 {6.6, 4.5},
                                                 {9.7, 4.5},
                                                 {9.7, 1},
                                                 {9.7, 4.5},
                                                 {15.5, 4.5}}) {
    path.push_back(p);
  }
  scene.paths = {path};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 4u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 48.0 + 9.0, 0.03 * 57.0);  // corridor and middle bay
  // The two bays cut off and the room behind the door, 9 m² each.
  for (size_t r = 1; r < 4; ++r) EXPECT_NEAR(plan->rooms[r].area_m2, 9.0, 0.08 * 9.0);
  EXPECT_EQ(report.open_sides_split, 2u);
}

// A 0.9 m × 0.9 m closet behind a 0.6 m opening in the right wall of a 6 m × 4 m room, and the
// path goes in: the closet is its own room by §3.3.2 (a seed, a narrow door), but at 0.81 m² no
// room; it joins the room beside it.
TEST(RoomLabelingTest, RoomUnderOneSquareMetreJoinsItsNeighbour) {
  Scene scene;
  scene.walls = {{{0, 0}, {6, 0}},         {{0, 4}, {6, 4}},         {{0, 0}, {0, 4}},
                 {{6, 0}, {6, 1.7}},       {{6, 2.3}, {6, 4}},       {{6, 1.7}, {6.1, 1.7}},
                 {{6, 2.3}, {6.1, 2.3}},   {{6.1, 1.7}, {6.1, 1.55}}, {{6.1, 2.3}, {6.1, 2.45}},
                 {{6.1, 1.55}, {7, 1.55}}, {{7, 1.55}, {7, 2.45}}, {{7, 2.45}, {6.1, 2.45}}};
  scene.paths = {{{1, 1}, {5, 1}, {5, 2}, {6.55, 2}, {5, 2}, {5, 3}, {1, 3}}};
  const WallSampleSet set = MakeSamples(scene);
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  ASSERT_EQ(plan->rooms.size(), 1u);
  EXPECT_NEAR(plan->rooms[0].area_m2, 24.0 + 0.06 + 0.81, 0.03 * 24.9);
  EXPECT_GE(report.small_merged_rooms, 1u);

  RoomLabelingOptions keep_small;
  keep_small.min_room_area_m2 = 0;
  absl::StatusOr<FloorPlan> kept = LabelRooms(set, keep_small);
  ASSERT_TRUE(kept.ok()) << kept.status();
  EXPECT_EQ(kept->rooms.size(), 2u);
}

// TwoRooms with room C = [0, 4.95]×[4.05, 8] above A, behind a 10 cm wall with a 0.9 m door
// (x ∈ [0.5, 1.4]); A is [0, 4.95]×[0, 3.95]. The path stays in A and B, so C is seen only
// through its door.
Scene ThreeRooms() {
  Scene scene;
  scene.walls = {{{0, 0}, {10, 0}},        {{10, 0}, {10, 4}},        {{10, 4}, {5.05, 4}},
                 {{0, 0}, {0, 8}},         {{0, 8}, {4.95, 8}},       {{4.95, 8}, {4.95, 4.05}},
                 {{0, 3.95}, {0.5, 3.95}}, {{1.4, 3.95}, {4.95, 3.95}}, {{0, 4.05}, {0.5, 4.05}},
                 {{1.4, 4.05}, {4.95, 4.05}}, {{0.5, 3.95}, {0.5, 4.05}}, {{1.4, 3.95}, {1.4, 4.05}}};
  AddWallAB(scene.walls, 3.95);
  scene.paths = TwoRooms().paths;
  return scene;
}

bool InRoomC(const Vector2d& p) { return p.x() < 4.95 && p.y() > 4.06; }

TEST(RoomLabelingTest, UnenteredRoomIsRemoved) {
  const WallSampleSet set = MakeSamples(ThreeRooms());
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  EXPECT_EQ(plan->rooms.size(), 2u);
  EXPECT_GE(report.removed_rooms, 1u);
  for (size_t t = 0; t < plan->triangles.size(); ++t) {
    EXPECT_FALSE(InRoomC(Centroid(*plan, t))) << "triangle " << t << " is in the unentered room";
  }
  EXPECT_NEAR(plan->rooms[0].area_m2, 19.8, 0.03 * 19.8);   // B
  EXPECT_NEAR(plan->rooms[1].area_m2, 19.55, 0.03 * 19.55);  // A

  RoomLabelingOptions keep;
  keep.remove_unentered_rooms = false;
  absl::StatusOr<FloorPlan> kept = LabelRooms(set, keep);
  ASSERT_TRUE(kept.ok()) << kept.status();
  CheckPlan(*kept);
  EXPECT_EQ(kept->rooms.size(), 3u);
  double area_c = 0;
  for (size_t t = 0; t < kept->triangles.size(); ++t) {
    if (InRoomC(Centroid(*kept, t))) area_c += TriangleArea(*kept, t);
  }
  EXPECT_GT(area_c, 2.0);  // the part of C seen through the door
}

// §3.3.1 mis-registration: a wall 10 cm thick (x ∈ [−0.05, 0.05]) between rooms A (left) and
// B (right), scanned from both sides by two path pieces. B's scan is registered 15 cm too far
// towards A (its poses and the samples it saw), more than the wall's thickness, so B's face of
// the wall lands at x = −0.10, 5 cm past A's face (x = −0.05).
struct Misregistered {
  WallSampleSet set;
  double centre_x = -0.075;  // between the two faces as registered
};
Misregistered MakeMisregistered() {
  Scene scene;
  AddRect(scene.walls, -4, 0, -0.05, 4);  // walls 0–3: room A
  AddRect(scene.walls, 0.05, 0, 4, 4);    // walls 4–7: room B
  scene.paths = {{{-3, 1}, {-1, 1}, {-1, 3}, {-3, 3}}, {{3, 1}, {1, 1}, {1, 3}, {3, 3}}};
  std::vector<int> wall_of;
  Misregistered out;
  out.set = MakeSamples(scene, &wall_of);
  const Vector2d shift(-0.15, 0);
  const uint32_t first_b_pose = out.set.path_breaks[0];
  for (size_t j = first_b_pose; j < out.set.poses.size(); ++j) out.set.poses[j] += shift;
  for (size_t i = 0; i < out.set.samples.size(); ++i) {
    if (wall_of[i] >= 4) out.set.samples[i].position += shift;
  }
  return out;
}

// Interior triangles crossing the wall's centre line (away from its ends).
int StraddlingTriangles(const FloorPlan& plan, double centre_x) {
  int n = 0;
  for (const auto& tri : plan.triangles) {
    double lo = 1e9, hi = -1e9, ylo = 1e9, yhi = -1e9;
    for (uint32_t v : tri) {
      lo = std::min(lo, plan.vertices[v].x());
      hi = std::max(hi, plan.vertices[v].x());
      ylo = std::min(ylo, plan.vertices[v].y());
      yhi = std::max(yhi, plan.vertices[v].y());
    }
    if (lo < centre_x && hi > centre_x && ylo > 0.2 && yhi < 3.8) ++n;
  }
  return n;
}

TEST(RoomLabelingTest, OcclusionCheckKeepsAMisregisteredWall) {
  const Misregistered m = MakeMisregistered();
  RoomLabelingReport report;
  absl::StatusOr<FloorPlan> plan = LabelRooms(m.set, {}, &report);
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  EXPECT_GT(report.truncated_segments, 0u);
  EXPECT_EQ(StraddlingTriangles(*plan, m.centre_x), 0);
  EXPECT_EQ(plan->rooms.size(), 2u);

  // Without the occlusion check (and without the thin-wall rule, which would catch it, below)
  // the wall is carved away.
  RoomLabelingOptions tiny;
  tiny.occlusion_diameter_m = 1e-6;
  tiny.thin_wall_spacings = 0;
  absl::StatusOr<FloorPlan> carved = LabelRooms(m.set, tiny);
  ASSERT_TRUE(carved.ok()) << carved.status();
  CheckPlan(*carved);
  EXPECT_GT(StraddlingTriangles(*carved, m.centre_x), 20);  // the wall is carved away
  EXPECT_EQ(carved->rooms.size(), 1u);                      // so A and B become one room

  // The thin-wall rule alone keeps them apart: the triangles carved across the wall have only
  // edges under 2.1 d_s (the two faces are d_s apart as registered), so they are cut off from
  // both rooms, never entered, and removed.
  tiny.thin_wall_spacings = RoomLabelingOptions{}.thin_wall_spacings;
  absl::StatusOr<FloorPlan> thin = LabelRooms(m.set, tiny);
  ASSERT_TRUE(thin.ok()) << thin.status();
  CheckPlan(*thin);
  EXPECT_EQ(StraddlingTriangles(*thin, m.centre_x), 0);
  EXPECT_EQ(thin->rooms.size(), 2u);
}

TEST(RoomLabelingTest, BadInput) {
  WallSampleSet set;
  set.poses = {{0.5, 1.5}};
  for (int i = 0; i < 2; ++i) {
    WallSample s;
    s.position = {static_cast<double>(i), 1};
    s.ceiling_z = 2;
    s.poses = {0};
    set.samples.push_back(s);
  }
  EXPECT_EQ(LabelRooms(set, {}).status().code(), absl::StatusCode::kInvalidArgument);
  set.samples.push_back(set.samples[0]);  // a duplicate is not a third sample
  EXPECT_EQ(LabelRooms(set, {}).status().code(), absl::StatusCode::kInvalidArgument);
  set.samples.back().position = {2, 1};  // collinear
  EXPECT_EQ(LabelRooms(set, {}).status().code(), absl::StatusCode::kInvalidArgument);
  set.samples.back().position = {0.5, 3};
  ASSERT_TRUE(LabelRooms(set, {}).ok());

  RoomLabelingOptions bad;
  bad.occlusion_diameter_m = -1;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.max_door_width_m = 0;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.door_narrowing = -0.1;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.door_context = 0;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.thin_wall_spacings = std::nan("");
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.seed_min_overlap = 3;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.open_side_max_m = -1;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.wall_end_span_deg = 360;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.min_room_area_m2 = -1;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.max_rounds = 0;
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.occlusion_diameter_m = std::nan("");
  EXPECT_EQ(LabelRooms(set, bad).status().code(), absl::StatusCode::kInvalidArgument);

  WallSampleSet invalid = set;
  invalid.samples[0].floor_z = 5;  // above the ceiling
  EXPECT_EQ(LabelRooms(invalid, {}).status().code(), absl::StatusCode::kInvalidArgument);
  invalid = set;
  invalid.samples[0].poses = {3};  // no such pose
  EXPECT_EQ(LabelRooms(invalid, {}).status().code(), absl::StatusCode::kInvalidArgument);

  WallSampleSet no_poses = set;
  no_poses.poses.clear();
  for (WallSample& s : no_poses.samples) s.poses.clear();
  const absl::Status status = LabelRooms(no_poses, {}).status();
  EXPECT_EQ(status.code(), absl::StatusCode::kFailedPrecondition) << status;
}

TEST(RoomLabelingTest, ShuffledSamplesGiveTheSameRooms) {
  const WallSampleSet set = MakeSamples(ThreeRooms());
  RoomLabelingOptions keep;
  keep.remove_unentered_rooms = false;
  absl::StatusOr<FloorPlan> a = LabelRooms(set, keep);
  ASSERT_TRUE(a.ok()) << a.status();
  WallSampleSet shuffled = set;
  std::mt19937 rng(11);
  std::shuffle(shuffled.samples.begin(), shuffled.samples.end(), rng);
  absl::StatusOr<FloorPlan> b = LabelRooms(shuffled, keep);
  ASSERT_TRUE(b.ok()) << b.status();
  ASSERT_EQ(a->rooms.size(), b->rooms.size());
  for (size_t r = 0; r < a->rooms.size(); ++r) {
    EXPECT_EQ(a->rooms[r].area_m2, b->rooms[r].area_m2);
    EXPECT_EQ(a->rooms[r].seed_radius_m, b->rooms[r].seed_radius_m);
  }
  EXPECT_EQ(a->triangles, b->triangles);
  EXPECT_EQ(a->triangle_room, b->triangle_room);
}

// Timing on a building of ≥ 30 k samples: 2 rows of 13 rooms (12 m × 12 m, 0.9 m doors) on a
// 2.6 m × 156 m corridor, interior walls 10 cm thick, a path through the corridor and into every
// room. Each cell (room or corridor) is convex, so a pose sees its own cell's samples; like a
// 0.25° laser fan, it keeps the nearest sample per 0.25° bin within 30 m. Disabled by default
// (the lead's benchmark will own it): run with --gtest_also_run_disabled_tests.
TEST(RoomLabelingTest, DISABLED_TimingOnALargeBuilding) {
  constexpr int kRooms = 13;
  constexpr double kW = 12, kCorr0 = 12, kCorr1 = 14.6, kTop = 26.6, kLen = kRooms * kW;
  constexpr double kHalf = 0.05;  // half a wall's thickness
  Scene scene;
  scene.walls = {{{0, 0}, {kLen, 0}}, {{0, kTop}, {kLen, kTop}}, {{0, 0}, {0, kTop}},
                 {{kLen, 0}, {kLen, kTop}}};
  // Corridor walls: faces on both sides, door jambs, one door per room at x ∈ [x + 1, x + 1.9].
  for (double y : {kCorr0, kCorr1}) {
    double start = 0;
    for (int i = 0; i <= kRooms; ++i) {
      const double end = i < kRooms ? i * kW + 1 : kLen;
      scene.walls.push_back({{start, y - kHalf}, {end, y - kHalf}});
      scene.walls.push_back({{start, y + kHalf}, {end, y + kHalf}});
      if (i < kRooms) {
        scene.walls.push_back({{end, y - kHalf}, {end, y + kHalf}});
        scene.walls.push_back({{end + 0.9, y - kHalf}, {end + 0.9, y + kHalf}});
        start = end + 0.9;
      }
    }
  }
  std::vector<std::array<double, 4>> cells = {{0, kCorr0 + kHalf, kLen, kCorr1 - kHalf}};
  std::vector<Vector2d> path = {{0.5, 13.3}};
  for (int i = 0; i < kRooms; ++i) {
    const double x = i * kW;
    if (i > 0) {
      for (double dx : {-kHalf, kHalf}) {
        scene.walls.push_back({{x + dx, 0}, {x + dx, kCorr0 - kHalf}});
        scene.walls.push_back({{x + dx, kCorr1 + kHalf}, {x + dx, kTop}});
      }
    }
    const double x0 = i > 0 ? x + kHalf : 0, x1 = i + 1 < kRooms ? x + kW - kHalf : kLen;
    cells.push_back({x0, 0, x1, kCorr0 - kHalf});
    cells.push_back({x0, kCorr1 + kHalf, x1, kTop});
    const double xc = x + 1.45;
    for (const Vector2d& p : std::vector<Vector2d>{{xc, 13.3}, {xc, 9}, {x + 6, 6}, {x + 9, 3},
                                                   {xc, 9}, {xc, 13.3}, {xc, 17}, {x + 6, 20},
                                                   {x + 9, 23}, {xc, 17}, {xc, 13.3}}) {
      path.push_back(p);
    }
  }
  path.push_back({kLen - 0.5, 13.3});
  scene.paths = {path};
  // Samples only; visibility per convex cell below (MakeSamples' exact test is O(P·S·W)).
  Scene bare = scene;
  bare.paths = {{{-100, -100}, {-100, -99}}};
  WallSampleSet set = MakeSamples(bare);
  set.poses = SamplePath(path);
  set.path_breaks.clear();
  for (WallSample& s : set.samples) s.poses.clear();
  auto on_boundary = [](const std::array<double, 4>& c, const Vector2d& p) {
    const double e = 0.01;
    const bool near = p.x() > c[0] - e && p.x() < c[2] + e && p.y() > c[1] - e && p.y() < c[3] + e;
    const bool inside = p.x() > c[0] + e && p.x() < c[2] - e && p.y() > c[1] + e && p.y() < c[3] - e;
    return near && !inside;
  };
  std::vector<std::vector<uint32_t>> cell_samples(cells.size());
  for (size_t c = 0; c < cells.size(); ++c) {
    for (size_t i = 0; i < set.samples.size(); ++i) {
      if (on_boundary(cells[c], set.samples[i].position)) cell_samples[c].push_back(i);
    }
  }
  std::vector<int> bin_sample(1440);
  std::vector<double> bin_dist(1440);
  for (size_t j = 0; j < set.poses.size(); ++j) {
    const Vector2d& s = set.poses[j];
    size_t c = 0;  // the corridor, grown by a wall's thickness: a pose in a doorway is in it
    while (c < cells.size() && !(s.x() >= cells[c][0] && s.x() <= cells[c][2] &&
                                 s.y() >= cells[c][1] - (c == 0 ? 0.11 : 0) &&
                                 s.y() <= cells[c][3] + (c == 0 ? 0.11 : 0))) {
      ++c;
    }
    ASSERT_LT(c, cells.size()) << "pose " << j << " is in no cell";
    std::fill(bin_sample.begin(), bin_sample.end(), -1);
    for (uint32_t i : cell_samples[c]) {
      const Vector2d d = set.samples[i].position - s;
      const double dist = d.norm();
      if (dist > 30) continue;
      const int bin = std::clamp(
          static_cast<int>((std::atan2(d.y(), d.x()) + M_PI) / (2 * M_PI) * 1440), 0, 1439);
      if (bin_sample[bin] < 0 || dist < bin_dist[bin]) {
        bin_sample[bin] = static_cast<int>(i);
        bin_dist[bin] = dist;
      }
    }
    for (int i : bin_sample) {
      if (i >= 0) set.samples[i].poses.push_back(static_cast<uint32_t>(j));
    }
  }
  RoomLabelingReport report;
  const auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<FloorPlan> plan = LabelRooms(set, {}, &report);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(plan.ok()) << plan.status();
  CheckPlan(*plan);
  std::printf(
      "LabelRooms: %.0f ms; %zu samples, %zu poses, %zu triangles (%zu interior), %zu sight "
      "segments (%zu truncated), %zu initial seeds, %zu merged, %zu rooms removed, %d rounds, "
      "%zu rooms\n",
      ms, report.samples, set.poses.size(), report.triangles, report.interior_triangles,
      report.sight_segments, report.truncated_segments, report.initial_seeds,
      report.merged_seeds, report.removed_rooms, report.rounds, plan->rooms.size());
  EXPECT_GE(report.samples, 30000u);
  EXPECT_EQ(plan->rooms.size(), 2u * kRooms + 1);
  int good = 0;  // rooms of 11.9 m × 11.95 m (11.95 m × 11.95 m at the ends)
  for (const FloorPlanRoom& room : plan->rooms) good += std::abs(room.area_m2 - 142.5) < 0.03 * 142.5;
  EXPECT_EQ(good, 2 * kRooms);

  // The speed goal: floor plan + rooms + extrusion for ≥ 30 k wall samples ≤ 1 s (the
  // dissertation: 8.5 s for 33.6 k). The whole level as the merge makes it (floorplan_pipeline.h).
  const auto t1 = std::chrono::steady_clock::now();
  absl::StatusOr<LevelFloorPlan> level = BuildLevelFloorPlan(set, 0, FloorPlanOptions{});
  const double level_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
  ASSERT_TRUE(level.ok()) << level.status();
  std::printf(
      "BuildLevelFloorPlan: %.0f ms (rooms %.0f, simplify %.0f, outline %.0f, extrude %.0f); "
      "%zu rooms, %zu extruded triangles\n",
      level_ms, 1e3 * level->seconds_rooms, 1e3 * level->seconds_simplify,
      1e3 * level->seconds_outline, 1e3 * level->seconds_extrude, level->plan.rooms.size(),
      level->extruded.triangles.size());
  EXPECT_EQ(level->plan.rooms.size(), 2u * kRooms + 1);
}

}  // namespace
}  // namespace carvemap
