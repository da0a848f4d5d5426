// Tests of the Eigencrust labelling (§3.2.1–§3.2.3) on synthetic wall samples
// (synthetic_walls_test_util.h).
#include "services/floorplan/eigencrust/eigencrust.h"

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "services/floorplan/eigencrust/synthetic_walls_test_util.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

using testing::AddRoom;
using testing::Face;
using testing::kSpacing;
using testing::MakeSamples;
using testing::Scene;

void Print(const char* name, const EigencrustReport& r) {
  std::printf("[%s] samples %zu triangles %zu poles %zu edges -%zu +%zu sight lines %zu known in %zu "
              "out %zu; pole nodes solved %zu (lambda %.3g), non-pole nodes %zu (lambda %.3g); "
              "inside %zu -> %zu, flipped unions %zu protrusions %zu, |B| %zu\n",
              name, r.samples, r.triangles, r.poles, r.negative_edges, r.positive_edges,
              r.sight_lines, r.known_inside, r.known_outside, r.pole_nodes_solved,
              r.pole_eigenvalue, r.nonpole_nodes, r.nonpole_eigenvalue, r.inside_before_cleanup,
              r.inside, r.flipped_unions, r.flipped_protrusions, r.boundary_edges);
}

double InsideArea(const EigencrustLabeling& l) {
  double area = 0;
  for (size_t t = 0; t < l.triangles.size(); ++t) {
    if (!l.inside[t]) continue;
    const Vector2d& a = l.vertices[l.triangles[t][0]];
    const Vector2d& b = l.vertices[l.triangles[t][1]];
    const Vector2d& c = l.vertices[l.triangles[t][2]];
    area += 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
  }
  return area;
}

double BoundaryLength(const EigencrustLabeling& l) {
  double len = 0;
  for (const auto& e : l.boundary) len += (l.vertices[e[0]] - l.vertices[e[1]]).norm();
  return len;
}

TEST(Eigencrust, OptionsAreValidated) {
  EigencrustOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.min_sight_lines = 0;
  EXPECT_NE(o.Validate().message().find("min_sight_lines"), std::string::npos);
  o = {};
  o.sight_middle_fraction = 1.5;
  EXPECT_NE(o.Validate().message().find("sight_middle_fraction"), std::string::npos);
  o = {};
  o.box_margin_m = 0;
  EXPECT_FALSE(o.Validate().ok());
  WallSampleSet two;
  two.samples.resize(2);
  two.samples[1].position = Vector2d(1, 0);
  for (auto& s : two.samples) s.ceiling_z = 1;
  EXPECT_EQ(LabelEigencrust(two, {}).status().code(), absl::StatusCode::kInvalidArgument);
}

// One 6 × 4 m room: the labelling's inside is the room (area, boundary length = perimeter).
TEST(Eigencrust, SingleRoomIsInside) {
  Scene scene;
  AddRoom(scene.faces, 0, 0, 6, 4);
  scene.path = {{1, 1}, {5, 1}, {5, 3}, {1, 3}};
  const WallSampleSet samples = MakeSamples(scene);
  EigencrustReport rep;
  absl::StatusOr<EigencrustLabeling> l = LabelEigencrust(samples, {}, &rep);
  ASSERT_TRUE(l.ok()) << l.status();
  Print("single room", rep);
  EXPECT_NEAR(InsideArea(*l), 24.0, 0.3);
  EXPECT_NEAR(BoundaryLength(*l), 20.0, 0.5);
  EXPECT_TRUE(l->InsideAt({3, 2}));
  EXPECT_TRUE(l->InsideAt({0.1, 0.1}));
  EXPECT_FALSE(l->InsideAt({-0.3, 2}));
  EXPECT_FALSE(l->InsideAt({6.4, 4.4}));
  EXPECT_GT(rep.poles, 0u);
  EXPECT_GT(rep.negative_edges, 0u);
  EXPECT_GT(rep.known_inside, 0u);
  EXPECT_GT(rep.known_outside, 0u);
}

// With no pose at all, nothing is known inside: the eigenvector alone must find the room (the
// negative pole edges of eq 3.1 oppose the inside to the box corners' outside super-node).
TEST(Eigencrust, SpectrumAloneFindsTheRoomWithoutPoses) {
  Scene scene;
  AddRoom(scene.faces, 0, 0, 6, 4);
  WallSampleSet samples = MakeSamples(scene);
  EigencrustReport rep;
  absl::StatusOr<EigencrustLabeling> l = LabelEigencrust(samples, {}, &rep);
  ASSERT_TRUE(l.ok()) << l.status();
  Print("no poses", rep);
  EXPECT_EQ(rep.known_inside, 0u);
  EXPECT_NEAR(InsideArea(*l), 24.0, 0.3);
  EXPECT_TRUE(l->InsideAt({3, 2}));
  EXPECT_FALSE(l->InsideAt({-0.5, -0.5}));
}

// Two 5 × 4 m rooms with a 0.15 m wall between them and a 0.9 m door: both rooms inside, the
// wall outside except at the door.
TEST(Eigencrust, TwoRoomsWithAThickWallAndADoor) {
  const Scene scene = testing::TwoRoomsWithDoor();
  const WallSampleSet samples = MakeSamples(scene);
  EigencrustReport rep;
  absl::StatusOr<EigencrustLabeling> l = LabelEigencrust(samples, {}, &rep);
  ASSERT_TRUE(l.ok()) << l.status();
  Print("two rooms", rep);
  EXPECT_NEAR(InsideArea(*l), 40.0 + 0.9 * 0.15, 0.6);
  EXPECT_TRUE(l->InsideAt({2.5, 2}));
  EXPECT_TRUE(l->InsideAt({7.5, 2}));
  EXPECT_TRUE(l->InsideAt({5.07, 1.95}));  // in the doorway
  EXPECT_FALSE(l->InsideAt({5.07, 0.7}));  // inside the wall
  EXPECT_FALSE(l->InsideAt({5.07, 3.3}));
}

// A round room (r = 3 m): the inside is the disc.
TEST(Eigencrust, RoundRoom) {
  Scene scene;
  const int n = 64;
  for (int k = 0; k < n; ++k) {
    const double a0 = 2 * M_PI * k / n, a1 = 2 * M_PI * (k + 1) / n;
    scene.faces.push_back({{3 * std::cos(a0), 3 * std::sin(a0)}, {3 * std::cos(a1), 3 * std::sin(a1)}});
  }
  scene.path = {{-1.5, 0}, {1.5, 0}, {0, 1.5}, {0, -1.5}};
  const WallSampleSet samples = MakeSamples(scene);
  absl::StatusOr<EigencrustLabeling> l = LabelEigencrust(samples, {});
  ASSERT_TRUE(l.ok()) << l.status();
  EXPECT_NEAR(InsideArea(*l), M_PI * 9 * std::pow(std::cos(M_PI / n), 2), 0.4);
}

// Outliers (clutter samples scattered in the room with random normals, seen by nobody) do not
// change the inside much: Eigencrust's robustness (§3.2.2, Kolluri et al.).
TEST(Eigencrust, OutliersInsideTheRoom) {
  Scene scene;
  AddRoom(scene.faces, 0, 0, 6, 4);
  scene.path = {{1, 1}, {5, 1}, {5, 3}, {1, 3}};
  WallSampleSet samples = MakeSamples(scene);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> x(0.5, 5.5), y(0.5, 3.5), a(0, 2 * M_PI);
  for (int i = 0; i < 40; ++i) {
    WallSample s;
    s.position = Vector2d(x(rng), y(rng));
    const double t = a(rng);
    s.normal = Vector2d(std::cos(t), std::sin(t));
    s.ceiling_z = 2.5;
    samples.samples.push_back(s);
  }
  absl::StatusOr<EigencrustLabeling> l = LabelEigencrust(samples, {});
  ASSERT_TRUE(l.ok()) << l.status();
  EXPECT_NEAR(InsideArea(*l), 24.0, 0.6);
  EXPECT_TRUE(l->InsideAt({3, 2}));
}

// §3.2.1: a wall scanned twice, 4 cm apart (registration error), becomes one: every sample ends
// within 1 cm of the middle line; samples of the opposite face (opposite normal) stay.
TEST(Eigencrust, SmoothingMergesADoubleSurfacedWall) {
  WallSampleSet set;
  set.spacing_m = kSpacing;
  for (int k = 0; k < 60; ++k) {
    for (double y : {0.0, 0.04}) {
      WallSample s;
      s.position = Vector2d(0.025 + k * kSpacing, y);
      s.normal = Vector2d(0, 1);
      s.ceiling_z = 2.5;
      set.samples.push_back(s);
    }
  }
  WallSample back;  // the wall's other face, 0.1 m behind, facing away
  back.position = Vector2d(1.5, -0.1);
  back.normal = Vector2d(0, -1);
  back.ceiling_z = 2.5;
  set.samples.push_back(back);
  EigencrustOptions o;
  o.smooth = true;
  absl::StatusOr<WallSampleSet> out = SmoothWallSamples(set, o);
  ASSERT_TRUE(out.ok()) << out.status();
  for (size_t i = 0; i + 1 < out->samples.size(); ++i) {
    EXPECT_NEAR(out->samples[i].position.y(), 0.02, 0.01) << i;
  }
  EXPECT_EQ(out->samples.back().position, back.position);
}

// Small unions flip (§3.2.3): a tiny closed loop of samples (a 20 cm column) in the middle of
// the room gives a few outside triangles inside the room; the rule turns them inside.
TEST(Eigencrust, SmallUnionsFlip) {
  Scene scene;
  AddRoom(scene.faces, 0, 0, 6, 4);
  // A 20 cm column at (3, 2), faces outward (the room is outside it).
  scene.faces.push_back({{2.9, 1.9}, {2.9, 2.1}});
  scene.faces.push_back({{2.9, 2.1}, {3.1, 2.1}});
  scene.faces.push_back({{3.1, 2.1}, {3.1, 1.9}});
  scene.faces.push_back({{3.1, 1.9}, {2.9, 1.9}});
  scene.path = {{1, 1}, {5, 1}, {5, 3}, {1, 3}, {1, 1}};
  const WallSampleSet samples = MakeSamples(scene);
  EigencrustOptions keep;
  keep.min_union_triangles = 0;
  EigencrustReport rep_keep, rep_flip;
  absl::StatusOr<EigencrustLabeling> kept = LabelEigencrust(samples, keep, &rep_keep);
  absl::StatusOr<EigencrustLabeling> flipped = LabelEigencrust(samples, {}, &rep_flip);
  ASSERT_TRUE(kept.ok() && flipped.ok());
  EXPECT_FALSE(kept->InsideAt({3, 2}));  // the column's inside is outside
  EXPECT_TRUE(flipped->InsideAt({3, 2}));  // a union of < 30 triangles
  EXPECT_GT(rep_flip.flipped_unions, 0u);
  EXPECT_EQ(rep_keep.flipped_unions, 0u);
}

}  // namespace
}  // namespace carvemap
