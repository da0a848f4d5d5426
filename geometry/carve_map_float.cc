#include "geometry/carve_map_float.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "geometry/float_lanes.h"

namespace carvemap {
namespace {

// Four float lanes. With SSE2 the intrinsics; elsewhere the same IEEE operations lane by lane,
// so both give the same bits.
#if defined(__SSE2__)
struct F4 {
  static constexpr int kLanes = 4;
  __m128 v;
  static F4 Set(float x) { return {_mm_set1_ps(x)}; }
  static F4 Iota(float t) { return {_mm_add_ps(_mm_set1_ps(t), _mm_set_ps(3, 2, 1, 0))}; }
  friend F4 operator+(F4 a, F4 b) { return {_mm_add_ps(a.v, b.v)}; }
  friend F4 operator-(F4 a, F4 b) { return {_mm_sub_ps(a.v, b.v)}; }
  friend F4 operator*(F4 a, F4 b) { return {_mm_mul_ps(a.v, b.v)}; }
  friend F4 operator/(F4 a, F4 b) { return {_mm_div_ps(a.v, b.v)}; }
  friend F4 Min(F4 a, F4 b) { return {_mm_min_ps(a.v, b.v)}; }
  friend F4 Max(F4 a, F4 b) { return {_mm_max_ps(a.v, b.v)}; }
  // Lanes of a where mask, else b (mask from a comparison: all ones or all zeros per lane).
  friend F4 Select(F4 mask, F4 a, F4 b) {
    return {_mm_or_ps(_mm_and_ps(mask.v, a.v), _mm_andnot_ps(mask.v, b.v))};
  }
  friend F4 Greater(F4 a, F4 b) { return {_mm_cmpgt_ps(a.v, b.v)}; }
  friend F4 LessEqual(F4 a, F4 b) { return {_mm_cmple_ps(a.v, b.v)}; }
  friend bool Any(F4 mask) { return _mm_movemask_ps(mask.v) != 0; }
  // 2^−k for integer k in [0, 126] given as the truncation of a non-negative float.
  static void TruncScale(F4 x, F4* k_float, F4* scale) {
    const __m128i k = _mm_cvttps_epi32(x.v);
    k_float->v = _mm_cvtepi32_ps(k);
    scale->v = _mm_castsi128_ps(_mm_slli_epi32(_mm_sub_epi32(_mm_set1_epi32(127), k), 23));
  }
  void Store(float* out) const { _mm_storeu_ps(out, v); }
};
#else
struct F4 {
  static constexpr int kLanes = 4;
  float v[4];
  template <typename Op>
  static F4 Map(F4 a, F4 b, Op op) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = op(a.v[i], b.v[i]);
    return r;
  }
  static F4 Set(float x) { return {{x, x, x, x}}; }
  static F4 Iota(float t) { return {{t + 0, t + 1, t + 2, t + 3}}; }
  friend F4 operator+(F4 a, F4 b) { return Map(a, b, [](float x, float y) { return x + y; }); }
  friend F4 operator-(F4 a, F4 b) { return Map(a, b, [](float x, float y) { return x - y; }); }
  friend F4 operator*(F4 a, F4 b) { return Map(a, b, [](float x, float y) { return x * y; }); }
  friend F4 operator/(F4 a, F4 b) { return Map(a, b, [](float x, float y) { return x / y; }); }
  // As minps/maxps: the second operand when either is NaN.
  friend F4 Min(F4 a, F4 b) { return Map(a, b, [](float x, float y) { return x < y ? x : y; }); }
  friend F4 Max(F4 a, F4 b) { return Map(a, b, [](float x, float y) { return x > y ? x : y; }); }
  static float Bits(bool on) {
    const uint32_t u = on ? ~0u : 0u;
    float f;
    std::memcpy(&f, &u, 4);
    return f;
  }
  static bool On(float m) {
    uint32_t u;
    std::memcpy(&u, &m, 4);
    return u != 0;
  }
  friend F4 Select(F4 mask, F4 a, F4 b) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = On(mask.v[i]) ? a.v[i] : b.v[i];
    return r;
  }
  friend F4 Greater(F4 a, F4 b) {
    return Map(a, b, [](float x, float y) { return Bits(x > y); });
  }
  friend F4 LessEqual(F4 a, F4 b) {
    return Map(a, b, [](float x, float y) { return Bits(x <= y); });
  }
  friend bool Any(F4 mask) {
    for (float m : mask.v)
      if (On(m)) return true;
    return false;
  }
  static void TruncScale(F4 x, F4* k_float, F4* scale) {
    for (int i = 0; i < 4; ++i) {
      const int32_t k = int32_t(x.v[i]);
      k_float->v[i] = float(k);
      const uint32_t bits = uint32_t(127 - k) << 23;
      std::memcpy(&scale->v[i], &bits, 4);
    }
  }
  void Store(float* out) const { std::memcpy(out, v, sizeof(v)); }
};
#endif

// L with L Lᵀ = adj(M) for M = (m11 m12; m12 m22) positive definite: adj(M) = (m22 −m12;
// −m12 m11), Cholesky (l11 0; l21 l22). False when M is not positive definite.
bool AdjCholesky(double m11, double m12, double m22, double* l11, double* l21, double* l22,
                 double* det) {
  *det = m11 * m22 - m12 * m12;
  if (!(m22 > 0) || !(*det > 0) || !std::isfinite(*det)) return false;
  *l11 = std::sqrt(m22);
  *l21 = -m12 / *l11;
  *l22 = std::sqrt(*det / m22);
  return true;
}

}  // namespace

float ExpNegFloat(float x) {
  float out[4];
  float_lanes::ExpNeg(F4::Set(x)).Store(out);
  return out[0];
}

float ErfcFloat(float z) {
  float out[4];
  float_lanes::HalfErfc(F4::Set(z)).Store(out);
  return 2.0f * out[0];
}

// Here, not in the AVX2 unit: it runs on every CPU.
bool EightFloatLanesAvailable() {
#if defined(CARVEMAP_AVX2_LANES)
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

std::optional<FloatRay> FloatRay::Make(const PreparedRay& ray,
                                       const Eigen::Vector3d& lattice_origin, double leaf_size,
                                       int axis) {
  const PreparedRay::Lateral lat = ray.lateral();
  FloatRay r;
  double a11, a21, a22, c11, c21, c22, det_a, det_c;
  if (!AdjCholesky(lat.s11, lat.s12, lat.s22, &a11, &a21, &a22, &det_a) ||
      !AdjCholesky(lat.p11, lat.p12, lat.p22, &c11, &c21, &c22, &det_c)) {
    return std::nullopt;
  }
  // tr(adj A · C) ≥ 0 for positive definite A and C.
  const double mix = lat.s22 * lat.p11 + lat.s11 * lat.p22 - 2 * lat.s12 * lat.p12;
  r.det_a_ = float(det_a);
  r.det_c_ = float(det_c);
  r.mix_ = float(std::max(mix, 0.0));
  if (!(r.det_a_ > 0) || !(r.det_c_ > 0)) return std::nullopt;  // below float's range
  r.inv_length_ = float(1.0 / ray.length());
  // As PreparedRay: σ floored at 1 nm.
  r.inv_sqrt2_sigma_s_ = float(1.0 / (std::sqrt(2.0) * std::max(ray.sensor_sigma_along(), 1e-9)));
  const double inv_sqrt2_sigma_p = 1.0 / (std::sqrt(2.0) * std::max(ray.point_sigma_along(), 1e-9));
  const double length = ray.length();
  // The inputs as linear functions of a displacement (x_∥, a, b), plus the constant of z_p.
  const auto inputs = [&](double par, double a, double b, double* y) {
    y[kPar] = par;
    y[kA1] = a11 * a + a21 * b;
    y[kA2] = a22 * b;
    y[kC1] = c11 * a + c21 * b;
    y[kC2] = c22 * b;
    y[kZp] = (par - (lat.kp1 * a + lat.kp2 * b)) * inv_sqrt2_sigma_p;
  };
  const auto project = [&](const Eigen::Vector3d& d, double* y) {
    inputs(d.dot(ray.direction()), d.dot(lat.e1), d.dot(lat.e2), y);
  };
  project(lattice_origin - ray.origin(), r.y0_);
  r.y0_[kZp] -= length * inv_sqrt2_sigma_p;
  project(Eigen::Vector3d::Unit(axis) * leaf_size, r.yt_);
  project(Eigen::Vector3d::Unit((axis + 1) % 3) * leaf_size, r.yu_);
  project(Eigen::Vector3d::Unit((axis + 2) % 3) * leaf_size, r.yv_);
  return r;
}

void FloatRay::EvaluateRow(int u, int v, int lo, int hi, float* w, float* d,
                           FloatLanes lanes) const {
  using float_lanes::RowInputs;
  static_assert(int(kPar) == int(RowInputs::kPar) && int(kA1) == int(RowInputs::kA1) &&
                int(kA2) == int(RowInputs::kA2) && int(kC1) == int(RowInputs::kC1) &&
                int(kC2) == int(RowInputs::kC2) && int(kZp) == int(RowInputs::kZp) &&
                int(kInputs) == int(RowInputs::kInputs));
  if (hi < lo) return;
  RowInputs in;
  for (int k = 0; k < kInputs; ++k) {
    in.base[k] = float(y0_[k] + double(u) * yu_[k] + double(v) * yv_[k] + double(lo) * yt_[k]);
    in.step[k] = float(yt_[k]);
  }
  in.det_a = det_a_;
  in.det_c = det_c_;
  in.mix = mix_;
  in.inv_length = inv_length_;
  in.inv_sqrt2_sigma_s = inv_sqrt2_sigma_s_;
  const int n = hi - lo + 1;
#if defined(CARVEMAP_AVX2_LANES)
  // Eight lanes pay from five leaves on (a row of up to four is one pass of four lanes).
  static const bool avx2 = EightFloatLanesAvailable();
  if (avx2 && (lanes == FloatLanes::kEight || (lanes == FloatLanes::kAuto && n > 4))) {
    float_lanes::EvaluateRowAvx2(in, n, w, d);
    return;
  }
#endif
  float_lanes::EvaluateRow<F4>(in, n, w, d);
}

}  // namespace carvemap
