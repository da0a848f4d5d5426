#include "services/sim/backpack_rig.h"

#include <cmath>

#include <Eigen/Geometry>

namespace carvemap {
namespace {
constexpr double kDeg = 3.14159265358979323846 / 180.0;
}

absl::Status RigOptions::Validate() const {
  if (!(rate_hz > 0 && rate_hz <= 1000)) {
    return absl::InvalidArgumentError("rig: rate_hz must be in (0, 1000]");
  }
  if (!(beam_step_deg >= 0.01 && beam_step_deg <= 45)) {
    return absl::InvalidArgumentError("rig: beam_step_deg must be in [0.01, 45]");
  }
  if (!(fov_deg > 0 && fov_deg <= 360)) {
    return absl::InvalidArgumentError("rig: fov_deg must be in (0, 360]");
  }
  if (!(max_range_m > 0.1)) return absl::InvalidArgumentError("rig: max_range_m must be > 0.1");
  return absl::OkStatus();
}

std::vector<LineScanner> MakeBackpackRig(const RigOptions& o) {
  const int beams = static_cast<int>(std::floor(o.fov_deg / o.beam_step_deg + 1e-9)) + 1;
  std::vector<Eigen::Vector3f> dirs(beams);
  for (int j = 0; j < beams; ++j) {
    const double a = (-0.5 * o.fov_deg + j * o.beam_step_deg) * kDeg;
    dirs[j] = Eigen::Vector3f(static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a)), 0);
  }
  // Vertical scanners: sensor x (mid-sweep) points up, sensor y to the system's left, so the
  // 90° blind wedge points down into the operator; the scan plane is across the walking
  // direction and then yawed so the planes sweep walls, floor and ceiling as he walks.
  Eigen::Matrix3d across;
  across.col(0) = Eigen::Vector3d::UnitZ();
  across.col(1) = Eigen::Vector3d::UnitY();
  across.col(2) = Eigen::Vector3d::UnitZ().cross(Eigen::Vector3d::UnitY());  // = -x
  const double period = 1.0 / o.rate_hz;
  auto make = [&](std::string name, const Eigen::Matrix3d& R, const Eigen::Vector3d& T,
                  int slot) {
    LineScanner s;
    s.name = std::move(name);
    s.T_system_sensor = Pose{Eigen::Quaterniond(R).normalized(), T};
    s.rate_hz = o.rate_hz;
    s.phase_s = period * (slot + 0.5) / 3.0;
    s.max_range_m = o.max_range_m;
    s.beams_sensor = dirs;
    return s;
  };
  const Eigen::Matrix3d yaw_l =
      Eigen::AngleAxisd(o.tilt_yaw_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Matrix3d yaw_r =
      Eigen::AngleAxisd(-o.tilt_yaw_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return {
      make("h_level", Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.12, 0.0, 0.20), 0),
      make("v_left", yaw_l * across, Eigen::Vector3d(-0.05, 0.18, 0.10), 1),
      make("v_right", yaw_r * across, Eigen::Vector3d(-0.05, -0.18, 0.10), 2),
  };
}

}  // namespace carvemap
