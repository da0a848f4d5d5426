#include "services/sim/localization_drift.h"

#include <cmath>
#include <random>

namespace carvemap {

absl::Status DriftOptions::Validate() const {
  for (double v : {sigma_xy_m, sigma_z_m, sigma_yaw_rad, sigma_roll_pitch_rad}) {
    if (!(v >= 0 && v < 10)) return absl::InvalidArgumentError("drift: sigmas must be in [0, 10)");
  }
  if (!(tau_s > 0)) return absl::InvalidArgumentError("drift: tau_s must be > 0");
  if (!(floor_position_m > 0 && floor_rotation_rad > 0)) {
    return absl::InvalidArgumentError("drift: covariance floors must be > 0");
  }
  return absl::OkStatus();
}

std::array<double, 6> DriftSigmas(const DriftOptions& o) {
  return {o.sigma_xy_m,           o.sigma_xy_m,           o.sigma_z_m,
          o.sigma_roll_pitch_rad, o.sigma_roll_pitch_rad, o.sigma_yaw_rad};
}

PathCovariance DriftCovariance(const DriftOptions& o, double t) {
  const std::array<double, 6> sigma = DriftSigmas(o);
  const double grow = 1.0 - std::exp(-2.0 * std::max(t, 0.0) / o.tau_s);
  PathCovariance c{};  // xx xy xz yy yz zz, then the same for rotation
  static constexpr int kDiag[3] = {0, 3, 5};
  for (int k = 0; k < 3; ++k) {
    const double fp = o.floor_position_m * o.floor_position_m;
    const double fr = o.floor_rotation_rad * o.floor_rotation_rad;
    c[kDiag[k]] = static_cast<float>(sigma[k] * sigma[k] * grow + fp);
    c[6 + kDiag[k]] = static_cast<float>(sigma[3 + k] * sigma[3 + k] * grow + fr);
  }
  return c;
}

std::vector<Eigen::Matrix<double, 6, 1>> SampleDrift(const DriftOptions& o,
                                                     std::span<const double> times,
                                                     uint64_t seed) {
  std::mt19937_64 rng(seed ^ 0xD1F7'5EED'0000'0001ull);
  std::normal_distribution<double> normal(0.0, 1.0);
  const std::array<double, 6> sigma = DriftSigmas(o);
  std::vector<Eigen::Matrix<double, 6, 1>> out(times.size());
  Eigen::Matrix<double, 6, 1> ou = Eigen::Matrix<double, 6, 1>::Zero();
  double t_prev = 0.0;
  for (size_t i = 0; i < times.size(); ++i) {
    // Exact OU step: x' = φx + σ√(1−φ²)·n keeps Var(t) = σ²(1 − e^{−2t/τ}) from x(0) = 0.
    const double phi = std::exp(-(times[i] - t_prev) / o.tau_s);
    const double q = std::sqrt(std::max(0.0, 1.0 - phi * phi));
    for (int k = 0; k < 6; ++k) ou[k] = phi * ou[k] + sigma[k] * q * normal(rng);
    out[i] = ou;
    t_prev = times[i];
  }
  return out;
}

Pose ApplyDrift(const Pose& truth, const Eigen::Matrix<double, 6, 1>& e) {
  Pose p;
  p.translation = truth.translation + e.head<3>();
  p.rotation = (RotationExp(e.tail<3>()) * truth.rotation).normalized();
  return p;
}

}  // namespace carvemap
