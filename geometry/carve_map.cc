#include "geometry/carve_map.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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

RangeGivenLateral PointRangeGivenLateral(const Eigen::Matrix3d& c, const Eigen::Vector3d& d) {
  const double marginal = std::max(d.dot(c * d), 0.0);
  // Invertible relative to its size: float covariances carry ~7 digits, so a direction with
  // less than 1e-12 of the mean variance cubed in the determinant is no spread at all.
  const double scale = c.trace() / 3;
  const double det = c.determinant();
  if (!(scale > 0) || !(det > 1e-12 * scale * scale * scale)) {
    return {Eigen::Vector3d::Zero(), std::sqrt(marginal)};
  }
  const Eigen::Vector3d lambda_d = c.inverse() * d;
  const double precision = d.dot(lambda_d);
  if (!(precision > 0) || !std::isfinite(precision)) {
    return {Eigen::Vector3d::Zero(), std::sqrt(marginal)};
  }
  const double var = 1.0 / precision;
  // Never wider than the marginal (rounding could make it so).
  return {d - var * lambda_d, std::sqrt(std::min(var, marginal))};
}

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
  pr.dir_ = axis * pr.inv_length_;  // as Direction()
  // Any orthonormal completion works: f_⊥ and k·x_⊥ do not depend on the basis.
  const Eigen::Vector3d helper =
      std::abs(pr.dir_.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  pr.e1_ = pr.dir_.cross(helper).normalized();
  pr.e2_ = pr.dir_.cross(pr.e1_);

  const Eigen::Matrix3d Cs = ToMatrix(ray.sensor_cov);
  const Eigen::Matrix3d Cp = ToMatrix(ray.point_cov);
  pr.sigma_s_par_ = std::sqrt(std::max(pr.dir_.dot(Cs * pr.dir_), 0.0));
  const RangeGivenLateral range = PointRangeGivenLateral(Cp, pr.dir_);
  pr.sigma_p_par_ = range.sigma;
  pr.kp1_ = range.k.dot(pr.e1_);
  pr.kp2_ = range.k.dot(pr.e2_);
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

std::optional<Eigen::Vector3d> PreparedRay::Direction(const RayModel& ray) {
  const Eigen::Vector3d axis = ray.point_mean.cast<double>() - ray.sensor_mean.cast<double>();
  const double length = axis.norm();
  if (!(length >= kMinRayLength_m)) return std::nullopt;
  return Eigen::Vector3d(axis * (1.0 / length));
}

void PreparedRay::EvaluateMany(const double* par, const double* a, const double* b, size_t n,
                               double* p, double* w) const {
  constexpr double kNoWeightExponent = 39.0;
  size_t i = 0;
#if defined(__SSE2__)
  // Two points at a time: f_⊥ = e^−exponent with the operations of EvaluateProjected and
  // ExpNeg lane by lane (IEEE arithmetic is the same in a vector lane as in a scalar), so the
  // result does not depend on this path.
  const __m128d zero = _mm_setzero_pd(), one = _mm_set1_pd(1.0), half = _mm_set1_pd(0.5);
  const __m128d inv_len = _mm_set1_pd(inv_length_);
  for (; i + 2 <= n; i += 2) {
    const __m128d va = _mm_loadu_pd(a + i), vb = _mm_loadu_pd(b + i);
    const __m128d perp2 = _mm_add_pd(_mm_mul_pd(va, va), _mm_mul_pd(vb, vb));
    const __m128d f = _mm_min_pd(_mm_max_pd(_mm_mul_pd(_mm_loadu_pd(par + i), inv_len), zero), one);
    const __m128d c11 = _mm_add_pd(_mm_set1_pd(ls11_), _mm_mul_pd(f, _mm_set1_pd(ld11_)));
    const __m128d c12 = _mm_add_pd(_mm_set1_pd(ls12_), _mm_mul_pd(f, _mm_set1_pd(ld12_)));
    const __m128d c22 = _mm_add_pd(_mm_set1_pd(ls22_), _mm_mul_pd(f, _mm_set1_pd(ld22_)));
    const __m128d q = _mm_add_pd(
        _mm_sub_pd(_mm_mul_pd(_mm_mul_pd(c22, va), va),
                   _mm_mul_pd(_mm_mul_pd(_mm_mul_pd(_mm_set1_pd(2.0), c12), va), vb)),
        _mm_mul_pd(_mm_mul_pd(c11, vb), vb));
    const __m128d det = _mm_sub_pd(_mm_mul_pd(c11, c22), _mm_mul_pd(c12, c12));
    __m128d e = _mm_div_pd(_mm_mul_pd(half, q), det);
    // det ≤ 0: no weight; |x_⊥| ≈ 0: on the ray, f_⊥ = 1.
    e = _mm_or_pd(_mm_and_pd(_mm_cmpgt_pd(det, zero), e),
                  _mm_andnot_pd(_mm_cmpgt_pd(det, zero), _mm_set1_pd(kNoWeightExponent + 1)));
    const __m128d on_ray = _mm_cmple_pd(perp2, _mm_set1_pd(1e-24));
    e = _mm_andnot_pd(on_ray, e);
    // ExpNeg(min(e, 40)) lane by lane: past 39 the weight is dropped below anyway.
    const __m128d x = _mm_min_pd(e, _mm_set1_pd(40.0));
    const __m128i k = _mm_cvttpd_epi32(_mm_add_pd(_mm_mul_pd(x, _mm_set1_pd(46.166241308446828)),
                                                  half));
    const __m128d kd = _mm_cvtepi32_pd(k);
    const __m128d r = _mm_sub_pd(
        _mm_sub_pd(x, _mm_mul_pd(kd, _mm_set1_pd(6.93147180369123816490e-01 / 32))),
        _mm_mul_pd(kd, _mm_set1_pd(1.90821492927058770002e-10 / 32)));
    const __m128d r2 = _mm_mul_pd(r, r);
    const __m128d poly = _mm_add_pd(
        _mm_sub_pd(one, r),
        _mm_mul_pd(r2, _mm_add_pd(_mm_sub_pd(half, _mm_mul_pd(r, _mm_set1_pd(1.0 / 6))),
                                  _mm_mul_pd(r2, _mm_add_pd(_mm_sub_pd(_mm_set1_pd(1.0 / 24),
                                                                       _mm_mul_pd(r, _mm_set1_pd(1.0 / 120))),
                                                            _mm_mul_pd(r2, _mm_set1_pd(1.0 / 720)))))));
    const int k0 = _mm_cvtsi128_si32(k), k1 = _mm_cvtsi128_si32(_mm_srli_si128(k, 4));
    const __m128d table = _mm_set_pd(kExp2NegJ32[k1 & 31], kExp2NegJ32[k0 & 31]);
    const __m128d scale =
        _mm_castsi128_pd(_mm_set_epi64x(int64_t(uint64_t(1023 - (k1 >> 5)) << 52),
                                        int64_t(uint64_t(1023 - (k0 >> 5)) << 52)));
    const __m128d f_perp = _mm_mul_pd(_mm_mul_pd(poly, table), scale);
    alignas(16) double ev[2], fv[2];
    _mm_store_pd(ev, e);
    _mm_store_pd(fv, f_perp);
    for (int l = 0; l < 2; ++l) {
      const size_t j = i + size_t(l);
      if (ev[l] > kNoWeightExponent) {
        p[j] = 0.5;
        w[j] = 0.0;
        continue;
      }
      // e = 0 exactly (on the ray) gives ExpNeg(0) = 1, as EvaluateProjected's f_⊥ = 1.
      const double fp = fv[l];
      const double z_s = -par[j] * inv_sqrt2_sigma_s_;
      const double z_p =
          ((par[j] - length_) - (kp1_ * a[j] + kp2_ * b[j])) * inv_sqrt2_sigma_p_;
      const double F_s = z_s <= -6.0 ? 1.0 : 0.5 * std::erfc(z_s);
      const double one_minus_F_p = z_p <= -6.0 ? 1.0 : 0.5 * std::erfc(z_p);
      p[j] = F_s * fp * one_minus_F_p + 0.5 * (1.0 - fp);
      w[j] = fp;
    }
  }
#endif
  for (; i < n; ++i) {
    const CarveSample s = EvaluateProjected(par[i], a[i], b[i]);
    p[i] = s.p;
    w[i] = s.w;
  }
}

CarveSample EvaluateCarveMap(const RayModel& ray, const Eigen::Vector3d& x) {
  absl::StatusOr<PreparedRay> pr = PreparedRay::Make(ray);
  if (!pr.ok()) return CarveSample{0.5, 0.0};
  return pr->Evaluate(x);
}

}  // namespace carvemap
