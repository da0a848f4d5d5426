#include "geometry/pose.h"

#include <algorithm>
#include <cmath>

namespace carvemap {

Pose InterpolatePose(const Pose& a, const Pose& b, double u) {
  // Eigen's slerp takes the shorter arc (it flips the sign of b when a·b < 0).
  return Pose{a.rotation.slerp(u, b.rotation).normalized(),
              (1.0 - u) * a.translation + u * b.translation};
}

Pose PoseAtTime(std::span<const TimedPose> path, double t) {
  if (t <= path.front().t) return path.front().pose;
  if (t >= path.back().t) return path.back().pose;
  auto it = std::upper_bound(path.begin(), path.end(), t,
                             [](double v, const TimedPose& p) { return v < p.t; });
  const TimedPose& b = *it;
  const TimedPose& a = *(it - 1);
  const double dt = b.t - a.t;
  const double u = dt > 0 ? (t - a.t) / dt : 0.0;
  return InterpolatePose(a.pose, b.pose, u);
}

Eigen::Vector3d RotationLog(const Eigen::Quaterniond& q_in) {
  Eigen::Quaterniond q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Eigen::Vector3d v = q.vec();
  const double s = v.norm();
  if (s < 1e-12) return 2.0 * v;  // small-angle limit
  const double angle = 2.0 * std::atan2(s, q.w());
  return v * (angle / s);
}

Eigen::Quaterniond RotationExp(const Eigen::Vector3d& e) {
  const double angle = e.norm();
  if (angle < 1e-12) {
    return Eigen::Quaterniond(1.0, 0.5 * e.x(), 0.5 * e.y(), 0.5 * e.z()).normalized();
  }
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, e / angle));
}

}  // namespace carvemap
