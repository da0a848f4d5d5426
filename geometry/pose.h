// Rigid poses and their interpolation along a path (§2.2, §2.4).
#pragma once

#include <span>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace carvemap {

// A rigid transform T_world_body: x_world = rotation * x_body + translation.
struct Pose {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  [[nodiscard]] Eigen::Vector3d operator*(const Eigen::Vector3d& x) const {
    return rotation * x + translation;
  }
  // Composition: (a * b)(x) = a(b(x)).
  [[nodiscard]] Pose operator*(const Pose& b) const {
    return Pose{rotation * b.rotation, rotation * b.translation + translation};
  }
  [[nodiscard]] Pose Inverse() const {
    Eigen::Quaterniond inv = rotation.conjugate();
    return Pose{inv, -(inv * translation)};
  }
};

// A pose at a time stamp, as stored in /path.
struct TimedPose {
  double t = 0;  // s
  Pose pose;
};

// §2.4: position interpolated linearly, orientation by SLERP, with u in [0, 1] from a to b.
[[nodiscard]] Pose InterpolatePose(const Pose& a, const Pose& b, double u);

// The pose at time t along a path sorted by ascending t. Times outside [front.t, back.t] are
// clamped to the end poses. REQUIRES: path non-empty and sorted.
[[nodiscard]] Pose PoseAtTime(std::span<const TimedPose> path, double t);

// Rotation vector e with Exp(e) = q (the log map), |e| <= pi.
[[nodiscard]] Eigen::Vector3d RotationLog(const Eigen::Quaterniond& q);
// Exp map of a rotation vector.
[[nodiscard]] Eigen::Quaterniond RotationExp(const Eigen::Vector3d& e);

}  // namespace carvemap
