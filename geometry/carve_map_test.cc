#include "geometry/carve_map.h"

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

// A 5 m ray along +x from the origin: sensor σ 2 cm, point σ 5 cm (isotropic).
RayModel AxisRay() {
  RayModel r;
  r.sensor_mean = Eigen::Vector3f(0, 0, 0);
  r.point_mean = Eigen::Vector3f(5, 0, 0);
  r.sensor_cov = ToSymCov(Matrix3d::Identity() * 0.02 * 0.02);
  r.point_cov = ToSymCov(Matrix3d::Identity() * 0.05 * 0.05);
  return r;
}

// A ray with random means and random SPD covariances.
RayModel RandomRay(std::mt19937& rng) {
  std::uniform_real_distribution<double> pos(-20, 20), u(-1, 1), sig(0.005, 0.3);
  auto spd = [&] {
    Matrix3d a;
    for (int i = 0; i < 9; ++i) a(i) = u(rng);
    return Matrix3d(a * a.transpose() * sig(rng) * sig(rng) + 1e-6 * Matrix3d::Identity());
  };
  RayModel r;
  r.sensor_mean = Vector3d(pos(rng), pos(rng), pos(rng)).cast<float>();
  r.point_mean = (r.sensor_mean.cast<double>() + Vector3d(u(rng), u(rng), u(rng)) * 15).cast<float>();
  r.sensor_cov = ToSymCov(spd());
  r.point_cov = ToSymCov(spd());
  return r;
}

TEST(CarveMapTest, PrepareComputesTheMarginals) {
  RayModel r = AxisRay();
  Matrix3d Cp = Matrix3d::Zero();
  Cp.diagonal() << 0.09, 0.01, 0.04;
  r.point_cov = ToSymCov(Cp);
  absl::StatusOr<PreparedRay> pr = PreparedRay::Make(r);
  ASSERT_TRUE(pr.ok()) << pr.status();
  EXPECT_NEAR(pr->length(), 5.0, 1e-6);
  EXPECT_NEAR((pr->direction() - Vector3d::UnitX()).norm(), 0, 1e-9);
  EXPECT_NEAR(pr->sensor_sigma_along(), 0.02, 1e-7);
  EXPECT_NEAR(pr->point_sigma_along(), 0.3, 1e-7);
}

TEST(CarveMapTest, InteriorAlongTheRayExteriorJustPastThePoint) {
  const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(AxisRay());
  ASSERT_TRUE(pr.ok());
  // Along the ray between a few σ in front of the sensor and a few σ before the point.
  for (double x = 0.1; x <= 4.8; x += 0.1) {
    const CarveSample s = pr->Evaluate(Vector3d(x, 0, 0));
    EXPECT_GT(s.p, 0.99) << x;
    EXPECT_DOUBLE_EQ(s.w, 1.0);
  }
  // At the sensor's mean F_s = 1/2; at the point's mean 1 − F_p = 1/2.
  EXPECT_NEAR(pr->Evaluate(Vector3d(0, 0, 0)).p, 0.5, 1e-9);
  EXPECT_NEAR(pr->Evaluate(Vector3d(5, 0, 0)).p, 0.5, 1e-6);
  // Just past the point (2σ): exterior, and deep past it p → 0.
  EXPECT_LT(pr->Evaluate(Vector3d(5.1, 0, 0)).p, 0.05);
  EXPECT_LT(pr->Evaluate(Vector3d(5.3, 0, 0)).p, 1e-6);
  // Eq 4.7 read literally also calls the axis behind the sensor exterior (F_s → 0 there).
  EXPECT_LT(pr->Evaluate(Vector3d(-0.1, 0, 0)).p, 0.5);
}

TEST(CarveMapTest, FarFromTheRayIsUnknownWithNoWeight) {
  const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(AxisRay());
  ASSERT_TRUE(pr.ok());
  for (const Vector3d& x : {Vector3d(2, 1, 0), Vector3d(2, 0, -3), Vector3d(6, 2, 2),
                            Vector3d(-1, 0.5, 0.5)}) {
    const CarveSample s = pr->Evaluate(x);
    EXPECT_NEAR(s.p, 0.5, 1e-9) << x.transpose();
    EXPECT_LT(s.w, 1e-9) << x.transpose();
  }
}

TEST(CarveMapTest, LateralWidthBlendsFromSensorToPoint) {
  const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(AxisRay());
  ASSERT_TRUE(pr.ok());
  // |x_⊥| = σ_⊥ gives f_⊥ = e^(−1/2): σ_⊥ = 2 cm at the sensor, 5 cm at the point, and at
  // mid-ray C* = (C_s + C_p)/2.
  const double mid = std::sqrt(0.5 * (0.02 * 0.02 + 0.05 * 0.05));
  EXPECT_NEAR(pr->Evaluate(Vector3d(0, 0.02, 0)).w, std::exp(-0.5), 1e-6);
  EXPECT_NEAR(pr->Evaluate(Vector3d(5, 0, -0.05)).w, std::exp(-0.5), 1e-6);
  EXPECT_NEAR(pr->Evaluate(Vector3d(2.5, mid * 0.6, mid * 0.8)).w, std::exp(-0.5), 1e-6);
  // f is clamped: beyond the point the width stays the point's, behind the sensor the sensor's.
  EXPECT_NEAR(pr->Evaluate(Vector3d(7, 0.05, 0)).w, std::exp(-0.5), 1e-6);
  EXPECT_NEAR(pr->Evaluate(Vector3d(-1, 0.02, 0)).w, std::exp(-0.5), 1e-6);
}

TEST(CarveMapTest, AnisotropicLateralCovariance) {
  RayModel r = AxisRay();
  Matrix3d C = Matrix3d::Zero();
  C.diagonal() << 0.01, 0.04, 0.0001;  // σ_y = 0.2 m, σ_z = 0.01 m
  r.sensor_cov = ToSymCov(C);
  r.point_cov = ToSymCov(C);
  const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(r);
  ASSERT_TRUE(pr.ok());
  EXPECT_NEAR(pr->Evaluate(Vector3d(1, 0.2, 0)).w, std::exp(-0.5), 1e-6);
  EXPECT_NEAR(pr->Evaluate(Vector3d(1, 0, 0.01)).w, std::exp(-0.5), 1e-5);
  // f_⊥ is the lateral Gaussian's density: e^(−1/2) on its whole 1σ ellipse, not only on the
  // axes (the density of the projection onto u would give (0.04 + 0.0001)/2 on the diagonal).
  for (double phi = 0; phi < 6.3; phi += 0.3) {
    EXPECT_NEAR(pr->Evaluate(Vector3d(1, 0.2 * std::cos(phi), 0.01 * std::sin(phi))).w,
                std::exp(-0.5), 1e-5)
        << phi;
  }
  // Half a σ along the wide axis and 25 σ off the narrow one: no weight (the projection form
  // gives e^(−6.5) here, and e^(−0.13) ≈ 0.88 at (0.1, 0.01)).
  EXPECT_LT(pr->Evaluate(Vector3d(1, 0.1, 0.25)).w, 1e-100);
  EXPECT_NEAR(pr->Evaluate(Vector3d(1, 0.1, 0.01)).w, std::exp(-0.5 * (0.25 + 1)), 1e-5);
}

// A ray meets the plane x + z = 5 at 45° (the point (5, 0, 0)), with the point spread along that
// plane as the sampling term spreads it (SamplingCovariance): σ 10 cm within the plane, 1 mm
// across it.
RayModel RayOntoTiltedPlane() {
  RayModel r = AxisRay();
  const Vector3d n = Vector3d(1, 0, 1).normalized();
  const Matrix3d in_plane = Matrix3d::Identity() - n * n.transpose();
  r.sensor_cov = ToSymCov(Matrix3d::Identity() * 1e-6);
  r.point_cov = ToSymCov(0.01 * in_plane + 1e-6 * Matrix3d::Identity());
  return r;
}

TEST(CarveMapTest, RangeGivenLateralFollowsTheSurface) {
  const RayModel r = RayOntoTiltedPlane();
  const RangeGivenLateral g = PointRangeGivenLateral(ToMatrix(r.point_cov), Vector3d::UnitX());
  // On the plane x = 5 − z: an offset z across the ray moves the surface's range by −z.
  EXPECT_NEAR(g.k.x(), 0, 1e-9);
  EXPECT_NEAR(g.k.y(), 0, 1e-6);
  EXPECT_NEAR(g.k.z(), -1, 1e-3);
  // Across the plane σ is 1 mm; along the ray that is 1 mm / cos 45°.
  EXPECT_NEAR(g.sigma, 0.001 * std::sqrt(2.0), 1e-5);
  // The marginal along the ray would be 7 cm.
  EXPECT_GT(std::sqrt(ToMatrix(r.point_cov)(0, 0)), 0.07);
  // No inverse: the marginal.
  Matrix3d along = Matrix3d::Zero();
  along(0, 0) = 0.04;
  const RangeGivenLateral m = PointRangeGivenLateral(along, Vector3d::UnitX());
  EXPECT_EQ(m.k, Vector3d::Zero());
  EXPECT_NEAR(m.sigma, 0.2, 1e-12);
}

TEST(CarveMapTest, SpreadRayCarvesUpToTheSurfaceBesideIt) {
  const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(RayOntoTiltedPlane());
  ASSERT_TRUE(pr.ok());
  // 5 cm beside the ray across the plane's trace (where the spread, seen across the ray, is
  // 10 cm·cos 45° = 7 cm), 3 cm in front of and behind the plane: the plane is at x = 4.95 for
  // z = 0.05 and at x = 5.05 for z = −0.05.
  for (const double z : {0.05, -0.05}) {
    const double surface_x = 5 - z;
    const CarveSample front = pr->Evaluate(Vector3d(surface_x - 0.03, 0, z));
    const CarveSample behind = pr->Evaluate(Vector3d(surface_x + 0.03, 0, z));
    EXPECT_GT(front.p, 0.75) << z;
    EXPECT_LT(behind.p, 0.25) << z;
    EXPECT_NEAR(front.w, std::exp(-0.5 * 0.05 * 0.05 / 0.005), 0.02) << z;
  }
  // Along y the plane does not move: the surface stays at x = 5.
  EXPECT_GT(pr->Evaluate(Vector3d(4.97, 0.1, 0)).p, 0.75);
  EXPECT_LT(pr->Evaluate(Vector3d(5.03, 0.1, 0)).p, 0.25);
}

TEST(CarveMapTest, WeightFallsOffMonotonicallyLaterally) {
  std::mt19937 rng(11);
  for (int k = 0; k < 50; ++k) {
    const RayModel r = RandomRay(rng);
    const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(r);
    ASSERT_TRUE(pr.ok());
    std::uniform_real_distribution<double> along(-0.2, 1.2), u(-1, 1);
    const double x_par = along(rng) * pr->length();
    Vector3d dir = Vector3d(u(rng), u(rng), u(rng));
    dir -= dir.dot(pr->direction()) * pr->direction();
    dir.normalize();
    double prev_w = 1.0, prev_dev = 0.5;
    for (double dist = 0; dist < 3.0; dist += 0.01) {
      const CarveSample s = pr->Evaluate(pr->origin() + x_par * pr->direction() + dist * dir);
      EXPECT_LE(s.w, prev_w + 1e-12);
      // And p moves towards 0.5 as the weight fades.
      EXPECT_LE(std::abs(s.p - 0.5), prev_dev + 1e-12);
      prev_w = s.w;
      prev_dev = std::abs(s.p - 0.5);
    }
  }
}

TEST(CarveMapTest, ValuesStayInTheUnitInterval) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> pos(-40, 40);
  for (int k = 0; k < 200; ++k) {
    const RayModel r = RandomRay(rng);
    const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(r);
    ASSERT_TRUE(pr.ok());
    for (int i = 0; i < 500; ++i) {
      // Half the queries near the ray, where the interesting values are.
      Vector3d x(pos(rng), pos(rng), pos(rng));
      if (i % 2) {
        std::uniform_real_distribution<double> t(-0.3, 1.3), n(-0.3, 0.3);
        x = pr->origin() + t(rng) * pr->length() * pr->direction() + Vector3d(n(rng), n(rng), n(rng));
      }
      const CarveSample s = pr->Evaluate(x);
      ASSERT_TRUE(s.p >= 0.0 && s.p <= 1.0) << s.p;
      ASSERT_TRUE(s.w >= 0.0 && s.w <= 1.0) << s.w;
    }
  }
}

TEST(CarveMapTest, InvariantUnderRigidMotionOfTheWholeSetup) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int k = 0; k < 30; ++k) {
    const RayModel r = RandomRay(rng);
    const Matrix3d R =
        Eigen::AngleAxisd(3 * u(rng), Vector3d(u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
    const Vector3d t(5 * u(rng), 5 * u(rng), 5 * u(rng));
    RayModel moved;
    moved.sensor_mean = (R * r.sensor_mean.cast<double>() + t).cast<float>();
    moved.point_mean = (R * r.point_mean.cast<double>() + t).cast<float>();
    moved.sensor_cov = ToSymCov(R * ToMatrix(r.sensor_cov) * R.transpose());
    moved.point_cov = ToSymCov(R * ToMatrix(r.point_cov) * R.transpose());
    const absl::StatusOr<PreparedRay> a = PreparedRay::Make(r);
    const absl::StatusOr<PreparedRay> b = PreparedRay::Make(moved);
    ASSERT_TRUE(a.ok() && b.ok());
    for (int i = 0; i < 100; ++i) {
      const double f = 1.4 * (u(rng) + 1) / 2 - 0.2;
      const Vector3d x = a->origin() + f * a->length() * a->direction() +
                         0.3 * Vector3d(u(rng), u(rng), u(rng));
      const CarveSample sa = a->Evaluate(x);
      const CarveSample sb = b->Evaluate(R * x + t);
      // Float storage of the moved means/covariances limits agreement.
      EXPECT_NEAR(sa.p, sb.p, 2e-3);
      EXPECT_NEAR(sa.w, sb.w, 2e-3);
    }
  }
}

TEST(CarveMapTest, DegenerateRaysCarveNothing) {
  RayModel r = AxisRay();
  r.point_mean = r.sensor_mean;
  EXPECT_EQ(PreparedRay::Make(r).status().code(), absl::StatusCode::kInvalidArgument);
  const CarveSample s = EvaluateCarveMap(r, Vector3d(0, 0, 0));
  EXPECT_EQ(s.p, 0.5);
  EXPECT_EQ(s.w, 0.0);
  r = AxisRay();
  r.point_cov[0] = NAN;
  EXPECT_FALSE(PreparedRay::Make(r).ok());
}

TEST(CarveMapTest, ZeroCovarianceIsAStepNotANaN) {
  RayModel r = AxisRay();
  r.sensor_cov = {};
  r.point_cov = {};
  const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(r);
  ASSERT_TRUE(pr.ok());
  EXPECT_NEAR(pr->Evaluate(Vector3d(2, 0, 0)).p, 1.0, 1e-12);
  EXPECT_NEAR(pr->Evaluate(Vector3d(6, 0, 0)).p, 0.0, 1e-12);
  const CarveSample off = pr->Evaluate(Vector3d(2, 0.001, 0));
  EXPECT_EQ(off.w, 0.0);
  EXPECT_EQ(off.p, 0.5);
}

TEST(CarveMapTest, FusionIsTheWeightedMean) {
  // Eq 4.8: two rays voting on the same leaf centre.
  const RayModel r = AxisRay();
  const Vector3d x(2, 0.02, 0);
  const CarveSample a = EvaluateCarveMap(r, x);
  const CarveSample b = EvaluateCarveMap(r, Vector3d(5.1, 0, 0));
  LeafStats leaf;
  FuseInto(leaf, a);
  FuseInto(leaf, b);
  EXPECT_EQ(leaf.count, 2u);
  EXPECT_NEAR(leaf.p(), (a.p * a.w + b.p * b.w) / (a.w + b.w), 1e-12);
}

TEST(CarveMapTest, ExpNegIsExpToFourUlp) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 40);
  for (int i = 0; i < 200000; ++i) {
    const double x = i < 100 ? i * 0.5 : u(rng);
    const double want = std::exp(-x);
    EXPECT_NEAR(ExpNeg(x), want, 9e-16 * want) << x;
  }
  EXPECT_EQ(ExpNeg(0.0), 1.0);
  EXPECT_EQ(ExpNeg(800.0), 0.0);
  EXPECT_EQ(ExpNeg(720.0), 0.0);  // subnormal range: flushed
  EXPECT_TRUE(std::isnan(ExpNeg(NAN)));
}

TEST(CarveMapTest, EvaluateAlongARowIsEvaluateAtEachPoint) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1, 1);
  int with_weight = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const RayModel ray = RandomRay(rng);
    const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(ray);
    ASSERT_TRUE(pr.ok());
    // A row crossing the ray near its middle, along one axis, 0.05 m apart.
    const Vector3d mid = 0.5 * (ray.sensor_mean + ray.point_mean).cast<double>();
    const int axis = trial % 3;
    Vector3d step = Vector3d::Zero();
    step[axis] = 0.05;
    const Vector3d x0 = mid - 20 * step + Vector3d(u(rng), u(rng), u(rng)) * 0.05;
    pr->EvaluateAlong(x0, step, 0, 39, [&](int i, const CarveSample& s) {
      const CarveSample e = pr->Evaluate(x0 + i * step);
      EXPECT_NEAR(s.p, e.p, 1e-13);
      EXPECT_NEAR(s.w, e.w, 1e-13);
      with_weight += e.w > 1e-6;
    });
  }
  EXPECT_GT(with_weight, 500);
}

// The carver's batch: bit for bit what Evaluate gives, near the sensor and the point (erfc),
// on the ray (f_⊥ = 1), far from it (no weight) and in between.
TEST(CarveMapTest, EvaluateManyIsEvaluateBitForBit) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(-1, 1), t(-0.2, 1.2);
  size_t weighted = 0, erfc_region = 0, far = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const RayModel ray = trial % 3 == 0 ? AxisRay() : RandomRay(rng);
    const absl::StatusOr<PreparedRay> pr = PreparedRay::Make(ray);
    ASSERT_TRUE(pr.ok());
    const Vector3d s = ray.sensor_mean.cast<double>(), e = ray.point_mean.cast<double>();
    std::vector<Vector3d> xs;
    for (int i = 0; i < 37; ++i) {  // odd: the scalar tail too
      const double lateral = std::pow(10.0, -4 + 4 * (u(rng) + 1) / 2);
      Vector3d x = s + t(rng) * (e - s) + lateral * Vector3d(u(rng), u(rng), u(rng));
      if (i == 5) x = s + 0.5 * (e - s);  // on the ray
      xs.push_back(x);
    }
    std::vector<double> par, a, b;
    for (const Vector3d& x : xs) {
      const PreparedRay::Projection pj = pr->Project(x);
      par.push_back(pj.par);
      a.push_back(pj.a);
      b.push_back(pj.b);
    }
    std::vector<double> p(xs.size()), w(xs.size());
    pr->EvaluateMany(par.data(), a.data(), b.data(), xs.size(), p.data(), w.data());
    for (size_t i = 0; i < xs.size(); ++i) {
      const CarveSample want = pr->Evaluate(xs[i]);
      EXPECT_EQ(p[i], want.p) << trial << " " << i;
      EXPECT_EQ(w[i], want.w) << trial << " " << i;
      weighted += want.w > 1e-6;
      far += want.w == 0;
      erfc_region += want.w > 1e-6 && std::abs(want.p - 0.5 * (1 + want.w)) > 1e-6;
    }
  }
  EXPECT_GT(weighted, 1000u);
  EXPECT_GT(far, 300u);
  EXPECT_GT(erfc_region, 200u);
}

}  // namespace
}  // namespace carvemap
