#include "services/floorplan/model/floorplan_simplify.h"

#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <random>
#include <set>
#include <utility>

#include "services/floorplan/model/room_polygons.h"
#include "services/floorplan/test_plans.h"

namespace carvemap {
namespace {

// GridPlan (test_plans.h) with each room seeded at its last triangle.
FloorPlan SeededGridPlan(int nx, int ny, double cell_m, const std::function<int(int, int)>& label,
                         int rooms) {
  FloorPlan plan = GridPlan(nx, ny, cell_m, label, rooms);
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    plan.rooms[plan.triangle_room[t]].seed_triangle = t;
  }
  return plan;
}

double TwiceArea(const FloorPlan& plan, size_t t) {
  const auto& tri = plan.triangles[t];
  const Eigen::Vector2d a = plan.vertices[tri[1]] - plan.vertices[tri[0]];
  const Eigen::Vector2d b = plan.vertices[tri[2]] - plan.vertices[tri[0]];
  return a.x() * b.y() - a.y() * b.x();
}

double TotalArea(const FloorPlan& plan) {
  double sum = 0;
  for (size_t t = 0; t < plan.triangles.size(); ++t) sum += 0.5 * TwiceArea(plan, t);
  return sum;
}

// Vertices on an edge without a reverse (the interior/exterior boundary).
std::set<uint32_t> BoundaryVertices(const FloorPlan& plan) {
  std::set<std::pair<uint32_t, uint32_t>> edges;
  for (const auto& tri : plan.triangles) {
    for (int k = 0; k < 3; ++k) edges.emplace(tri[k], tri[(k + 1) % 3]);
  }
  std::set<uint32_t> out;
  for (const auto& [a, b] : edges) {
    if (!edges.contains({b, a})) out.insert(a);
  }
  return out;
}

// Moves the vertices for which `which` holds by uniform noise in [-noise, noise] in x and y.
void AddNoise(FloorPlan& plan, double noise_m, uint32_t seed,
              const std::function<bool(const Eigen::Vector2d&)>& which) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-noise_m, noise_m);
  for (auto& p : plan.vertices) {
    const double dx = u(rng), dy = u(rng);
    if (which(p)) p += Eigen::Vector2d(dx, dy);
  }
}

double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                       const Eigen::Vector2d& b) {
  const Eigen::Vector2d d = b - a;
  const double t = std::clamp((p - a).dot(d) / d.squaredNorm(), 0.0, 1.0);
  return (a + t * d - p).norm();
}

// Largest distance of a point of `before` from the wall loops of `after`.
double MaxDeviation(const std::vector<Eigen::Vector2d>& before, const FloorPlanOutline& after) {
  double worst = 0;
  for (const auto& p : before) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& wall : after.walls) {
      for (size_t i = 0; i + 1 < wall.size(); ++i) {
        best = std::min(best, SegmentDistance(p, wall[i], wall[i + 1]));
      }
    }
    worst = std::max(worst, best);
  }
  return worst;
}

std::vector<Eigen::Vector2d> Positions(const FloorPlan& plan, const std::set<uint32_t>& vs) {
  std::vector<Eigen::Vector2d> out;
  for (uint32_t v : vs) out.push_back(plan.vertices[v]);
  return out;
}

void ExpectAllCcw(const FloorPlan& plan) {
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    ASSERT_GT(TwiceArea(plan, t), 0) << "triangle " << t;
  }
}

TEST(FloorPlanSimplifyTest, NoisyStraightWallCollapsesToFewVertices) {
  // A 2 × 0.5 m room sampled every 5 cm; the bottom wall has ±1 cm noise.
  FloorPlan plan = SeededGridPlan(
      40, 10, 0.05, [](int, int) { return 0; }, 1);
  AddNoise(plan, 0.01, 7,
           [](const Eigen::Vector2d& p) { return p.y() == 0 && p.x() > 0.01 && p.x() < 1.99; });
  const double area_before = TotalArea(plan);
  const std::vector<Eigen::Vector2d> before = Positions(plan, BoundaryVertices(plan));
  ASSERT_EQ(before.size(), 100u);
  SimplifyReport report;
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}, &report).ok());
  ExpectAllCcw(plan);
  ASSERT_TRUE(ValidateFloorPlan(plan).ok());
  const std::set<uint32_t> after = BoundaryVertices(plan);
  int bottom = 0;
  for (uint32_t v : after) bottom += plan.vertices[v].y() < 0.02;
  // The noisy bottom wall keeps its two corners and a few vertices; the clean walls only their
  // corners.
  EXPECT_LE(bottom, 6) << "boundary vertices after: " << after.size();
  EXPECT_LE(after.size(), 8u);
  EXPECT_EQ(report.boundary_vertices_before, 100u);
  EXPECT_EQ(report.boundary_vertices_after, after.size());
  EXPECT_LT(report.max_error_m, 0.05);
  EXPECT_LT(std::abs(TotalArea(plan) - area_before) / area_before, 0.01);
  EXPECT_NEAR(plan.rooms[0].area_m2, TotalArea(plan), 1e-12);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  EXPECT_LT(MaxDeviation(before, *outline), 0.03);
  std::cout << "noisy wall: " << after.size() << " boundary vertices (" << bottom
            << " on the noisy wall), area change "
            << std::abs(TotalArea(plan) - area_before) / area_before * 100 << " %\n";
}

TEST(FloorPlanSimplifyTest, DoorwayKeepsItsVertices) {
  // Rooms 0 (x < 1) and 1 (x > 1.05) with a 5 cm wall between them (no triangles) except a
  // 20 cm doorway (cells of room 0) at 0.4 ≤ y < 0.6.
  FloorPlan plan = SeededGridPlan(
      41, 20, 0.05,
      [](int i, int j) {
        if (i < 20) return 0;
        if (i == 20) return j >= 8 && j < 12 ? 0 : -1;
        return 1;
      },
      2);
  // Vertices in both rooms and their neighbours.
  std::vector<std::set<int>> rooms_of(plan.vertices.size());
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    for (uint32_t v : plan.triangles[t]) rooms_of[v].insert(plan.triangle_room[t]);
  }
  std::set<uint32_t> keep;
  for (const auto& tri : plan.triangles) {
    bool multi = false;
    for (uint32_t v : tri) multi |= rooms_of[v].size() > 1;
    if (multi) keep.insert(tri.begin(), tri.end());
  }
  ASSERT_FALSE(keep.empty());
  const std::vector<Eigen::Vector2d> kept_before = Positions(plan, keep);
  const size_t boundary_before = BoundaryVertices(plan).size();
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}).ok());
  ExpectAllCcw(plan);
  for (const Eigen::Vector2d& p : kept_before) {
    bool found = false;
    for (const auto& q : plan.vertices) found |= (p - q).norm() < 1e-12;
    EXPECT_TRUE(found) << "doorway vertex " << p.transpose() << " was removed";
  }
  // The doorway's jambs (the wall ends at y = 0.4 and 0.6 on both sides) are still walls.
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  ASSERT_EQ(outline->rooms.size(), 2u);
  EXPECT_NEAR(outline->rooms[0].area_m2 + outline->rooms[1].area_m2, 41 * 20 * 0.0025 - 16 * 0.0025,
              1e-9);
  EXPECT_LT(BoundaryVertices(plan).size(), boundary_before / 2);
}

TEST(FloorPlanSimplifyTest, RandomNoisyPlanHasNoFlippedTriangles) {
  // 3 m × 2 m, six rooms in blocks, a few missing blocks (columns), ±1 cm noise everywhere.
  std::mt19937 rng(301);
  std::set<std::pair<int, int>> holes;
  for (int k = 0; k < 6; ++k) holes.emplace(1 + rng() % 13, 1 + rng() % 8);
  FloorPlan plan = SeededGridPlan(
      60, 40, 0.05,
      [&](int i, int j) {
        if (holes.contains({i / 4, j / 4})) return -1;
        return (i / 20) + 3 * (j / 20);
      },
      6);
  AddNoise(plan, 0.01, 11, [](const Eigen::Vector2d&) { return true; });
  ExpectAllCcw(plan);
  const double area_before = TotalArea(plan);
  const std::vector<Eigen::Vector2d> before = Positions(plan, BoundaryVertices(plan));
  SimplifyReport report;
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}, &report).ok());
  ExpectAllCcw(plan);
  ASSERT_TRUE(ValidateFloorPlan(plan).ok());
  EXPECT_GT(report.collapses, 100u);
  double rooms_area = 0;
  for (const auto& room : plan.rooms) rooms_area += room.area_m2;
  EXPECT_NEAR(rooms_area, TotalArea(plan), 1e-9);
  EXPECT_LT(std::abs(TotalArea(plan) - area_before) / area_before, 0.01);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  // Each room stays one piece with the same number of holes as before.
  EXPECT_EQ(outline->walls.size(), 1 + holes.size());
  EXPECT_LT(MaxDeviation(before, *outline), 0.05);
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    const int seed = plan.rooms[r].seed_triangle;
    ASSERT_GE(seed, 0);
    EXPECT_EQ(plan.triangle_room[seed], static_cast<int>(r));
  }
  std::cout << "random plan: " << report.boundary_vertices_before << " → "
            << report.boundary_vertices_after << " boundary vertices, " << report.collapses
            << " collapses, " << report.rejected << " rejected\n";
}

TEST(FloorPlanSimplifyTest, WallStepSurvives) {
  // 2 × 1 m room whose bottom wall steps up by 30 cm at x = 1 (a notch), ±1 cm noise on the
  // walls.
  FloorPlan plan = SeededGridPlan(
      40, 20, 0.05, [](int i, int j) { return i >= 20 && j < 6 ? -1 : 0; }, 1);
  const std::set<uint32_t> boundary = BoundaryVertices(plan);
  AddNoise(plan, 0.01, 5, [&](const Eigen::Vector2d& p) {
    for (uint32_t v : boundary) {
      if (plan.vertices[v] == p) return true;
    }
    return false;
  });
  const std::vector<Eigen::Vector2d> before = Positions(plan, boundary);
  const double area_before = TotalArea(plan);
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}).ok());
  ExpectAllCcw(plan);
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  // Every original wall sample, the step's included, is within 5 cm of the simplified walls.
  EXPECT_LT(MaxDeviation(before, *outline), 0.05);
  EXPECT_LT(std::abs(TotalArea(plan) - area_before) / area_before, 0.01);
  // The step's two corners are still there (within the noise and one chamfer).
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(1.0, 0.0), Eigen::Vector2d(1.0, 0.3)}) {
    double best = 1e9;
    for (uint32_t v : BoundaryVertices(plan))
      best = std::min(best, (plan.vertices[v] - corner).norm());
    EXPECT_LT(best, 0.06) << corner.transpose();
  }
  EXPECT_LE(BoundaryVertices(plan).size(), 30u);
}

// Noisy wall samples of an L-shaped plan, Delaunay-triangulated (as LabelRooms does, §3.3.1):
// the triangulation has the slivers and ears along walls that grids lack.
TEST(FloorPlanSimplifyTest, DelaunayOfNoisyWallSamples) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  const std::vector<Eigen::Vector2d> corners = {{0, 0}, {4, 0}, {4, 1.5}, {2, 1.5}, {2, 3}, {0, 3}};
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> noise(-0.01, 0.01);
  std::vector<Eigen::Vector2d> samples;
  for (size_t c = 0; c < corners.size(); ++c) {
    const Eigen::Vector2d a = corners[c], b = corners[(c + 1) % corners.size()];
    const int steps = static_cast<int>(std::round((b - a).norm() / 0.05));
    for (int k = 0; k < steps; ++k) {
      samples.push_back(a + (b - a) * k / steps + Eigen::Vector2d(noise(rng), noise(rng)));
    }
  }
  // Interior: inside the polygon through the samples in order (the walls as scanned).
  const std::vector<Eigen::Vector2d>& truth = samples;
  auto inside = [&](const Eigen::Vector2d& p) {
    bool in = false;
    for (size_t i = 0, j = truth.size() - 1; i < truth.size(); j = i++) {
      if ((truth[i].y() > p.y()) != (truth[j].y() > p.y()) &&
          p.x() < (truth[j].x() - truth[i].x()) * (p.y() - truth[i].y()) /
                          (truth[j].y() - truth[i].y()) +
                      truth[i].x()) {
        in = !in;
      }
    }
    return in;
  };
  std::vector<std::pair<K::Point_2, uint32_t>> points;
  for (uint32_t i = 0; i < samples.size(); ++i) {
    points.emplace_back(K::Point_2(samples[i].x(), samples[i].y()), i);
  }
  using Vb = CGAL::Triangulation_vertex_base_with_info_2<uint32_t, K>;
  using Tds = CGAL::Triangulation_data_structure_2<Vb>;
  CGAL::Delaunay_triangulation_2<K, Tds> dt(points.begin(), points.end());
  FloorPlan plan;
  plan.vertices = samples;
  plan.vertex_floor_z.assign(samples.size(), 0);
  plan.vertex_ceiling_z.assign(samples.size(), 3);
  plan.rooms.resize(1);  // one room: the doorway rule is DoorwayKeepsItsVertices' business
  for (auto f = dt.finite_faces_begin(); f != dt.finite_faces_end(); ++f) {
    const std::array<uint32_t, 3> tri = {f->vertex(0)->info(), f->vertex(1)->info(),
                                         f->vertex(2)->info()};
    const Eigen::Vector2d c = (samples[tri[0]] + samples[tri[1]] + samples[tri[2]]) / 3.0;
    if (!inside(c)) continue;
    plan.triangles.push_back(tri);
    plan.triangle_room.push_back(0);
  }
  ExpectAllCcw(plan);
  ASSERT_TRUE(ValidateFloorPlan(plan).ok()) << ValidateFloorPlan(plan);
  absl::StatusOr<FloorPlanOutline> outline_before = TraceFloorPlan(plan);
  ASSERT_TRUE(outline_before.ok());
  ASSERT_EQ(outline_before->walls.size(), 1u);
  const double area_before = TotalArea(plan);
  SimplifyReport report;
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}, &report).ok());
  ExpectAllCcw(plan);
  ASSERT_TRUE(ValidateFloorPlan(plan).ok());
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  EXPECT_EQ(outline->walls.size(), 1u);
  EXPECT_EQ(outline->rooms.size(), 1u);
  EXPECT_LT(std::abs(TotalArea(plan) - area_before) / area_before, 0.01);
  EXPECT_LT(MaxDeviation(samples, *outline), 0.05);
  // Six corners and a few more on the noisy walls: far below the 280 samples.
  EXPECT_EQ(report.boundary_vertices_before, 280u);
  EXPECT_LE(report.boundary_vertices_after, 16u);
  std::cout << "delaunay L: " << report.boundary_vertices_before << " → "
            << report.boundary_vertices_after << " boundary vertices, " << report.rejected
            << " rejected, max error " << report.max_error_m << " m\n";
}

TEST(FloorPlanSimplifyTest, RejectsMissingErrorBound) {
  FloorPlan plan = SeededGridPlan(
      2, 2, 1.0, [](int, int) { return 0; }, 1);
  EXPECT_EQ(SimplifyFloorPlan(plan, {}).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(SimplifyFloorPlan(plan, {.max_error_m = std::nan("")}).code(),
            absl::StatusCode::kInvalidArgument);
  plan.triangles.push_back(plan.triangles[0]);
  plan.triangle_room.push_back(0);
  const FloorPlan copy = plan;
  EXPECT_EQ(SimplifyFloorPlan(plan, {.max_error_m = 0.05}).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(plan.triangles, copy.triangles);
}

TEST(FloorPlanSimplifyTest, SixtyThousandTrianglesIsFast) {
  FloorPlan plan = SeededGridPlan(
      200, 150, 0.05, [](int i, int j) { return (i / 100) + 2 * (j / 75); }, 4);
  AddNoise(plan, 0.01, 3, [](const Eigen::Vector2d&) { return true; });
  ASSERT_EQ(plan.triangles.size(), 60000u);
  const auto start = std::chrono::steady_clock::now();
  SimplifyReport report;
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}, &report).ok());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ExpectAllCcw(plan);
  std::cout << "simplify 60k triangles: " << seconds * 1000 << " ms, "
            << report.boundary_vertices_before << " → " << report.boundary_vertices_after
            << " boundary vertices\n";
  EXPECT_LT(seconds, 1.0);
}

}  // namespace
}  // namespace carvemap
