#include "geometry/wedge_geometry.h"

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Vector3d;

SymCov3f Iso(double sigma) { return ToSymCov(Eigen::Matrix3d::Identity() * sigma * sigma); }

RayModel Ray(const Vector3d& s, const Vector3d& p, double sigma_p = 0.0, double sigma_s = 0.0) {
  return RayModel{s.cast<float>(), p.cast<float>(), Iso(sigma_s), Iso(sigma_p)};
}

Wedge FourRays(const RayModel& a, const RayModel& b, const RayModel& c, const RayModel& d) {
  Wedge w;
  w.rays = {a, b, c, d};
  w.num_rays = 4;
  return w;
}

SymCov3f RandomCov(std::mt19937_64& rng, double max_sigma) {
  std::normal_distribution<double> n(0, 1);
  Eigen::Matrix3d a;
  for (int i = 0; i < 9; ++i) a(i) = n(rng);
  const double s = std::uniform_real_distribution<double>(0, max_sigma)(rng);
  return ToSymCov(s * s * a * a.transpose() / 3);
}

// A random wedge somewhere in a ±30 m world. `kind` picks the generic case or a degenerate one.
enum class Kind { kGeneric, kSharedSensor, kFlat, kCollinear, kSingle, kTwoRays, kZeroLength };

Wedge RandomWedge(std::mt19937_64& rng, Kind kind) {
  std::uniform_real_distribution<double> u(-1, 1);
  auto uv = [&] { return Vector3d(u(rng), u(rng), u(rng)); };
  const Vector3d sensor = 30 * uv();
  Vector3d dir = uv().normalized();
  const double range = std::uniform_real_distribution<double>(0.3, 25)(rng);
  Wedge w;
  w.num_rays = 4;
  const Vector3d side1 = dir.unitOrthogonal(), side2 = dir.cross(side1);
  const double spread = std::uniform_real_distribution<double>(0.001, 0.2)(rng) * range;
  for (int i = 0; i < 4; ++i) {
    RayModel& r = w.rays[i];
    Vector3d s = sensor + 0.05 * uv();
    Vector3d p = sensor + range * dir + spread * uv();
    switch (kind) {
      case Kind::kGeneric: case Kind::kTwoRays: break;
      case Kind::kSharedSensor: s = sensor + 1e-7 * uv(); break;
      case Kind::kFlat:  // sensor and points in the plane spanned by dir and side1
        s = sensor;
        p = sensor + range * dir + spread * u(rng) * side1;
        break;
      case Kind::kCollinear: s = sensor; p = sensor + range * (1 + 0.1 * i) * dir; break;
      case Kind::kSingle: break;
      case Kind::kZeroLength: p = s; break;
    }
    r.sensor_mean = s.cast<float>();
    r.point_mean = p.cast<float>();
    r.sensor_cov = RandomCov(rng, 0.02);
    r.point_cov = RandomCov(rng, kind == Kind::kFlat ? 0.0 : 0.05);
  }
  if (kind == Kind::kSingle) w.num_rays = 1;
  if (kind == Kind::kTwoRays) w.num_rays = 2;
  (void)side2;
  return w;
}

// Generating points of the wedge's volume (for single rays: the segment only).
std::vector<Vector3d> Corners(const Wedge& w, double sigmas) {
  std::vector<Vector3d> c;
  for (int i = 0; i < w.num_rays; ++i) {
    c.push_back(w.rays[i].sensor_mean.cast<double>());
    c.push_back(ExtendedPointMean(w.rays[i], sigmas));
  }
  return c;
}

// Random points of the convex hull of `corners` (random convex combinations).
std::vector<Vector3d> SampleHull(const std::vector<Vector3d>& corners, int n,
                                 std::mt19937_64& rng) {
  std::exponential_distribution<double> e(1.0);
  std::uniform_int_distribution<int> pick(0, int(corners.size()) - 1);
  std::vector<Vector3d> out;
  for (int i = 0; i < n; ++i) {
    Vector3d x = Vector3d::Zero();
    double sum = 0;
    // Mostly points on faces and edges (few non-zero weights), where a wrong plane would show.
    const int terms = 1 + i % 4;
    for (int t = 0; t < terms; ++t) {
      const double wt = e(rng);
      x += wt * corners[pick(rng)];
      sum += wt;
    }
    out.push_back(x / sum);
  }
  return out;
}

Eigen::AlignedBox3d BoxAround(const Vector3d& x, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  const double size = std::pow(10.0, -3 + 4 * u(rng));  // 1 mm … 10 m
  const Vector3d lo = x - size * Vector3d(u(rng), u(rng), u(rng));
  return Eigen::AlignedBox3d(lo, lo + Vector3d::Constant(size));
}

TEST(WedgeHullTest, PyramidIsExact) {
  // All rays from the origin to the corners of a 2 m square at x = 10 m: a pyramid.
  const Vector3d o = Vector3d::Zero();
  const Wedge w = FourRays(Ray(o, {10, -1, -1}), Ray(o, {10, 1, -1}), Ray(o, {10, 1, 1}),
                           Ray(o, {10, -1, 1}));
  const WedgeHull h = MakeWedgeHull(w);
  EXPECT_EQ(h.planes.size(), 5u);  // 4 sides + base; the quad base deduplicated
  EXPECT_TRUE(h.box.isApprox(Eigen::AlignedBox3d(Vector3d(0, -1, -1), Vector3d(10, 1, 1)), 1e-6));
  EXPECT_TRUE(HullContainsPoint(h, {5, 0.49, 0.49}));
  EXPECT_FALSE(HullContainsPoint(h, {5, 0.51, 0}));
  EXPECT_FALSE(HullContainsPoint(h, {10.01, 0, 0}));
  EXPECT_TRUE(HullIntersectsBox(h, {Vector3d(5, 0.49, 0), Vector3d(5.01, 0.6, 0.01)}));
  EXPECT_FALSE(HullIntersectsBox(h, {Vector3d(5, 0.52, 0), Vector3d(5.01, 0.6, 0.01)}));
  // A box touching the apex only at a corner.
  EXPECT_TRUE(HullIntersectsBox(h, {Vector3d(-1, -1, -1), Vector3d(0, 0, 0)}));
  EXPECT_FALSE(HullIntersectsBox(h, {Vector3d(-1, -1, -1), Vector3d(-0.001, 0, 0)}));
}

TEST(WedgeHullTest, ExtendsThreeSigmaAlongTheRay) {
  RayModel r = Ray({0, 0, 0}, {10, 0, 0});
  // σ_x = 0.1, σ_y = 1: only the component along the ray counts.
  r.point_cov = {0.01f, 0, 0, 1.0f, 0, 0.0001f};
  EXPECT_NEAR(ExtendedPointMean(r).x(), 10.3, 1e-6);
  EXPECT_NEAR(ExtendedPointMean(r, 1.0).x(), 10.1, 1e-6);
  const Vector3d o = Vector3d::Zero();
  Wedge w = FourRays(r, Ray(o, {10, 1, 0}, 0.1), Ray(o, {10, 1, 1}, 0.1), Ray(o, {10, 0, 1}, 0.1));
  const WedgeHull h = MakeWedgeHull(w);
  EXPECT_TRUE(HullContainsPoint(h, {10.29, 0.001, 0.001}));
  EXPECT_FALSE(HullContainsPoint(h, {10.32, 0.001, 0.001}));
}

TEST(WedgeHullTest, SingleRayIsSegmentWidenedByOneSigmaPerLateralAxis) {
  RayModel r = Ray({1, 2, 3}, {1, 2, 13}, 0.01, 0.0);
  r.point_cov = {0.04f, 0, 0, 0.01f, 0, 0.0001f};  // σ_⊥ = 0.2 (x) and 0.1 (y), σ_∥ = 0.01
  Wedge w;
  w.rays[0] = r;
  w.num_rays = 1;
  const WedgeHull h = MakeWedgeHull(w);
  EXPECT_EQ(h.planes.size(), 6u);
  for (double t : {0.0, 0.5, 1.0}) {
    const Vector3d c(1, 2, 3 + t * 10.03);
    EXPECT_TRUE(HullContainsPoint(h, c + Vector3d(0.199, 0.099, 0))) << t;
    EXPECT_TRUE(HullContainsPoint(h, c + Vector3d(-0.199, -0.099, 0))) << t;
    EXPECT_FALSE(HullContainsPoint(h, c + Vector3d(0.21, 0, 0))) << t;
    EXPECT_FALSE(HullContainsPoint(h, c + Vector3d(0, -0.11, 0))) << t;
  }
  EXPECT_TRUE(HullContainsPoint(h, {1, 2, 13.02}));   // within 3σ_∥ past the point
  EXPECT_FALSE(HullContainsPoint(h, {1, 2, 13.05}));  // beyond it
  EXPECT_FALSE(HullContainsPoint(h, {1, 2, 2.99}));   // behind the sensor
  // A wider sensor Gaussian widens the box along both axes.
  w.rays[0].sensor_cov = Iso(0.3);
  const WedgeHull wide = MakeWedgeHull(w);
  EXPECT_TRUE(HullContainsPoint(wide, {1.29, 2.29, 8}));
  EXPECT_FALSE(HullContainsPoint(wide, {1.31, 2, 8}));
}

TEST(WedgeHullTest, SingleRayBoxFollowsATiltedSpread) {
  // A ray along z whose point spread across it has its axes at 30° from x and y: σ 0.2 along
  // the first, 0.05 along the second. The box turns with them, however the ray points.
  const double c = std::cos(M_PI / 6), s = std::sin(M_PI / 6);
  const Vector3d major(c, s, 0), minor(-s, c, 0);
  for (const Vector3d& dir : {Vector3d(0, 0, 1), Vector3d(0, 0, -1)}) {
    const Vector3d from(1, 2, 5), to = from + 4 * dir;
    const Eigen::Matrix3d cov = 0.04 * major * major.transpose() +
                                0.0025 * minor * minor.transpose() +
                                1e-6 * Eigen::Matrix3d::Identity();
    RayModel r = Ray(from, to);
    r.point_cov = ToSymCov(cov);
    Wedge w;
    w.rays[0] = r;
    w.num_rays = 1;
    const WedgeHull h = MakeWedgeHull(w);
    const Vector3d mid = from + 2 * dir;
    for (double sign : {-1.0, 1.0}) {
      EXPECT_TRUE(HullContainsPoint(h, mid + sign * (0.198 * major + 0.049 * minor)));
      EXPECT_FALSE(HullContainsPoint(h, mid + sign * 0.21 * major));
      EXPECT_FALSE(HullContainsPoint(h, mid + sign * 0.06 * minor));
    }
    // 0.16 along x is inside the spread's axis-aligned box (half-width 0.175 in x) but 0.08
    // off the minor axis: outside the turned one.
    EXPECT_FALSE(HullContainsPoint(h, mid + Vector3d(0.16, 0, 0)));
  }
}

TEST(WedgeHullTest, GrazingSingleRayStaysBelowTheSlabAboveIt) {
  // A horizontal scanner 1.85 m up whose ray, pitched 1.5° by pose noise, meets a ceiling at
  // 2.61 m 28 m away: the point covariance of the simulated Freiburg101 walk (σ 9.5 cm along x,
  // 22 cm across in y, 9 cm in z), the sensor's 10 cm / 3 cm. A 3σ tube reached 3.3 m, through a
  // 0.2 m roof slab, and carved a false level above it; the hull must stay inside the slab.
  RayModel r = Ray({12.4, 25.1, 1.85}, {40.15, 20.05, 2.61});
  r.point_cov = {0.0090f, 0, 0, 0.0434f, 0, 0.0067f};
  r.sensor_cov = {0.0063f, 0, 0, 0.0063f, 0, 0.0006f};
  Wedge w;
  w.rays[0] = r;
  w.num_rays = 1;
  const WedgeHull h = MakeWedgeHull(w);
  EXPECT_LT(h.box.max().z(), 2.80);
  EXPECT_GT(h.box.max().z(), 2.61);  // it still reaches past the point
  EXPECT_TRUE(HullContainsPoint(h, {40.15, 20.05, 2.60}));
}

TEST(WedgeHullTest, FlatWedgeGetsAMillimetre) {
  // Operator standing still: both frames identical, so the four rays lie in the plane z = 0.
  const Vector3d o(0, 0, 0);
  const Wedge w = FourRays(Ray(o, {5, 0, 0}), Ray(o, {5, 1, 0}), Ray(o, {5, 0, 0}),
                           Ray(o, {5, 1, 0}));
  const WedgeHull h = MakeWedgeHull(w);
  EXPECT_GT(h.box.sizes().z(), 0.0019);
  EXPECT_LT(h.box.sizes().z(), 0.0021);
  EXPECT_TRUE(HullContainsPoint(h, {4, 0.5, 0.0009}));
  EXPECT_FALSE(HullContainsPoint(h, {4, 0.5, 0.0011}));
  EXPECT_FALSE(HullContainsPoint(h, {4, 0.9, 0}));  // in the plane, outside the triangle
  // Leaf boxes on either side of the plane both touch it.
  EXPECT_TRUE(HullIntersectsBox(h, {Vector3d(4, 0.5, 0), Vector3d(4.0625, 0.5625, 0.0625)}));
  EXPECT_TRUE(HullIntersectsBox(h, {Vector3d(4, 0.5, -0.0625), Vector3d(4.0625, 0.5625, 0)}));
  EXPECT_FALSE(HullIntersectsBox(h, {Vector3d(4, 0.5, 0.002), Vector3d(4.0625, 0.5625, 0.06)}));
}

TEST(WedgeHullTest, CollinearAndPointWedges) {
  const Vector3d o(1, 1, 1);
  const Vector3d d = Vector3d(1, 2, 3).normalized();
  const Wedge line = FourRays(Ray(o, o + 4 * d), Ray(o, o + 5 * d), Ray(o, o + 4 * d),
                              Ray(o, o + 5 * d));
  WedgeHull h = MakeWedgeHull(line);
  EXPECT_TRUE(HullContainsPoint(h, o + 2 * d));
  EXPECT_TRUE(HullContainsPoint(h, o + 5 * d));
  EXPECT_FALSE(HullContainsPoint(h, o + 2 * d + 0.01 * d.unitOrthogonal()));
  const Wedge point = FourRays(Ray(o, o), Ray(o, o), Ray(o, o), Ray(o, o));
  h = MakeWedgeHull(point);
  EXPECT_TRUE(HullContainsPoint(h, o));
  EXPECT_TRUE(HullIntersectsBox(h, {o, o + Vector3d::Constant(0.1)}));
  EXPECT_FALSE(HullIntersectsBox(h, {o + Vector3d::Constant(0.01), o + Vector3d::Constant(0.1)}));
}

// Every point of the wedge's volume lies in the hull, and every box containing one intersects it.
class WedgeHullFuzzTest : public ::testing::TestWithParam<Kind> {};

TEST_P(WedgeHullFuzzTest, ConservativeAgainstDenseSampling) {
  std::mt19937_64 rng(1234 + int(GetParam()));
  for (int iter = 0; iter < 300; ++iter) {
    const Wedge w = RandomWedge(rng, GetParam());
    const double sigmas = iter % 3 == 0 ? 0.0 : 3.0;
    const WedgeHull h = MakeWedgeHull(w, sigmas);
    ASSERT_FALSE(h.planes.empty());
    const std::vector<Vector3d> corners = Corners(w, sigmas);
    for (const Vector3d& c : corners) ASSERT_TRUE(HullContainsPoint(h, c)) << iter;
    for (const Vector3d& x : SampleHull(corners, 400, rng)) {
      ASSERT_TRUE(HullContainsPoint(h, x)) << iter;
      ASSERT_TRUE(HullIntersectsBox(h, BoxAround(x, rng))) << iter;
      // The 6.25 cm leaf holding x.
      const Vector3d lo = (x / 0.0625).array().floor() * 0.0625;
      ASSERT_TRUE(HullIntersectsBox(h, {lo, lo + Vector3d::Constant(0.0625)})) << iter;
    }
  }
}

TEST_P(WedgeHullFuzzTest, FarBoxesDoNotIntersect) {
  std::mt19937_64 rng(99 + int(GetParam()));
  std::uniform_real_distribution<double> u(0, 1);
  for (int iter = 0; iter < 300; ++iter) {
    const Wedge w = RandomWedge(rng, GetParam());
    const WedgeHull h = MakeWedgeHull(w);
    // Boxes beyond the bounding box, and boxes beyond a face plane.
    const int axis = iter % 3;
    Eigen::AlignedBox3d far = h.box;
    far.min()[axis] = h.box.max()[axis] + 0.001 + u(rng);
    far.max()[axis] = far.min()[axis] + u(rng);
    EXPECT_FALSE(HullIntersectsBox(h, far));
    for (const Eigen::Vector4d& q : h.planes) {
      const Vector3d n = q.head<3>();
      const Vector3d x = n * (q[3] + 0.01);  // a point 1 cm beyond the plane
      const double half = 0.004 / std::sqrt(3.0);
      EXPECT_FALSE(HullIntersectsBox(
          h, {x - Vector3d::Constant(half), x + Vector3d::Constant(half)}));
    }
  }
}

// chunk_binning and the worker's descent rely on it: a box containing an intersecting box
// intersects too.
TEST_P(WedgeHullFuzzTest, MonotoneInTheBox) {
  std::mt19937_64 rng(7 + int(GetParam()));
  std::uniform_real_distribution<double> u(0, 1);
  for (int iter = 0; iter < 200; ++iter) {
    const WedgeHull h = MakeWedgeHull(RandomWedge(rng, GetParam()));
    for (int j = 0; j < 100; ++j) {
      const Vector3d c = h.box.center() + 0.7 * h.box.sizes().cwiseProduct(
                                                    Vector3d(u(rng), u(rng), u(rng)) -
                                                    Vector3d::Constant(0.5));
      const Eigen::AlignedBox3d small = BoxAround(c, rng);
      Eigen::AlignedBox3d big = small;
      big.extend(BoxAround(c, rng));
      if (HullIntersectsBox(h, small)) {
        ASSERT_TRUE(HullIntersectsBox(h, big));
      }
    }
  }
}

// The re-carve skips a wedge whose points' box meets no region, without building its hull:
// that box must hold the hull's, flat and collinear hulls (widened 1 mm) included.
TEST_P(WedgeHullFuzzTest, PointsBoxHoldsTheHull) {
  if (GetParam() == Kind::kSingle) GTEST_SKIP() << "single rays are widened by their σ";
  std::mt19937_64 rng(31 + int(GetParam()));
  for (int iter = 0; iter < 300; ++iter) {
    const Wedge w = RandomWedge(rng, GetParam());
    std::array<Vector3d, 4> s, e;
    for (int r = 0; r < w.num_rays; ++r) {
      s[r] = w.rays[r].sensor_mean.cast<double>();
      e[r] = ExtendedPointMean(w.rays[r], 3.0);
    }
    const size_t n = size_t(w.num_rays);
    const WedgeHull h = HullOfWedgePoints({s.data(), n}, {e.data(), n});
    const Eigen::AlignedBox3d box = WedgePointsBox({s.data(), n}, {e.data(), n});
    ASSERT_TRUE(box.contains(h.box)) << iter;
    // Not much larger: 2 mm around the points.
    Eigen::AlignedBox3d points;
    for (size_t r = 0; r < n; ++r) points.extend(s[r]).extend(e[r]);
    EXPECT_LE((box.max() - points.max()).maxCoeff(), 2.001e-3);
  }
}

INSTANTIATE_TEST_SUITE_P(Kinds, WedgeHullFuzzTest,
                         ::testing::Values(Kind::kGeneric, Kind::kSharedSensor, Kind::kFlat,
                                           Kind::kCollinear, Kind::kSingle, Kind::kTwoRays,
                                           Kind::kZeroLength));

// The coordinator sends each wedge's facet triples; the worker's hull from them is the same,
// plane for plane. A hint naming a non-facet is ignored; one missing a facet only loosens.
TEST(WedgeHullTest, FacetHintRebuildsTheSameHull) {
  std::mt19937_64 rng(42);
  int hinted = 0;
  for (int iter = 0; iter < 300; ++iter) {
    const Wedge w = RandomWedge(rng, iter % 2 ? Kind::kGeneric : Kind::kSharedSensor);
    uint64_t facets = 0;
    const WedgeHull searched = MakeWedgeHull(w, 3.0, &facets);
    if (facets == 0) continue;
    ++hinted;
    uint64_t hint = facets;
    const WedgeHull replayed = MakeWedgeHull(w, 3.0, &hint);
    EXPECT_EQ(hint, facets);
    ASSERT_EQ(replayed.planes.size(), searched.planes.size());
    for (size_t i = 0; i < searched.planes.size(); ++i) {
      EXPECT_EQ(replayed.planes[i], searched.planes[i]);
    }
    EXPECT_EQ(replayed.box.min(), searched.box.min());
    EXPECT_EQ(replayed.box.max(), searched.box.max());
    // A bit for a triple that is not a facet: the hint is dropped, the hull searched.
    for (int t = 0; t < 56; ++t) {
      if (facets >> t & 1) continue;
      uint64_t bad = facets | uint64_t{1} << t;
      const WedgeHull h = MakeWedgeHull(w, 3.0, &bad);
      EXPECT_EQ(h.planes.size(), searched.planes.size());
      break;
    }
    // A facet missing: still every point of the wedge inside.
    uint64_t fewer = facets & (facets - 1);
    const WedgeHull loose = MakeWedgeHull(w, 3.0, &fewer);
    for (const Vector3d& c : Corners(w, 3.0)) EXPECT_TRUE(HullContainsPoint(loose, c));
  }
  EXPECT_GT(hinted, 250);
}

TEST(WedgeHullTest, Timing) {
  std::mt19937_64 rng(5);
  std::vector<Wedge> wedges;
  for (int i = 0; i < 2000; ++i) wedges.push_back(RandomWedge(rng, Kind::kGeneric));
  auto t0 = std::chrono::steady_clock::now();
  std::vector<WedgeHull> hulls;
  for (const Wedge& w : wedges) hulls.push_back(MakeWedgeHull(w));
  auto t1 = std::chrono::steady_clock::now();
  size_t planes = 0, hits = 0;
  for (const WedgeHull& h : hulls) planes += h.planes.size();
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  std::vector<Eigen::AlignedBox3d> boxes;
  for (const WedgeHull& h : hulls) {
    for (int j = 0; j < 50; ++j) {
      const Vector3d c = h.box.center() + 1.5 * h.box.sizes().cwiseProduct(
                                                    Vector3d(u(rng), u(rng), u(rng)));
      boxes.emplace_back(c, c + Vector3d::Constant(0.0625));
    }
  }
  auto t2 = std::chrono::steady_clock::now();
  for (int rep = 0; rep < 10; ++rep) {
    for (size_t i = 0; i < boxes.size(); ++i) hits += HullIntersectsBox(hulls[i / 50], boxes[i]);
  }
  auto t3 = std::chrono::steady_clock::now();
  const double ns_hull = std::chrono::duration<double, std::nano>(t1 - t0).count() / hulls.size();
  const double ns_box =
      std::chrono::duration<double, std::nano>(t3 - t2).count() / (10.0 * boxes.size());
  std::printf("MakeWedgeHull %.0f ns, HullIntersectsBox %.1f ns/call, %.1f planes/hull, "
              "%.0f%% hits\n",
              ns_hull, ns_box, double(planes) / hulls.size(), 10.0 * hits / boxes.size());
  EXPECT_GT(hits, 0u);
}

TEST(WedgeGeometryTest, ValidateNamesTheBadRayAndField) {
  Wedge w;
  for (int r = 0; r < 4; ++r) {
    w.rays[r].sensor_mean = Eigen::Vector3f(0, 0, 0);
    w.rays[r].point_mean = Eigen::Vector3f(1, float(r), 0);
    w.rays[r].sensor_cov = {1e-4f, 0, 0, 1e-4f, 0, 1e-4f};
    w.rays[r].point_cov = {1e-4f, 0, 0, 1e-4f, 0, 1e-4f};
  }
  EXPECT_TRUE(ValidateWedge(w).ok());
  w.num_rays = 0;
  EXPECT_NE(ValidateWedge(w).message().find("num_rays 0"), std::string::npos);
  w.num_rays = 5;
  EXPECT_EQ(ValidateWedge(w).code(), absl::StatusCode::kInvalidArgument);
  w.num_rays = 4;
  w.rays[2].point_cov[3] = std::numeric_limits<float>::infinity();
  EXPECT_NE(ValidateWedge(w).message().find("ray 2 has a non-finite point_cov"),
            std::string::npos);
  w.num_rays = 2;  // unused rays are not checked
  EXPECT_TRUE(ValidateWedge(w).ok());
}

}  // namespace
}  // namespace carvemap
