#include "geometry/noise_model.h"

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

// Options without the isotropic floor, so hand-computed covariances compare exactly.
NoiseModelOptions NoFloor() {
  NoiseModelOptions o;
  o.covariance_floor_m = 0.0;
  return o;
}

void ExpectMatrixNear(const Matrix3d& a, const Matrix3d& b, double tol) {
  EXPECT_LE((a - b).cwiseAbs().maxCoeff(), tol) << "got\n" << a << "\nexpected\n" << b;
}

TEST(NoiseModelTest, OptionsValidate) {
  EXPECT_TRUE(NoiseModelOptions{}.Validate().ok());
  NoiseModelOptions o;
  o.covariance_floor_m = -1;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
  o = {};
  o.default_rotation_sigma_rad = NAN;
  EXPECT_FALSE(o.Validate().ok());
}

TEST(NoiseModelTest, CrossMatrixIsTheCrossProduct) {
  const Vector3d v(1, -2, 3), w(0.5, 4, -1);
  EXPECT_NEAR((CrossMatrix(v) * w - v.cross(w)).norm(), 0, 1e-15);
}

TEST(NoiseModelTest, PureTranslationCovariancePassesThrough) {
  PoseCovariance cov;
  cov.position << 0.04, 0.01, 0, 0.01, 0.09, 0.002, 0, 0.002, 0.01;
  SensorNoiseParams sensor;  // at the system origin, no clock or range noise
  const Pose pose{Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Vector3d::UnitZ())), {5, 6, 1}};
  FrameNoiseModel model(pose, cov, Vector3d(0, 0, 3), sensor, NoFloor());
  ExpectMatrixNear(model.sensor_cov(), cov.position, 1e-15);
  const Gaussian3d p = model.PointGaussian(Vector3d(4, 1, 0));
  ExpectMatrixNear(p.cov, cov.position, 1e-15);
  EXPECT_NEAR((p.mean - (pose * Vector3d(4, 1, 0))).norm(), 0, 1e-12);
}

TEST(NoiseModelTest, LeverArmWithYawUncertaintyIsPerpendicular) {
  // 1 m arm along world x, yaw σ 0.01 rad: the sensor moves ±1 cm along y, not along the arm.
  PoseCovariance cov;
  cov.rotation(2, 2) = 1e-4;
  Matrix3d expected = Matrix3d::Zero();
  expected(1, 1) = 1e-4;
  ExpectMatrixNear(PoseCovarianceAt(cov, Vector3d(1, 0, 0)), expected, 1e-18);

  SensorNoiseParams sensor;
  sensor.T_s2c = Vector3d(1, 0, 0);
  FrameNoiseModel model(Pose{}, cov, Vector3d::Zero(), sensor, NoFloor());
  ExpectMatrixNear(model.sensor_cov(), expected, 1e-18);
  EXPECT_NEAR((model.sensor_world() - Vector3d(1, 0, 0)).norm(), 0, 1e-15);

  // The point's lever arm runs from the system origin: a point 2 m further along x has a 3 m
  // arm, so 9e-4 m² along y.
  const Gaussian3d p = model.PointGaussian(Vector3d(2, 0, 0));
  expected(1, 1) = 9e-4;
  ExpectMatrixNear(p.cov, expected, 1e-17);
}

TEST(NoiseModelTest, LeverArmIsInTheWorldFrame) {
  // The system is yawed 90°: the body-frame arm (1, 0, 0) points along world y, so yaw
  // uncertainty now moves the sensor along world x.
  PoseCovariance cov;
  cov.rotation(2, 2) = 1e-4;
  SensorNoiseParams sensor;
  sensor.T_s2c = Vector3d(1, 0, 0);
  const Pose pose{Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Vector3d::UnitZ())), {}};
  FrameNoiseModel model(pose, cov, Vector3d::Zero(), sensor, NoFloor());
  Matrix3d expected = Matrix3d::Zero();
  expected(0, 0) = 1e-4;
  ExpectMatrixNear(model.sensor_cov(), expected, 1e-17);
}

TEST(NoiseModelTest, RotationCovarianceMatchesSamplingTheConvention) {
  // docs/DESIGN.md §3: R_est = Exp(e)·R_true with e ~ N(0, C_R) in the world frame. Sample it and
  // compare the spread of a rigidly attached point with eq 4.2.
  Matrix3d C_R;
  C_R << 4e-4, 1e-4, 0, 1e-4, 1e-4, -5e-5, 0, -5e-5, 9e-4;
  const Eigen::LLT<Matrix3d> llt(C_R);
  const Matrix3d L = llt.matrixL();
  const Eigen::Quaterniond R_true(Eigen::AngleAxisd(0.8, Vector3d(1, 2, 3).normalized()));
  const Vector3d body(3, -1, 2);
  const Vector3d v = R_true * body;
  std::mt19937 rng(7);
  std::normal_distribution<double> n01;
  const int kSamples = 200000;
  Matrix3d emp = Matrix3d::Zero();
  for (int i = 0; i < kSamples; ++i) {
    const Vector3d e = L * Vector3d(n01(rng), n01(rng), n01(rng));
    const Vector3d d = RotationExp(e) * R_true * body - v;
    emp += d * d.transpose();
  }
  emp /= kSamples;
  PoseCovariance cov;
  cov.rotation = C_R;
  const Matrix3d model = PoseCovarianceAt(cov, v);
  // Sampling error ~ 1/sqrt(N) ≈ 0.2 % of entries of size ~1e-2; small-angle error smaller.
  EXPECT_LE((emp - model).cwiseAbs().maxCoeff(), 0.02 * model.cwiseAbs().maxCoeff());
}

TEST(NoiseModelTest, TimestampTermFollowsAngularVelocity) {
  // ω = 2 rad/s about z, σ_t = 1 ms, 1 m arm along x: the sensor smears along y by σ_t·|ω|·1 m.
  const Vector3d omega(0, 0, 2);
  Matrix3d expected = Matrix3d::Zero();
  expected(1, 1) = std::pow(0.001 * 2 * 1, 2);
  ExpectMatrixNear(TimestampCovariance(Vector3d(1, 0, 0), omega, 0.001), expected, 1e-20);
  // An arm along ω is not moved by the rotation.
  ExpectMatrixNear(TimestampCovariance(Vector3d(0, 0, 5), omega, 0.001), Matrix3d::Zero(), 0);

  SensorNoiseParams sensor;
  sensor.T_s2c = Vector3d(1, 0, 0);
  sensor.sigma_t_s = 0.001;
  FrameNoiseModel model(Pose{}, PoseCovariance{}, omega, sensor, NoFloor());
  ExpectMatrixNear(model.sensor_cov(), expected, 1e-20);
  // Point 9 m further along x: 10 m arm.
  expected(1, 1) = std::pow(0.001 * 2 * 10, 2);
  ExpectMatrixNear(model.PointGaussian(Vector3d(9, 0, 0)).cov, expected, 1e-18);
}

TEST(NoiseModelTest, RangeNoiseIsAlongTheRayOnly) {
  SensorNoiseParams sensor;
  sensor.range_sigma_a_m = 0.01;
  sensor.range_sigma_b = 0.001;
  // The sensor looks along its x, mounted pitched down 30° about system y; the system yaws 40°.
  sensor.R_s2c = Eigen::AngleAxisd(M_PI / 6, Vector3d::UnitY()).toRotationMatrix();
  sensor.T_s2c = Vector3d(0.2, 0, 1.5);
  const Pose pose{Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Vector3d::UnitZ())), {1, 2, 0}};
  FrameNoiseModel model(pose, PoseCovariance{}, Vector3d::Zero(), sensor, NoFloor());
  EXPECT_LE(model.sensor_cov().cwiseAbs().maxCoeff(), 0.0);  // range noise never moves the sensor
  const Gaussian3d g = model.PointGaussian(Vector3d(10, 0, 0));
  const Vector3d d = (g.mean - model.sensor_world()).normalized();
  const double sigma_r = 0.01 + 0.001 * 10;
  ExpectMatrixNear(g.cov, sigma_r * sigma_r * d * d.transpose(), 1e-17);
  EXPECT_NEAR(d.dot(g.cov * d), sigma_r * sigma_r, 1e-17);
  const Vector3d across = d.cross(Vector3d::UnitZ()).normalized();
  EXPECT_NEAR(across.dot(g.cov * across), 0.0, 1e-18);
}

TEST(NoiseModelTest, SamplingCovarianceIsTheShareOfTheGapsToTheNeighbours) {
  const Vector3d p(5, 0, 0);
  // In-frame neighbours 8 cm to either side along y; the previous frame's point 10 cm along z
  // and 2 cm further along x (the surface is tilted).
  const std::vector<Vector3d> along{{5, -0.08, 0}, {5, 0.08, 0}};
  const std::vector<Vector3d> across{{5.02, 0, 0.1}};
  const Matrix3d c = SamplingCovariance(p, along, across, 1.0 / 12);
  Matrix3d expected = Matrix3d::Zero();
  expected(1, 1) = 0.08 * 0.08 / 12;  // the mean of the two sides, not their sum
  const Vector3d o(0.02, 0, 0.1);
  expected += o * o.transpose() / 12;
  ExpectMatrixNear(c, expected, 1e-15);
  // It lies in the surface through the points: nothing along that surface's normal.
  const Vector3d normal = Vector3d(0, 1, 0).cross(o).normalized();
  EXPECT_NEAR(normal.dot(c * normal), 0.0, 1e-15);
  // No neighbours, no spread; share 0, no spread.
  ExpectMatrixNear(SamplingCovariance(p, {}, {}, 1.0 / 12), Matrix3d::Zero(), 0);
  ExpectMatrixNear(SamplingCovariance(p, along, across, 0), Matrix3d::Zero(), 0);
}

TEST(NoiseModelTest, AlongAndAcrossKeepsTheMarginalAndTheLateralBlock) {
  Matrix3d a;
  a << 1, 2, 0.5, -1, 3, 1, 0.2, 0.4, 2;
  const Matrix3d c = a * a.transpose();  // SPD, with cross terms in every direction
  const Vector3d d = Vector3d(1, 2, -1).normalized();
  const Matrix3d b = AlongAndAcross(c, d);
  EXPECT_NEAR(d.dot(b * d), d.dot(c * d), 1e-12);
  const Vector3d e1 = d.cross(Vector3d::UnitX()).normalized(), e2 = d.cross(e1);
  for (const Vector3d& u : {e1, e2}) {
    for (const Vector3d& v : {e1, e2}) EXPECT_NEAR(u.dot(b * v), u.dot(c * v), 1e-12);
    EXPECT_NEAR(d.dot(b * u), 0.0, 1e-12);
  }
  ExpectMatrixNear(b, b.transpose(), 1e-12);
}

TEST(NoiseModelTest, FloorKeepsNoiselessCovariancesPositiveDefinite) {
  NoiseModelOptions o;  // floor 1 mm
  FrameNoiseModel model(Pose{}, PoseCovariance{}, Vector3d::Zero(), SensorNoiseParams{}, o);
  ExpectMatrixNear(model.sensor_cov(), 1e-6 * Matrix3d::Identity(), 1e-20);
  const RayModel r = model.Ray(Vector3d(3, 0, 0));
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Matrix3d>(ToMatrix(r.point_cov)).eigenvalues().minCoeff(),
            0.9e-6);
  EXPECT_NEAR((r.point_mean - Eigen::Vector3f(3, 0, 0)).norm(), 0, 1e-6);
}

TEST(NoiseModelTest, MakeRayModelSumsAllTerms) {
  PoseCovariance cov;
  cov.position = 0.01 * Matrix3d::Identity();
  cov.rotation = 1e-4 * Matrix3d::Identity();
  SensorNoiseParams sensor;
  sensor.T_s2c = Vector3d(0, 0.5, 0);
  sensor.sigma_t_s = 0.002;
  sensor.range_sigma_a_m = 0.02;
  const Vector3d omega(0.5, 0, 1);
  const RayModel r = MakeRayModel(Pose{}, cov, omega, sensor, Vector3d(4, 0, 0), NoFloor());
  const Vector3d vs(0, 0.5, 0), vp(4, 0.5, 0);
  const Matrix3d Cs = PoseCovarianceAt(cov, vs) + TimestampCovariance(vs, omega, 0.002);
  const Matrix3d Cp = PoseCovarianceAt(cov, vp) + TimestampCovariance(vp, omega, 0.002) +
                      RangeCovariance(Vector3d::UnitX(), 0.02);
  ExpectMatrixNear(ToMatrix(r.sensor_cov), Cs, 1e-8);
  ExpectMatrixNear(ToMatrix(r.point_cov), Cp, 1e-8);
}

std::vector<TimedPose> SpinningPath(const Vector3d& omega, const Eigen::Quaterniond& start) {
  std::vector<TimedPose> path;
  for (int i = 0; i <= 10; ++i) {
    const double t = 100.0 + 0.1 * i;
    path.push_back({t, Pose{RotationExp(omega * (0.1 * i)) * start, Vector3d(i, 0, 0)}});
  }
  return path;
}

TEST(NoiseModelTest, AngularVelocityIsWorldFrame) {
  const Vector3d omega(0.3, -0.2, 1.5);
  // A tilted start orientation: a body-frame ω would differ from the world-frame one.
  const Eigen::Quaterniond start(Eigen::AngleAxisd(1.0, Vector3d(1, 1, 0).normalized()));
  const std::vector<TimedPose> path = SpinningPath(omega, start);
  for (double t : {100.0, 100.05, 100.37, 100.5, 101.0, 99.0, 105.0}) {
    EXPECT_NEAR((AngularVelocityAt(path, t) - omega).norm(), 0, 1e-9) << t;
  }
  EXPECT_EQ(AngularVelocityAt(std::span<const TimedPose>(path.data(), 1), 100.0),
            Vector3d::Zero());
}

TEST(NoiseModelTest, PoseCovarianceIsInterpolatedLinearly) {
  const std::vector<TimedPose> path = SpinningPath(Vector3d::Zero(), Eigen::Quaterniond::Identity());
  std::vector<std::array<float, 12>> rows(path.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    const float s = float(i);
    rows[i] = {s, 0, 0, 2 * s, 0, 0, 0.1f * s, 0, 0, 0.1f * s, 0, 0.2f * s};
  }
  const NoiseModelOptions o;
  absl::StatusOr<PoseCovariance> c = PoseCovarianceAtTime(path, rows, 100.25, o);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->position(0, 0), 2.5, 1e-6);
  EXPECT_NEAR(c->position(1, 1), 5.0, 1e-6);
  EXPECT_NEAR(c->rotation(2, 2), 0.5, 1e-6);
  EXPECT_NEAR(PoseCovarianceAtTime(path, rows, 50, o)->position(0, 0), 0.0, 0);
  EXPECT_NEAR(PoseCovarianceAtTime(path, rows, 500, o)->position(0, 0), 10.0, 1e-6);

  // Without /path_cov: the defaults.
  c = PoseCovarianceAtTime(path, {}, 100.25, o);
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR(c->position(2, 2), 0.05 * 0.05, 1e-15);
  EXPECT_NEAR(c->rotation(0, 0), 0.005 * 0.005, 1e-15);
  EXPECT_EQ(c->position(0, 1), 0.0);

  rows.pop_back();
  EXPECT_EQ(PoseCovarianceAtTime(path, rows, 100.25, o).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap
