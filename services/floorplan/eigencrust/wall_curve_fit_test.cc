// Tests of the RANSAC line and circle fitting of walls (§3.2.4) on boundary polylines made
// here: samples every 5 cm along known lines and circles with ±1 cm noise, their normals, and
// the boundary edges joining consecutive samples.
#include "services/floorplan/eigencrust/wall_curve_fit.h"

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Vector2d;

constexpr double kSpacing = 0.05;

struct Polyline {
  std::vector<Vector2d> vertices, normals;
  std::vector<std::array<int, 2>> boundary;
  std::vector<Vector2d> truth;  // noise-free positions
};

// Appends samples from a to b (b excluded) with the normal on the left; joins them in order.
void AddSegment(Polyline& p, const Vector2d& a, const Vector2d& b, std::mt19937& rng,
                double noise) {
  std::uniform_real_distribution<double> u(-noise, noise);
  const Vector2d d = b - a;
  const int n = static_cast<int>(std::round(d.norm() / kSpacing));
  const Vector2d normal = Vector2d(-d.y(), d.x()).normalized();
  for (int k = 0; k < n; ++k) {
    const Vector2d t = a + d * (static_cast<double>(k) / n);
    if (!p.vertices.empty()) {
      p.boundary.push_back({static_cast<int>(p.vertices.size()) - 1,
                            static_cast<int>(p.vertices.size())});
    }
    p.truth.push_back(t);
    p.vertices.push_back(t + normal * u(rng));
    p.normals.push_back(normal);
  }
}

void Close(Polyline& p) {
  p.boundary.push_back({static_cast<int>(p.vertices.size()) - 1, 0});
}

double DistanceToLine(const Vector2d& x, const Vector2d& a, const Vector2d& b) {
  const Vector2d d = (b - a).normalized();
  return std::abs((x - a).dot(Vector2d(-d.y(), d.x())));
}

TEST(WallCurveFit, OptionsAndInputsAreValidated) {
  WallCurveFitOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.min_inliers = 2;
  EXPECT_FALSE(o.Validate().ok());
  o = {};
  o.max_radius_m = 0.1;
  EXPECT_FALSE(o.Validate().ok());
  std::vector<Vector2d> v = {{0, 0}, {1, 0}};
  EXPECT_EQ(FitWallCurves(v, v, {{0, 5}}, kSpacing, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FitWallCurves(v, {{0, 1}}, {{0, 1}}, kSpacing, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FitWallCurves(v, v, {{0, 1}}, 0, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// A 6 × 4 m rectangle of noisy samples: four lines; the fitted samples lie on the true walls
// (much closer than the noise) and the corners are sharp (a sample at each true corner).
TEST(WallCurveFit, RectangleGivesFourLinesAndSharpCorners) {
  std::mt19937 rng(5);
  Polyline p;
  const std::vector<Vector2d> c = {{0, 0}, {6, 0}, {6, 4}, {0, 4}};
  for (int i = 0; i < 4; ++i) AddSegment(p, c[i], c[(i + 1) % 4], rng, 0.01);
  Close(p);
  WallCurveFitReport rep;
  absl::StatusOr<WallCurveFit> fit = FitWallCurves(p.vertices, p.normals, p.boundary, kSpacing,
                                                   {}, &rep);
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(rep.lines, 4u);
  EXPECT_EQ(rep.circles, 0u);
  EXPECT_EQ(rep.assigned, p.vertices.size());
  double before = 0, after = 0;
  for (size_t i = 0; i < p.vertices.size(); ++i) {
    double db = 1e9, da = 1e9;
    for (int w = 0; w < 4; ++w) {
      db = std::min(db, DistanceToLine(p.vertices[i], c[w], c[(w + 1) % 4]));
      da = std::min(da, DistanceToLine(fit->fitted[i], c[w], c[(w + 1) % 4]));
    }
    before += db;
    after += da;
  }
  before /= p.vertices.size();
  after /= p.vertices.size();
  EXPECT_LT(after, 0.3 * before) << "before " << before << " after " << after;
  for (const Vector2d& corner : c) {
    double best = 1e9;
    for (const Vector2d& f : fit->fitted) best = std::min(best, (f - corner).norm());
    EXPECT_LT(best, 0.01) << corner.transpose();
  }
}

// A round room of radius 2.5 m: one circle model of the right radius.
TEST(WallCurveFit, RoundRoomGivesOneCircle) {
  std::mt19937 rng(6);
  Polyline p;
  const int n = static_cast<int>(std::round(2 * M_PI * 2.5 / kSpacing));
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  for (int k = 0; k < n; ++k) {
    const double a = 2 * M_PI * k / n;
    const Vector2d r(std::cos(a), std::sin(a));
    p.truth.push_back(2.5 * r + Vector2d(1, 2));
    p.vertices.push_back((2.5 + u(rng)) * r + Vector2d(1, 2));
    p.normals.push_back(-r);
    if (k > 0) p.boundary.push_back({k - 1, k});
  }
  Close(p);
  WallCurveFitReport rep;
  absl::StatusOr<WallCurveFit> fit = FitWallCurves(p.vertices, p.normals, p.boundary, kSpacing,
                                                   {}, &rep);
  ASSERT_TRUE(fit.ok()) << fit.status();
  ASSERT_EQ(rep.circles, 1u);
  EXPECT_EQ(rep.lines, 0u);
  const WallCurve& circle = fit->curves[0];
  EXPECT_NEAR(circle.radius, 2.5, 0.005);
  EXPECT_NEAR((circle.point - Vector2d(1, 2)).norm(), 0, 0.005);
  for (const Vector2d& f : fit->fitted) EXPECT_NEAR((f - Vector2d(1, 2)).norm(), 2.5, 0.006);
}

// The back walls of two offices on one line (§3.2.4's example), 3 m apart: one model.
TEST(WallCurveFit, CollinearWallsShareOneModel) {
  std::mt19937 rng(7);
  Polyline p;
  AddSegment(p, {0, 0}, {2, 0}, rng, 0.005);
  const int first = static_cast<int>(p.vertices.size());
  AddSegment(p, {5, 0}, {7, 0}, rng, 0.005);
  // Split the polyline in two: drop the edge that joined the pieces.
  std::erase_if(p.boundary, [&](const auto& e) { return e[1] == first; });
  absl::StatusOr<WallCurveFit> fit = FitWallCurves(p.vertices, p.normals, p.boundary, kSpacing, {});
  ASSERT_TRUE(fit.ok()) << fit.status();
  ASSERT_EQ(fit->curves.size(), 1u);
  EXPECT_EQ(fit->curve_of[0], fit->curve_of[first]);
}

// A wall piece shorter than 1 m keeps no model of its own (§3.2.4); a long one does.
TEST(WallCurveFit, ShortPiecesAreDropped) {
  std::mt19937 rng(8);
  Polyline p;
  AddSegment(p, {0, 0}, {0.7, 0}, rng, 0.0);
  const int second = static_cast<int>(p.vertices.size());
  AddSegment(p, {3, 1}, {3, 4}, rng, 0.0);
  std::erase_if(p.boundary, [&](const auto& e) { return e[1] == second; });
  WallCurveFitReport rep;
  absl::StatusOr<WallCurveFit> fit =
      FitWallCurves(p.vertices, p.normals, p.boundary, kSpacing, {}, &rep);
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(fit->curve_of[0], -1);
  EXPECT_EQ(fit->fitted[0], p.vertices[0]);
  EXPECT_GE(fit->curve_of[second], 0);
  EXPECT_EQ(fit->curves.size(), 1u);
}

// The same input and seed give the same result.
TEST(WallCurveFit, Deterministic) {
  std::mt19937 rng(9);
  Polyline p;
  const std::vector<Vector2d> c = {{0, 0}, {5, 0}, {5, 3}, {2, 3}, {2, 5}, {0, 5}};
  for (size_t i = 0; i < c.size(); ++i) AddSegment(p, c[i], c[(i + 1) % c.size()], rng, 0.01);
  Close(p);
  absl::StatusOr<WallCurveFit> a = FitWallCurves(p.vertices, p.normals, p.boundary, kSpacing, {});
  absl::StatusOr<WallCurveFit> b = FitWallCurves(p.vertices, p.normals, p.boundary, kSpacing, {});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->curve_of, b->curve_of);
  EXPECT_EQ(a->fitted, b->fitted);
  EXPECT_EQ(a->curves.size(), 6u);
}

}  // namespace
}  // namespace carvemap
