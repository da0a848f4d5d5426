// Localization error of the backpack (§2.2: ~10 cm, errors of successive poses highly
// correlated; §4.1.1: a covariance per pose). Modelled as independent Ornstein–Uhlenbeck
// processes on the position error and on the world-frame rotation vector error, started at 0
// at t = 0 (a localizer's output is smooth: no white jitter). The reported covariance adds a
// small floor so it is never singular:
//   p_est = p_true + e_p,  R_est = Exp(e_r)·R_true  (docs/DESIGN.md §3).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "geometry/pose.h"
#include "storage/scan_types.h"

namespace carvemap {

struct DriftOptions {
  double sigma_xy_m = 0.10;            // stationary std-dev of x and y errors
  double sigma_z_m = 0.03;
  double sigma_yaw_rad = 0.5 * 3.14159265358979323846 / 180;
  double sigma_roll_pitch_rad = 0.2 * 3.14159265358979323846 / 180;
  double tau_s = 30.0;                 // correlation time
  double floor_position_m = 0.001;     // covariance floor, std-dev
  double floor_rotation_rad = 1e-4;    // covariance floor, std-dev
  [[nodiscard]] absl::Status Validate() const;
};

// Per-axis std-devs: position x y z, rotation x y z.
[[nodiscard]] std::array<double, 6> DriftSigmas(const DriftOptions& o);

// Covariance of the error at time t (diagonal): OU variance σ²(1 − e^{−2t/τ}) plus the floor.
[[nodiscard]] PathCovariance DriftCovariance(const DriftOptions& o, double t);

// One sample per time in `times` (ascending, >= 0): e = (e_p, e_r). Exact OU discretization,
// deterministic in `seed`.
[[nodiscard]] std::vector<Eigen::Matrix<double, 6, 1>> SampleDrift(const DriftOptions& o,
                                                                   std::span<const double> times,
                                                                   uint64_t seed);

// Applies an error to a true pose.
[[nodiscard]] Pose ApplyDrift(const Pose& truth, const Eigen::Matrix<double, 6, 1>& e);

}  // namespace carvemap
