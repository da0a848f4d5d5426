#include "geometry/carve_map_float.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace carvemap {
namespace {

// Four float lanes. With SSE2 the intrinsics; elsewhere the same IEEE operations lane by lane,
// so both give the same bits.
#if defined(__SSE2__)
struct F4 {
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

// e^−x for x in [0, 87], as ExpNegFloat.
inline __attribute__((always_inline)) F4 ExpNeg4(F4 x) {
  constexpr float kLog2e = 1.44269504088896341f;
  constexpr float kC1 = 0.693359375f, kC2 = -2.12194440e-4f;  // ln 2 = C1 + C2, C1 exact
  F4 kf, scale;
  F4::TruncScale(x * F4::Set(kLog2e) + F4::Set(0.5f), &kf, &scale);  // k = round(x / ln 2)
  // s = −(x − k ln 2) ∈ [−ln2/2, ln2/2]; e^−x = 2^−k e^s.
  const F4 s = (kf * F4::Set(kC1) - x) + kf * F4::Set(kC2);
  const F4 z = s * s;
  F4 y = F4::Set(1.9875691500e-4f);
  y = y * s + F4::Set(1.3981999507e-3f);
  y = y * s + F4::Set(8.3334519073e-3f);
  y = y * s + F4::Set(4.1665795894e-2f);
  y = y * s + F4::Set(1.6666665459e-1f);
  y = y * s + F4::Set(5.0000001201e-1f);
  y = (y * z + s) + F4::Set(1.0f);
  return y * scale;
}

// 0.5·erfc(z) for any z: Abramowitz & Stegun 7.1.26 on |z| (absolute error < 1.5e−7),
// reflected for z < 0.
inline __attribute__((always_inline)) F4 HalfErfc4(F4 z) {
  const F4 zero = F4::Set(0.0f);
  const F4 neg = Greater(zero, z);
  const F4 az = Select(neg, zero - z, z);
  const F4 t = F4::Set(1.0f) / (F4::Set(1.0f) + F4::Set(0.3275911f) * az);
  F4 poly = F4::Set(1.061405429f);
  for (float c : {-1.453152027f, 1.421413741f, -0.284496736f, 0.254829592f}) {
    poly = poly * t + F4::Set(c);
  }
  // erfc(|z|) = t·poly·e^−z² (z² ≤ 87: erfc(9.3) is 0 in float anyway).
  const F4 e = (t * poly) * ExpNeg4(Min(az * az, F4::Set(87.0f)));
  return F4::Set(0.5f) * Select(neg, F4::Set(2.0f) - e, e);
}

// Past this f_⊥ < 1.2e−17: no weight (as carve_map.h's kNoWeightExponent).
constexpr float kNoWeightExponent = 39.0f;
// erfc's argument at or below which 0.5·erfc is 1 in double (carve_map.h skips it there too).
constexpr float kErfcSaturated = -6.0f;

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
  ExpNeg4(F4::Set(x)).Store(out);
  return out[0];
}

float ErfcFloat(float z) {
  float out[4];
  HalfErfc4(F4::Set(z)).Store(out);
  return 2.0f * out[0];
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

void FloatRay::EvaluateRow(int u, int v, int lo, int hi, float* w, float* d) const {
  if (hi < lo) return;
  F4 base[kInputs], step[kInputs];
  for (int k = 0; k < kInputs; ++k) {
    base[k] = F4::Set(float(y0_[k] + double(u) * yu_[k] + double(v) * yv_[k] + double(lo) * yt_[k]));
    step[k] = F4::Set(float(yt_[k]));
  }
  const F4 zero = F4::Set(0.0f), one = F4::Set(1.0f), half = F4::Set(0.5f);
  const F4 inv_len = F4::Set(inv_length_), det_a = F4::Set(det_a_), det_c = F4::Set(det_c_);
  const F4 mix = F4::Set(mix_), cut = F4::Set(kNoWeightExponent);
  const F4 saturated = F4::Set(kErfcSaturated), neg_is = F4::Set(-inv_sqrt2_sigma_s_);
  float wl[4], dl[4];
  for (int t = lo; t <= hi; t += 4) {
    const F4 k = F4::Iota(float(t - lo));
    const F4 par = base[kPar] + k * step[kPar];
    const F4 ua1 = base[kA1] + k * step[kA1], ua2 = base[kA2] + k * step[kA2];
    const F4 uc1 = base[kC1] + k * step[kC1], uc2 = base[kC2] + k * step[kC2];
    const F4 f = Min(Max(par * inv_len, zero), one);
    const F4 g = one - f;
    const F4 num = g * (ua1 * ua1 + ua2 * ua2) + f * (uc1 * uc1 + uc2 * uc2);
    const F4 den = g * (g * det_a + f * mix) + f * f * det_c;
    const F4 e = half * (num / den);
    const F4 weighted = LessEqual(e, cut);  // false for NaN too
    const F4 fw = Select(weighted, ExpNeg4(Min(e, cut)), zero);
    // Φ terms: F_s = 0.5 erfc(−x_∥/(σ_s√2)), 1 − F_p = 0.5 erfc(z_p); 1 where saturated.
    const F4 zs = par * neg_is;
    const F4 zp = base[kZp] + k * step[kZp];
    const F4 s_open = Greater(zs, saturated), p_open = Greater(zp, saturated);
    const F4 fs = Any(s_open) ? Select(s_open, HalfErfc4(zs), one) : one;
    const F4 fp = Any(p_open) ? Select(p_open, HalfErfc4(zp), one) : one;
    // p − 0.5 = f_⊥ (F_s (1 − F_p) − 0.5): kept apart from 0.5, so that a vote of weight 1e−15
    // (a leaf deep in a wide wedge) still says "interior" (p = 0.5 + ~1e−15, which float's
    // 0.5 + x would round to 0.5 exactly).
    const F4 dv = fw * ((fs * fp) - half);
    const int n = std::min(4, hi - t + 1);
    if (n == 4) {
      fw.Store(w + (t - lo));
      dv.Store(d + (t - lo));
    } else {
      fw.Store(wl);
      dv.Store(dl);
      std::copy(wl, wl + n, w + (t - lo));
      std::copy(dl, dl + n, d + (t - lo));
    }
  }
}

}  // namespace carvemap
