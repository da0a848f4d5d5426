// Plain records of the carvemap-scan format (docs/DESIGN.md §3), as read and written.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace carvemap {

inline constexpr std::string_view kScanFormatName = "carvemap-scan";
inline constexpr int kScanFormatVersion = 1;

// One row of /path: the system pose in the world frame (ENU, z up) at time t (s).
struct PathRecord {
  double t, x, y, z;
  double qw, qx, qy, qz;
};

// One row of /path_cov: position covariance (xx xy xz yy yz zz, m²), then rotation covariance
// (same order, rad²) over a world-frame rotation vector e with R_est = Exp(e)·R_true.
using PathCovariance = std::array<float, 12>;

// The world frame turned by `yaw_rad` about the vertical through its origin (x = y = 0),
// counter-clockwise seen from above: a pose's position and orientation, and a covariance's
// two blocks (both over world-frame vectors: C' = R·C·Rᵀ). §2.3's north alignment.
void TurnAboutVertical(double yaw_rad, PathRecord& pose);
void TurnAboutVertical(double yaw_rad, PathCovariance& cov);

enum class SensorKind { kLine, kGrid, kPoints };
[[nodiscard]] std::string_view SensorKindName(SensorKind kind);  // "line", "grid", "points"

// A sensor group /sensors/<name> (its attributes).
struct SensorInfo {
  std::string name;
  SensorKind kind = SensorKind::kLine;
  uint32_t rows = 0, cols = 0;  // grid sensors only: a frame is rows×cols rays, row-major
  Eigen::Matrix3d R_s2c = Eigen::Matrix3d::Identity();  // sensor ➜ system rotation
  Eigen::Vector3d T_s2c = Eigen::Vector3d::Zero();      // sensor ➜ system translation, m
  double sigma_t_s = 0.0;                               // clock sync std-dev, s
  std::array<double, 2> range_sigma = {0.0, 0.0};       // std-dev = a + b·range, m
  double max_range_m = 30.0;
};

// What is wrong with a sensor's mounting and noise parameters (docs/DESIGN.md §3), or "" when
// nothing: every value finite, R_s2c a rotation (R·Rᵀ = I and det R = 1 within 1e-6),
// sigma_t and range_sigma not negative, max_range > 0. The writer refuses such a sensor and
// the reader such a file.
[[nodiscard]] std::string SensorParametersProblem(const SensorInfo& info);

// One row of /sensors/<name>/frames: rays [first, first+count) of the sensor's /points.
struct FrameRecord {
  double t;
  uint64_t first;
  uint32_t count;
};

// One row of /magnetometer.
struct MagnetometerRecord {
  double t, mx, my, mz;
};

// One frame as the reader streams it: the sensor index (into the reader's sensor list), the
// frame's row in its frames table, its time, and its ray end points in the sensor frame
// (NaN row = no return).
struct ScanFrame {
  int sensor = -1;
  uint64_t row = 0;
  double t = 0.0;
  std::vector<Eigen::Vector3f> points_sensor;
};

}  // namespace carvemap
