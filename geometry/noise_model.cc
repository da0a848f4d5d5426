#include "geometry/noise_model.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

absl::Status CheckNonNegative(const char* name, double v) {
  if (!std::isfinite(v) || v < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("noise_model options: ", name, " must be finite and >= 0, got ", v));
  }
  return absl::OkStatus();
}

PoseCovariance FromRow(const std::array<float, 12>& row) {
  PoseCovariance c;
  c.position = ToMatrix(SymCov3f{row[0], row[1], row[2], row[3], row[4], row[5]});
  c.rotation = ToMatrix(SymCov3f{row[6], row[7], row[8], row[9], row[10], row[11]});
  return c;
}

// The index of the segment [i, i+1] used for time t (clamped to the first/last segment).
// REQUIRES: path.size() >= 2.
size_t SegmentIndex(std::span<const TimedPose> path, double t) {
  auto it = std::upper_bound(path.begin(), path.end(), t,
                             [](double v, const TimedPose& p) { return v < p.t; });
  const size_t upper = static_cast<size_t>(it - path.begin());
  if (upper == 0) return 0;
  return std::min(upper - 1, path.size() - 2);
}

}  // namespace

absl::Status NoiseModelOptions::Validate() const {
  if (auto s = CheckNonNegative("default_position_sigma_m", default_position_sigma_m); !s.ok()) {
    return s;
  }
  if (auto s = CheckNonNegative("default_rotation_sigma_rad", default_rotation_sigma_rad);
      !s.ok()) {
    return s;
  }
  return CheckNonNegative("covariance_floor_m", covariance_floor_m);
}

Eigen::Matrix3d CrossMatrix(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(),  //
      v.z(), 0, -v.x(),   //
      -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d PoseCovarianceAt(const PoseCovariance& cov, const Eigen::Vector3d& lever_world) {
  const Eigen::Matrix3d vx = CrossMatrix(lever_world);
  return cov.position + vx * cov.rotation * vx.transpose();
}

Eigen::Matrix3d TimestampCovariance(const Eigen::Vector3d& lever_world,
                                    const Eigen::Vector3d& omega_world, double sigma_t_s) {
  // [v]× σ_t ω ωᵀ σ_t [v]×ᵀ = (σ_t v × ω)(σ_t v × ω)ᵀ: a rank-1 term along v × ω.
  const Eigen::Vector3d a = sigma_t_s * lever_world.cross(omega_world);
  return a * a.transpose();
}

Eigen::Matrix3d RangeCovariance(const Eigen::Vector3d& unit_dir_world, double sigma_r_m) {
  return (sigma_r_m * sigma_r_m) * unit_dir_world * unit_dir_world.transpose();
}

Eigen::Vector3d AngularVelocityAt(std::span<const TimedPose> path, double t) {
  if (path.size() < 2) return Eigen::Vector3d::Zero();
  const size_t i = SegmentIndex(path, t);
  const TimedPose& a = path[i];
  const TimedPose& b = path[i + 1];
  const double dt = b.t - a.t;
  if (!(dt > 0)) return Eigen::Vector3d::Zero();
  // World-frame increment: R_b = Exp(ω dt)·R_a, the convention of the rotation covariance.
  return RotationLog(b.pose.rotation * a.pose.rotation.conjugate()) / dt;
}

PoseCovariance DefaultPoseCovariance(const NoiseModelOptions& options) {
  PoseCovariance c;
  c.position = Eigen::Matrix3d::Identity() *
               (options.default_position_sigma_m * options.default_position_sigma_m);
  c.rotation = Eigen::Matrix3d::Identity() *
               (options.default_rotation_sigma_rad * options.default_rotation_sigma_rad);
  return c;
}

absl::StatusOr<PoseCovariance> PoseCovarianceAtTime(
    std::span<const TimedPose> path, std::span<const std::array<float, 12>> path_cov, double t,
    const NoiseModelOptions& options) {
  if (path_cov.empty()) return DefaultPoseCovariance(options);
  if (path.empty()) return absl::InvalidArgumentError("noise_model: empty path");
  if (path_cov.size() != path.size()) {
    return absl::InvalidArgumentError(absl::StrCat("noise_model: /path_cov has ", path_cov.size(),
                                                   " rows but /path has ", path.size()));
  }
  if (path.size() == 1 || t <= path.front().t) return FromRow(path_cov.front());
  if (t >= path.back().t) return FromRow(path_cov.back());
  const size_t i = SegmentIndex(path, t);
  const double dt = path[i + 1].t - path[i].t;
  const double u = dt > 0 ? (t - path[i].t) / dt : 0.0;
  // A convex combination of covariances stays positive semi-definite.
  const PoseCovariance a = FromRow(path_cov[i]);
  const PoseCovariance b = FromRow(path_cov[i + 1]);
  return PoseCovariance{(1 - u) * a.position + u * b.position,
                        (1 - u) * a.rotation + u * b.rotation};
}

FrameNoiseModel::FrameNoiseModel(const Pose& pose_world_sys, const PoseCovariance& cov,
                                 const Eigen::Vector3d& omega_world,
                                 const SensorNoiseParams& sensor,
                                 const NoiseModelOptions& options)
    : range_sigma_a_m_(sensor.range_sigma_a_m), range_sigma_b_(sensor.range_sigma_b) {
  const Eigen::Matrix3d R_world_sys = pose_world_sys.rotation.toRotationMatrix();
  R_world_sensor_ = R_world_sys * sensor.R_s2c;
  system_world_ = pose_world_sys.translation;
  const Eigen::Vector3d lever_sensor = R_world_sys * sensor.T_s2c;
  sensor_world_ = system_world_ + lever_sensor;

  const double floor2 = options.covariance_floor_m * options.covariance_floor_m;
  position_cov_ = cov.position + floor2 * Eigen::Matrix3d::Identity();
  const double st2 = sensor.sigma_t_s * sensor.sigma_t_s;
  // Eqs 4.1 + 4.3 (and 4.2 + 4.4) share the sandwich [v]× (·) [v]×ᵀ, so sum the middles once.
  lever_cov_ = cov.rotation + st2 * omega_world * omega_world.transpose();
  const Eigen::Matrix3d vx = CrossMatrix(lever_sensor);
  // Eq 4.5 = eq 4.1 + eq 4.3.
  sensor_cov_ = position_cov_ + vx * lever_cov_ * vx.transpose();
  sensor_cov_f_ = ToSymCov(sensor_cov_);
}

Gaussian3d FrameNoiseModel::PointGaussian(const Eigen::Vector3d& point_sensor) const {
  Gaussian3d g;
  const Eigen::Vector3d ray_world = R_world_sensor_ * point_sensor;
  g.mean = sensor_world_ + ray_world;
  const Eigen::Matrix3d vx = CrossMatrix(g.mean - system_world_);
  const double range = point_sensor.norm();
  const double sigma_r = range_sigma_a_m_ + range_sigma_b_ * range;
  // Eq 4.6 = eq 4.2 + eq 4.4 + C_noise.
  g.cov = position_cov_ + vx * lever_cov_ * vx.transpose();
  if (range > 0) g.cov += RangeCovariance(ray_world / range, sigma_r);
  return g;
}

Eigen::Matrix3d AlongAndAcross(const Eigen::Matrix3d& c, const Eigen::Vector3d& d) {
  const Eigen::Matrix3d along = d * d.transpose();
  const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - along;
  return along * c * along + across * c * across;
}

Eigen::Matrix3d SamplingCovariance(const Eigen::Vector3d& point,
                                   std::span<const Eigen::Vector3d> axis_a,
                                   std::span<const Eigen::Vector3d> axis_b, double share) {
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  for (std::span<const Eigen::Vector3d> axis : {axis_a, axis_b}) {
    if (axis.empty()) continue;
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (const Eigen::Vector3d& q : axis) sum += (q - point) * (q - point).transpose();
    c += sum / double(axis.size());
  }
  return share * c;
}

RayModel FrameNoiseModel::Ray(const Eigen::Vector3d& point_sensor) const {
  const Gaussian3d p = PointGaussian(point_sensor);
  RayModel r;
  r.sensor_mean = sensor_world_.cast<float>();
  r.point_mean = p.mean.cast<float>();
  r.sensor_cov = sensor_cov_f_;
  r.point_cov = ToSymCov(p.cov);
  return r;
}

RayModel MakeRayModel(const Pose& pose_world_sys, const PoseCovariance& cov,
                      const Eigen::Vector3d& omega_world, const SensorNoiseParams& sensor,
                      const Eigen::Vector3d& point_sensor, const NoiseModelOptions& options) {
  return FrameNoiseModel(pose_world_sys, cov, omega_world, sensor, options).Ray(point_sensor);
}

}  // namespace carvemap
