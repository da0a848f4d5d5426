#include "geometry/pose.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

TEST(PoseTest, ComposeAndInverse) {
  Pose a{Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
         Eigen::Vector3d(1, -2, 0.5)};
  Pose id = a * a.Inverse();
  EXPECT_NEAR((id * Eigen::Vector3d(3, 4, 5) - Eigen::Vector3d(3, 4, 5)).norm(), 0, 1e-12);
}

TEST(PoseTest, InterpolationIsLinearInPositionAndSlerpInRotation) {
  std::vector<TimedPose> path = {
      {0.0, Pose{Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0)}},
      {2.0, Pose{Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(2, 4, 0)}}};
  Pose mid = PoseAtTime(path, 0.5);
  EXPECT_NEAR((mid.translation - Eigen::Vector3d(0.5, 1, 0)).norm(), 0, 1e-12);
  // A quarter of the way through a 90° yaw is 22.5°, at constant angular rate.
  Eigen::AngleAxisd aa(mid.rotation);
  EXPECT_NEAR(aa.angle(), M_PI / 8, 1e-12);
  EXPECT_NEAR(aa.axis().z(), 1.0, 1e-12);
  // Clamped outside the path.
  EXPECT_NEAR((PoseAtTime(path, -1).translation).norm(), 0, 1e-12);
  EXPECT_NEAR((PoseAtTime(path, 9).translation - Eigen::Vector3d(2, 4, 0)).norm(), 0, 1e-12);
}

TEST(PoseTest, SlerpTakesTheShortArc) {
  Eigen::Quaterniond a(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()));
  Eigen::Quaterniond b(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  b.coeffs() = -b.coeffs();  // same rotation, other hemisphere
  Pose m = InterpolatePose(Pose{a, {}}, Pose{b, {}}, 0.5);
  EXPECT_NEAR(Eigen::AngleAxisd(m.rotation).angle(), 0.2, 1e-12);
}

TEST(PoseTest, ExpLogRoundTrip) {
  for (const Eigen::Vector3d& e : {Eigen::Vector3d(0.1, -0.2, 0.3), Eigen::Vector3d(1e-9, 0, 0),
                                  Eigen::Vector3d(0, 3.0, 0)}) {
    EXPECT_NEAR((RotationLog(RotationExp(e)) - e).norm(), 0, 1e-9) << e.transpose();
  }
}

}  // namespace
}  // namespace carvemap
