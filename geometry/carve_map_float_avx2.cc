// FloatRay's rows eight leaves at a time, for CPUs with AVX2 (chosen at run time by
// carve_map_float.cc). Built with -mavx2 and without FMA or contraction (geometry/CMakeLists.txt):
// the same IEEE operations per lane as the four-lane path, so the same bits. Nothing here but
// this unit's own code and intrinsics (float_lanes.h says why).
#include <immintrin.h>

#include "geometry/float_lanes.h"

namespace carvemap::float_lanes {
namespace {

struct F8 {
  static constexpr int kLanes = 8;
  __m256 v;
  static F8 Set(float x) { return {_mm256_set1_ps(x)}; }
  static F8 Iota(float t) {
    return {_mm256_add_ps(_mm256_set1_ps(t), _mm256_set_ps(7, 6, 5, 4, 3, 2, 1, 0))};
  }
  friend F8 operator+(F8 a, F8 b) { return {_mm256_add_ps(a.v, b.v)}; }
  friend F8 operator-(F8 a, F8 b) { return {_mm256_sub_ps(a.v, b.v)}; }
  friend F8 operator*(F8 a, F8 b) { return {_mm256_mul_ps(a.v, b.v)}; }
  friend F8 operator/(F8 a, F8 b) { return {_mm256_div_ps(a.v, b.v)}; }
  // As minps/maxps: the second operand when either is NaN.
  friend F8 Min(F8 a, F8 b) { return {_mm256_min_ps(a.v, b.v)}; }
  friend F8 Max(F8 a, F8 b) { return {_mm256_max_ps(a.v, b.v)}; }
  friend F8 Select(F8 mask, F8 a, F8 b) {
    return {_mm256_or_ps(_mm256_and_ps(mask.v, a.v), _mm256_andnot_ps(mask.v, b.v))};
  }
  // Ordered comparisons, as SSE's cmpgtps and cmpleps: false for NaN.
  friend F8 Greater(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GT_OS)}; }
  friend F8 LessEqual(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OS)}; }
  friend bool Any(F8 mask) { return _mm256_movemask_ps(mask.v) != 0; }
  static void TruncScale(F8 x, F8* k_float, F8* scale) {
    const __m256i k = _mm256_cvttps_epi32(x.v);
    k_float->v = _mm256_cvtepi32_ps(k);
    scale->v =
        _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_sub_epi32(_mm256_set1_epi32(127), k), 23));
  }
  void Store(float* out) const { _mm256_storeu_ps(out, v); }
};

}  // namespace

void EvaluateRowAvx2(const RowInputs& in, int n, float* w, float* d) {
  EvaluateRow<F8>(in, n, w, d);
}

}  // namespace carvemap::float_lanes
