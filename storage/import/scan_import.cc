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
    return absl::InvalidArgumentError(
        absl::StrCat("quaternion (w x y z) = (", qw, " ", qx, " ", qy, " ", qz, ") has norm ",
                     norm, ", not 1"));
  }
  return q / norm;
}

}  // namespace carvemap
