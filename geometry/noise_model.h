// The noise model of one scan ray (§4.1.1, eqs 4.1–4.6): the sensor position and the scan
// point as world-frame Gaussians N(μ_s, C_s) and N(μ_p, C_p), from the localization covariance
// of the system pose, the clock-sync error of the sensor and the sensor's range noise.
//
// Conventions (docs/DESIGN.md §3): the rotation covariance is over a world-frame rotation vector e
// with R_est = Exp(e)·R_true, so a world-frame lever arm v (from the system origin) moves by
// e × v = −[v]× e, whose covariance is [v]× C_R [v]×ᵀ. Angular velocities are world-frame
// too: R(t + δt) = Exp(ω δt)·R(t). Plain functions over Eigen types; no I/O, no logging.
#pragma once

#include <array>
#include <span>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/carving_types.h"
#include "geometry/pose.h"

namespace carvemap {

struct NoiseModelOptions {
  // Used when the scan has no /path_cov (docs/DESIGN.md §3 makes it optional): an isotropic
  // position std-dev (m) and rotation std-dev (rad) for every pose.
  double default_position_sigma_m = 0.05;
  double default_rotation_sigma_rad = 0.005;
  // An isotropic std-dev (m) added to both Gaussians. Noiseless data (simulations, imports
  // without covariances) would otherwise give singular covariances: a zero-width carve map
  // (eq 4.7 degenerates to steps, f_⊥ to 0/0) and zero-width wedges. 1 mm is far below any
  // leaf size (0.78 cm at the finest), so it never changes real data visibly.
  double covariance_floor_m = 0.001;

  // All values finite and >= 0.
  [[nodiscard]] absl::Status Validate() const;
};

// The localization covariance of the system pose at one time (§4.1.1).
struct PoseCovariance {
  Eigen::Matrix3d position = Eigen::Matrix3d::Zero();  // C_pose_T, m²
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Zero();  // C_pose_R, rad², world rotation vector
};

// Sensor parameters the noise model needs (a SensorInfo's extrinsics and noise attributes).
struct SensorNoiseParams {
  Eigen::Matrix3d R_s2c = Eigen::Matrix3d::Identity();  // sensor ➜ system rotation
  Eigen::Vector3d T_s2c = Eigen::Vector3d::Zero();      // sensor ➜ system translation, m
  double sigma_t_s = 0.0;                               // clock-sync std-dev, s
  double range_sigma_a_m = 0.0;                         // range std-dev = a + b·range, m
  double range_sigma_b = 0.0;
};

// A world-frame Gaussian in double precision.
struct Gaussian3d {
  Eigen::Vector3d mean;  // m
  Eigen::Matrix3d cov;   // m²
};

// The cross-product matrix [v]×, with [v]× w = v × w.
[[nodiscard]] Eigen::Matrix3d CrossMatrix(const Eigen::Vector3d& v);

// Eqs 4.1/4.2: C_T + [v]× C_R [v]×ᵀ for a world-frame lever arm v from the system origin.
[[nodiscard]] Eigen::Matrix3d PoseCovarianceAt(const PoseCovariance& cov,
                                               const Eigen::Vector3d& lever_world);
// Eqs 4.3/4.4: [v]× (σ_t² ω ωᵀ) [v]×ᵀ, ω the world-frame angular velocity (rad/s).
[[nodiscard]] Eigen::Matrix3d TimestampCovariance(const Eigen::Vector3d& lever_world,
                                                  const Eigen::Vector3d& omega_world,
                                                  double sigma_t_s);
// C_noise of eq 4.6: σ_r² d dᵀ along the unit ray direction d (range noise only moves the
// point along its ray).
[[nodiscard]] Eigen::Matrix3d RangeCovariance(const Eigen::Vector3d& unit_dir_world,
                                              double sigma_r_m);

// The sampling term of a ray's point covariance (§4.2.1): a wedge's rays stand for the surface
// between them, so each ray's point is spread over its share of the surface up to its
// neighbours' points. Without it a ray is only as wide as its pose covariance: with noiseless or
// well-localized data (1 mm) and rays 5–10 cm apart, eq 4.8's weights between the rays of a
// wedge vanish and the carve is a speckle of unobserved leaves.
//   C = share · Σ_axes mean_{k ∈ axis} (p_k − p)(p_k − p)ᵀ
// over the neighbours' points p_k along each scan axis (in-frame, frame-to-frame); share = 1/12
// is the variance of a uniform spread over the gap. The spread lies in the surface through the
// points (it is not made lateral to the ray): eq 4.7's F_p, taken conditional on the lateral
// offset (carve_map.h), then follows that surface, so the spread carves beside the ray up to
// the surface and not behind it, even at grazing incidence. Empty axes contribute nothing.
[[nodiscard]] Eigen::Matrix3d SamplingCovariance(const Eigen::Vector3d& point,
                                                 std::span<const Eigen::Vector3d> axis_a,
                                                 std::span<const Eigen::Vector3d> axis_b,
                                                 double share);

// C without its covariances between the unit direction d and the directions across it:
// (ddᵀ) C (ddᵀ) + P C P, P = I − ddᵀ. Eq 4.7 reads the point Gaussian of eqs 4.1–4.6 through
// its marginal along the ray (F_p) and its block across it (f_⊥). Taken conditional on the
// lateral offset (carve_map.h), F_p would also read the cross terms, and those of the pose
// terms do not describe the surface the ray meets: a rotation error moves the point across the
// lever arm from the system origin, which leans away from the ray by up to the sensor's height
// over the range, and tilted so, grazing rays carve above a ceiling. Only the sampling term
// (SamplingCovariance), added after this, tilts F_p along the surface.
[[nodiscard]] Eigen::Matrix3d AlongAndAcross(const Eigen::Matrix3d& c, const Eigen::Vector3d& d);

// The world-frame angular velocity at time t along a path sorted by ascending t, from the
// rotation log of the two poses around t: ω = Log(R_b·R_aᵀ)/(t_b − t_a). Times outside the
// path use its first/last segment; a path of fewer than two poses gives zero.
[[nodiscard]] Eigen::Vector3d AngularVelocityAt(std::span<const TimedPose> path, double t);

// The pose covariance at time t: the rows of /path_cov (one per pose of `path`, layout of
// PathCovariance: position xx xy xz yy yz zz, then rotation, same order) interpolated linearly
// between the two poses around t (clamped at the ends). An empty `path_cov` gives the option
// defaults. Errors: InvalidArgument when sizes differ or the path is empty.
[[nodiscard]] absl::StatusOr<PoseCovariance> PoseCovarianceAtTime(
    std::span<const TimedPose> path, std::span<const std::array<float, 12>> path_cov, double t,
    const NoiseModelOptions& options);
[[nodiscard]] PoseCovariance DefaultPoseCovariance(const NoiseModelOptions& options);

// Everything the rays of one frame share, computed once per frame: the sensor Gaussian (eq 4.5,
// identical for all rays of a frame since they share one timestamp) and the terms of eq 4.6
// that only depend on the pose. Ray() then costs a few 3×3 products per ray.
// REQUIRES: options.Validate().ok().
class FrameNoiseModel {
 public:
  FrameNoiseModel(const Pose& pose_world_sys, const PoseCovariance& cov,
                  const Eigen::Vector3d& omega_world, const SensorNoiseParams& sensor,
                  const NoiseModelOptions& options);

  // The ray to `point_sensor` (sensor frame, m; finite). Eq 4.6 with lever arm
  // v_p = point_world − system position and range = |point_sensor|.
  [[nodiscard]] RayModel Ray(const Eigen::Vector3d& point_sensor) const;

  [[nodiscard]] const Eigen::Vector3d& sensor_world() const { return sensor_world_; }
  [[nodiscard]] const Eigen::Matrix3d& sensor_cov() const { return sensor_cov_; }
  // The double-precision point Gaussian that Ray() rounds to floats.
  [[nodiscard]] Gaussian3d PointGaussian(const Eigen::Vector3d& point_sensor) const;

 private:
  Eigen::Matrix3d R_world_sensor_;
  Eigen::Vector3d system_world_;
  Eigen::Vector3d sensor_world_;
  Eigen::Matrix3d sensor_cov_;      // eq 4.5 plus the floor
  Eigen::Matrix3d position_cov_;    // C_pose_T plus the floor
  Eigen::Matrix3d lever_cov_;       // C_pose_R + σ_t² ω ωᵀ: both are sandwiched by [v_p]×
  SymCov3f sensor_cov_f_;
  double range_sigma_a_m_;
  double range_sigma_b_;
};

// One ray without the per-frame cache (eqs 4.5 and 4.6).
[[nodiscard]] RayModel MakeRayModel(const Pose& pose_world_sys, const PoseCovariance& cov,
                                    const Eigen::Vector3d& omega_world,
                                    const SensorNoiseParams& sensor,
                                    const Eigen::Vector3d& point_sensor,
                                    const NoiseModelOptions& options);

}  // namespace carvemap
