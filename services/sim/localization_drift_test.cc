#include "services/sim/localization_drift.h"

#include <cmath>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

class DriftTest : public ::testing::Test {
 protected:
  void SetUp() override {
    for (int i = 0; i < 200000; ++i) times_.push_back(0.05 * (i + 1));  // 10000 s at 20 Hz
    err_ = SampleDrift(o_, times_, 42);
  }
  DriftOptions o_;
  std::vector<double> times_;
  std::vector<Eigen::Matrix<double, 6, 1>> err_;
};

TEST_F(DriftTest, StationaryStdDevs) {
  const std::array<double, 6> sigma = DriftSigmas(o_);
  for (int k = 0; k < 6; ++k) {
    double m = 0, v = 0;
    for (const auto& e : err_) m += e[k];
    m /= err_.size();
    for (const auto& e : err_) v += (e[k] - m) * (e[k] - m);
    const double expected = sigma[k];
    EXPECT_NEAR(std::sqrt(v / err_.size()), expected, 0.15 * expected) << "axis " << k;
  }
  EXPECT_NEAR(o_.sigma_yaw_rad, 0.5 * kDeg, 1e-12);
}

TEST_F(DriftTest, CorrelatedOverSeconds) {
  // Lag of 1 s = 20 samples: OU correlation e^{-1/30} ≈ 0.967.
  for (int k : {0, 1, 5}) {
    double sxy = 0, sxx = 0, syy = 0;
    for (size_t i = 0; i + 20 < err_.size(); ++i) {
      sxy += err_[i][k] * err_[i + 20][k];
      sxx += err_[i][k] * err_[i][k];
      syy += err_[i + 20][k] * err_[i + 20][k];
    }
    EXPECT_GT(sxy / std::sqrt(sxx * syy), 0.9) << "axis " << k;
  }
}

TEST_F(DriftTest, NormalizedErrorsAverageThree) {
  // e^T C^{-1} e with C from DriftCovariance, including the transient from e(0) = 0.
  double pos = 0, rot = 0;
  for (size_t i = 0; i < err_.size(); ++i) {
    const PathCovariance c = DriftCovariance(o_, times_[i]);
    pos += err_[i][0] * err_[i][0] / c[0] + err_[i][1] * err_[i][1] / c[3] +
           err_[i][2] * err_[i][2] / c[5];
    rot += err_[i][3] * err_[i][3] / c[6] + err_[i][4] * err_[i][4] / c[9] +
           err_[i][5] * err_[i][5] / c[11];
  }
  EXPECT_NEAR(pos / err_.size(), 3.0, 0.4);
  EXPECT_NEAR(rot / err_.size(), 3.0, 0.4);
}

TEST(Drift, CovarianceGrowsFromTheFloor) {
  DriftOptions o;
  const PathCovariance c0 = DriftCovariance(o, 0);
  EXPECT_NEAR(c0[0], o.floor_position_m * o.floor_position_m, 1e-9);
  EXPECT_EQ(c0[1], 0.0f);
  const PathCovariance c1 = DriftCovariance(o, 1e4);
  EXPECT_NEAR(c1[0], 0.01 + 1e-6, 1e-6);
  EXPECT_NEAR(c1[5], 0.0009 + 1e-6, 1e-6);
  const PathCovariance ch = DriftCovariance(o, o.tau_s);
  EXPECT_NEAR(ch[3], 0.01 * (1 - std::exp(-2.0)) + 1e-6, 1e-6);
}

TEST(Drift, ApplyAndDeterminism) {
  DriftOptions o;
  const std::vector<double> t = {1, 2, 3};
  EXPECT_EQ(SampleDrift(o, t, 5), SampleDrift(o, t, 5));
  EXPECT_NE(SampleDrift(o, t, 5), SampleDrift(o, t, 6));
  Pose truth{Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ())), {1, 2, 3}};
  Eigen::Matrix<double, 6, 1> e;
  e << 0.1, -0.2, 0.05, 0.0, 0.0, 0.01;
  const Pose est = ApplyDrift(truth, e);
  EXPECT_TRUE(est.translation.isApprox(Eigen::Vector3d(1.1, 1.8, 3.05)));
  EXPECT_TRUE(RotationLog(est.rotation * truth.rotation.conjugate())
                  .isApprox(Eigen::Vector3d(0, 0, 0.01), 1e-9));
}

}  // namespace
}  // namespace carvemap
