#include "storage/scan_types.h"

#include <cmath>
#include <sstream>

#include <Eigen/Geometry>

namespace carvemap {

void TurnAboutVertical(double yaw_rad, PathRecord& p) {
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()));
  const Eigen::Vector3d x = turn * Eigen::Vector3d(p.x, p.y, p.z);
  const Eigen::Quaterniond q = turn * Eigen::Quaterniond(p.qw, p.qx, p.qy, p.qz);
  p.x = x.x(), p.y = x.y(), p.z = x.z();
  p.qw = q.w(), p.qx = q.x(), p.qy = q.y(), p.qz = q.z();
}

void TurnAboutVertical(double yaw_rad, PathCovariance& c) {
  const Eigen::Matrix3d r = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (int block = 0; block < 2; ++block) {
    float* v = c.data() + 6 * block;  // xx xy xz yy yz zz
    Eigen::Matrix3d m;
    m << v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5];
    const Eigen::Matrix3d t = r * m * r.transpose();
    v[0] = float(t(0, 0)), v[1] = float(t(0, 1)), v[2] = float(t(0, 2));
    v[3] = float(t(1, 1)), v[4] = float(t(1, 2)), v[5] = float(t(2, 2));
  }
}

std::string SensorParametersProblem(const SensorInfo& info) {
  const bool finite = info.R_s2c.allFinite() && info.T_s2c.allFinite() &&
                      std::isfinite(info.sigma_t_s) && std::isfinite(info.range_sigma[0]) &&
                      std::isfinite(info.range_sigma[1]) && std::isfinite(info.max_range_m);
  if (!finite) return "non-finite extrinsics or noise parameters";
  // The same tolerance as the path's quaternions' unit norm would give a rotation built from
  // them in double precision, far above float rounding of a matrix written by hand.
  constexpr double kTolerance = 1e-6;
  const double off =
      (info.R_s2c * info.R_s2c.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double det = info.R_s2c.determinant();
  if (off > kTolerance || std::abs(det - 1) > kTolerance) {
    std::ostringstream why;
    why << "R_s2c is not a rotation (R·Rᵀ is off the identity by up to " << off
        << ", det R = " << det << ")";
    return why.str();
  }
  if (info.sigma_t_s < 0 || info.range_sigma[0] < 0 || info.range_sigma[1] < 0) {
    return "sigma_t and range_sigma must not be negative";
  }
  if (!(info.max_range_m > 0)) {
    std::ostringstream why;
    why << "max_range must be > 0 m, got " << info.max_range_m;
    return why.str();
  }
  return "";
}

std::string_view SensorKindName(SensorKind kind) {
  switch (kind) {
    case SensorKind::kLine:
      return "line";
    case SensorKind::kGrid:
      return "grid";
    case SensorKind::kPoints:
      return "points";
  }
  return "unknown";
}

}  // namespace carvemap
