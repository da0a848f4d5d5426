// Eq 4.7 along a row of leaves in single precision, written once for any width of float lanes
// (carve_map_float.cc: four, SSE2 or portable; carve_map_float_avx2.cc: eight, AVX2). A lane
// type V supplies Set, Iota, + − × ÷, Min, Max, Select, Greater, LessEqual, Any, TruncScale and
// Store with IEEE single-precision semantics, lane by lane: every width then gives the same
// bits for the same leaf, whichever the CPU picks at run time.
//
// Private to geometry/: instantiate only with a lane type of internal linkage (in an unnamed
// namespace), so that the copies compiled for different instruction sets never merge. No
// standard-library calls here for the same reason (an out-of-line copy compiled with AVX2
// could be the one the linker keeps for everybody).
#pragma once

namespace carvemap::float_lanes {

// A row's inputs of eq 4.7 at its first leaf and their step per leaf (FloatRay's affine
// inputs: x_∥, the whitened lateral coordinates at each end, z_p), and the ray's constants.
struct RowInputs {
  enum Input { kPar, kA1, kA2, kC1, kC2, kZp, kInputs };
  float base[kInputs];
  float step[kInputs];
  float det_a, det_c, mix, inv_length, inv_sqrt2_sigma_s;
};

// Past this f_⊥ < 1.2e−17: no weight (as carve_map.h's kNoWeightExponent).
inline constexpr float kNoWeightExponent = 39.0f;
// erfc's argument at or below which 0.5·erfc is 1 in double (carve_map.h skips it there too).
inline constexpr float kErfcSaturated = -6.0f;

// e^−x for x in [0, 87]: Cody–Waite reduction by ln 2 and a degree-7 polynomial, as cephes'
// expf (within 2 ulp).
template <typename V>
inline __attribute__((always_inline)) V ExpNeg(V x) {
  constexpr float kLog2e = 1.44269504088896341f;
  constexpr float kC1 = 0.693359375f, kC2 = -2.12194440e-4f;  // ln 2 = C1 + C2, C1 exact
  V kf, scale;
  V::TruncScale(x * V::Set(kLog2e) + V::Set(0.5f), &kf, &scale);  // k = round(x / ln 2)
  // s = −(x − k ln 2) ∈ [−ln2/2, ln2/2]; e^−x = 2^−k e^s.
  const V s = (kf * V::Set(kC1) - x) + kf * V::Set(kC2);
  const V z = s * s;
  V y = V::Set(1.9875691500e-4f);
  y = y * s + V::Set(1.3981999507e-3f);
  y = y * s + V::Set(8.3334519073e-3f);
  y = y * s + V::Set(4.1665795894e-2f);
  y = y * s + V::Set(1.6666665459e-1f);
  y = y * s + V::Set(5.0000001201e-1f);
  y = (y * z + s) + V::Set(1.0f);
  return y * scale;
}

// 0.5·erfc(z) for any z: Abramowitz & Stegun 7.1.26 on |z| (absolute error < 1.5e−7),
// reflected for z < 0.
template <typename V>
inline __attribute__((always_inline)) V HalfErfc(V z) {
  const V zero = V::Set(0.0f);
  const V neg = Greater(zero, z);
  const V az = Select(neg, zero - z, z);
  const V t = V::Set(1.0f) / (V::Set(1.0f) + V::Set(0.3275911f) * az);
  V poly = V::Set(1.061405429f);
  poly = poly * t + V::Set(-1.453152027f);
  poly = poly * t + V::Set(1.421413741f);
  poly = poly * t + V::Set(-0.284496736f);
  poly = poly * t + V::Set(0.254829592f);
  // erfc(|z|) = t·poly·e^−z² (z² ≤ 87: erfc(9.3) is 0 in float anyway).
  const V e = (t * poly) * ExpNeg(Min(az * az, V::Set(87.0f)));
  return V::Set(0.5f) * Select(neg, V::Set(2.0f) - e, e);
}

// w[i] and d[i] = p − 0.5 for the row's leaves i = 0 … n − 1 (FloatRay::EvaluateRow).
template <typename V>
inline __attribute__((always_inline)) void EvaluateRow(const RowInputs& in, int n, float* w,
                                                       float* d) {
  using I = RowInputs;
  V base[I::kInputs], step[I::kInputs];
  for (int k = 0; k < I::kInputs; ++k) {
    base[k] = V::Set(in.base[k]);
    step[k] = V::Set(in.step[k]);
  }
  const V zero = V::Set(0.0f), one = V::Set(1.0f), half = V::Set(0.5f);
  const V inv_len = V::Set(in.inv_length), det_a = V::Set(in.det_a), det_c = V::Set(in.det_c);
  const V mix = V::Set(in.mix), cut = V::Set(kNoWeightExponent);
  const V saturated = V::Set(kErfcSaturated), neg_is = V::Set(-in.inv_sqrt2_sigma_s);
  float wl[V::kLanes], dl[V::kLanes];
  for (int i = 0; i < n; i += V::kLanes) {
    const V k = V::Iota(float(i));
    const V par = base[I::kPar] + k * step[I::kPar];
    const V ua1 = base[I::kA1] + k * step[I::kA1], ua2 = base[I::kA2] + k * step[I::kA2];
    const V uc1 = base[I::kC1] + k * step[I::kC1], uc2 = base[I::kC2] + k * step[I::kC2];
    const V f = Min(Max(par * inv_len, zero), one);
    const V g = one - f;
    const V num = g * (ua1 * ua1 + ua2 * ua2) + f * (uc1 * uc1 + uc2 * uc2);
    const V den = g * (g * det_a + f * mix) + f * f * det_c;
    const V e = half * (num / den);
    const V weighted = LessEqual(e, cut);  // false for NaN too
    const V fw = Select(weighted, ExpNeg(Min(e, cut)), zero);
    // Φ terms: F_s = 0.5 erfc(−x_∥/(σ_s√2)), 1 − F_p = 0.5 erfc(z_p); 1 where saturated.
    const V zs = par * neg_is;
    const V zp = base[I::kZp] + k * step[I::kZp];
    const V s_open = Greater(zs, saturated), p_open = Greater(zp, saturated);
    const V fs = Any(s_open) ? Select(s_open, HalfErfc(zs), one) : one;
    const V fp = Any(p_open) ? Select(p_open, HalfErfc(zp), one) : one;
    // p − 0.5 = f_⊥ (F_s (1 − F_p) − 0.5): kept apart from 0.5, so that a vote of weight 1e−15
    // (a leaf deep in a wide wedge) still says "interior" (p = 0.5 + ~1e−15, which float's
    // 0.5 + x would round to 0.5 exactly).
    const V dv = fw * ((fs * fp) - half);
    if (n - i >= V::kLanes) {
      fw.Store(w + i);
      dv.Store(d + i);
    } else {
      fw.Store(wl);
      dv.Store(dl);
      for (int j = 0; j < n - i; ++j) {
        w[i + j] = wl[j];
        d[i + j] = dl[j];
      }
    }
  }
}

// Eight lanes with AVX2 (carve_map_float_avx2.cc, built only on x86-64). REQUIRES: the CPU
// has AVX2 (EightFloatLanesAvailable(), carve_map_float.h).
void EvaluateRowAvx2(const RowInputs& in, int n, float* w, float* d);

}  // namespace carvemap::float_lanes
