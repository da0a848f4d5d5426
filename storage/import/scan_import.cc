#include "storage/import/scan_import.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace carvemap {

absl::Status EmitFrame(const FrameSink& sink, double t, std::span<const Eigen::Vector3f> points,
                       ImportedScan& scan) {
  if (sink) {
    if (absl::Status s = sink(t, points); !s.ok()) return s;
  } else {
    scan.frames.push_back(ImportedFrame{t, {points.begin(), points.end()}});
  }
  ++scan.frame_count;
  scan.point_count += points.size();
  return absl::OkStatus();
}

absl::StatusOr<Eigen::Vector4d> CheckedUnitQuaternion(double qw, double qx, double qy, double qz,
                                                      double tolerance) {
  const Eigen::Vector4d q(qw, qx, qy, qz);
  if (!q.allFinite()) return absl::InvalidArgumentError("non-finite quaternion");
  const double norm = q.norm();
  if (std::abs(norm - 1.0) > tolerance) {
    return absl::InvalidArgumentError(absl::StrCat("quaternion (w x y z) = (", qw, " ", qx, " ", qy,
                                                   " ", qz, ") has norm ", norm, ", not 1"));
  }
  return q / norm;
}

absl::Status ValidateCloudOptions(std::string_view command, double max_range_m,
                                  const std::array<double, 2>& range_sigma,
                                  const std::optional<Eigen::Vector3d>& shift) {
  const absl::string_view c(command.data(), command.size());
  if (!(max_range_m >= 0) || !std::isfinite(max_range_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat(c, ": --max-range ", max_range_m, " (need ≥ 0; 0: from the data)"));
  }
  if (!(range_sigma[0] >= 0) || !(range_sigma[1] >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(c, ": --range-sigma needs A ≥ 0 and B ≥ 0"));
  }
  if (shift && !shift->allFinite()) {
    return absl::InvalidArgumentError(absl::StrCat(c, ": --shift needs three finite numbers"));
  }
  return absl::OkStatus();
}

Eigen::Vector3d CloudShift(const std::optional<Eigen::Vector3d>& given,
                           const Eigen::Vector3d& first_position) {
  if (given) return *given;
  return Eigen::Vector3d(std::floor(first_position.x() / 1000) * 1000,
                         std::floor(first_position.y() / 1000) * 1000, 0);
}

}  // namespace carvemap
