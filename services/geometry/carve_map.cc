#include "services/geometry/carve_map.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// Below this a ray has no usable direction (float means carry ~1 µm precision near the origin).
constexpr double kMinRayLength_m = 1e-6;
// A zero marginal σ would turn F_s/F_p into steps through 0·∞ = NaN at the step; a 1 nm σ is a
// step for every practical purpose and keeps erfc's argument finite.
constexpr double kMinSigma_m = 1e-9;

bool AllFinite(const SymCov3f& c) {
  return std::all_of(c.begin(), c.end(), [](float v) { return std::isfinite(v); });
}

}  // namespace

absl::StatusOr<PreparedRay> PreparedRay::Make(const RayModel& ray) {
  if (!ray.sensor_mean.allFinite() || !ray.point_mean.allFinite() || !AllFinite(ray.sensor_cov) ||
      !AllFinite(ray.point_cov)) {
    return absl::InvalidArgumentError("carve_map: ray with a non-finite mean or covariance");
  }
  PreparedRay pr;
  pr.origin_ = ray.sensor_mean.cast<double>();
  const Eigen::Vector3d axis = ray.point_mean.cast<double>() - pr.origin_;
  pr.length_ = axis.norm();
  if (!(pr.length_ >= kMinRayLength_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat("carve_map: ray of length ", pr.length_, " m has no direction"));
  }
  pr.inv_length_ = 1.0 / pr.length_;
  pr.dir_ = axis * pr.inv_length_;
  // Any orthonormal completion works: σ_⊥² = uᵀC*u does not depend on the basis.
  const Eigen::Vector3d helper =
      std::abs(pr.dir_.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  pr.e1_ = pr.dir_.cross(helper).normalized();
  pr.e2_ = pr.dir_.cross(pr.e1_);

  const Eigen::Matrix3d Cs = ToMatrix(ray.sensor_cov);
  const Eigen::Matrix3d Cp = ToMatrix(ray.point_cov);
  pr.sigma_s_par_ = std::sqrt(std::max(pr.dir_.dot(Cs * pr.dir_), 0.0));
  pr.sigma_p_par_ = std::sqrt(std::max(pr.dir_.dot(Cp * pr.dir_), 0.0));
  pr.inv_sqrt2_sigma_s_ = 1.0 / (std::sqrt(2.0) * std::max(pr.sigma_s_par_, kMinSigma_m));
  pr.inv_sqrt2_sigma_p_ = 1.0 / (std::sqrt(2.0) * std::max(pr.sigma_p_par_, kMinSigma_m));

  const Eigen::Matrix3d Cd = Cp - Cs;
  pr.ls11_ = pr.e1_.dot(Cs * pr.e1_);
  pr.ls12_ = pr.e1_.dot(Cs * pr.e2_);
  pr.ls22_ = pr.e2_.dot(Cs * pr.e2_);
  pr.ld11_ = pr.e1_.dot(Cd * pr.e1_);
  pr.ld12_ = pr.e1_.dot(Cd * pr.e2_);
  pr.ld22_ = pr.e2_.dot(Cd * pr.e2_);
  return pr;
}

CarveSample EvaluateCarveMap(const RayModel& ray, const Eigen::Vector3d& x) {
  absl::StatusOr<PreparedRay> pr = PreparedRay::Make(ray);
  if (!pr.ok()) return CarveSample{0.5, 0.0};
  return pr->Evaluate(x);
}

}  // namespace carvemap
