// Eq 4.7 (§4.1.2) in single precision, four leaves at a time: the fast carve's evaluator
// (worker/chunk_octree.h, CarveEvaluation::kFast). carve_map.h is the reference; this gives the
// same values within 5e−6 (w and p): far below the tolerance the fast carve is held to
// (worker/chunk_octree.h).
//
// Why it is cheaper than PreparedRay::EvaluateMany, beyond four float lanes against two double
// ones: along a row of leaves every input of eq 4.7 is affine in the leaf index, so each is
// stepped from the row's first leaf; the lateral quadratic form is written so that float does
// not cancel (below); e^−x and erfc are short polynomials of our own.
//
// f_⊥'s exponent, ½ x_⊥ᵀ C*⁻¹ x_⊥ with C* = (1 − f) A + f C (A, C the 2×2 lateral blocks of
// C_s and C_p, f = clamp(x_∥ / L, 0, 1)), is computed as
//   ½ [(1 − f)|L_Aᵀx_⊥|² + f|L_Cᵀx_⊥|²] / [(1 − f)² det A + f² det C + f(1 − f) tr(adj A · C)]
// with L Lᵀ = adj(·) (Cholesky): adj is linear on 2×2 matrices, det(X + Y) = det X + det Y +
// tr(adj X · Y), and every term is ≥ 0, so nothing cancels however flat the covariances are.
// (The double path forms c11 c22 − c12², which float could not afford for a 1 mm × 2.5 cm
// spread.)
//
// Determinism: only IEEE-exact operations (add, mul, div, compare, conversions) in a fixed
// order, the same for every leaf whatever the width of the lanes: eight with AVX2 where the
// CPU has it, four with SSE2 on other x86-64 CPUs (the baseline), the same operations lane by
// lane elsewhere; no FMA contraction, no libm. Tiles are bit-identical on any worker.
#pragma once

#include <optional>

#include <Eigen/Core>

#include "geometry/carve_map.h"

namespace carvemap {

// Which lanes FloatRay::EvaluateRow uses: kAuto picks eight where the CPU has them and the row
// is longer than four leaves; the others are for tests (kEight falls back to four without).
enum class FloatLanes { kAuto, kFour, kEight };
// Whether this CPU has the eight lanes (AVX2; x86-64 builds only).
[[nodiscard]] bool EightFloatLanesAvailable();

class FloatRay {
 public:
  // The ray's constants on the lattice of leaf centres x(t, u, v) = lattice_origin + s·(t e_a +
  // u e_b + v e_c), s = leaf_size, a = axis, b = a + 1 and c = a + 2 (mod 3): rows of leaves
  // run along `axis`. std::nullopt when a lateral block is not positive definite (no
  // Cholesky): evaluate that ray with the double path.
  static std::optional<FloatRay> Make(const PreparedRay& ray, const Eigen::Vector3d& lattice_origin,
                                      double leaf_size, int axis);

  // Eq 4.7 at x(t, u, v) for t = lo … hi: w[i] and d[i] = p − 0.5 for t = lo + i (p itself
  // would lose a tiny weight's "interior": 0.5 + 1e−15 is 0.5 in float). A leaf with f_⊥'s
  // exponent above 39 (f_⊥ < 1.2e−17) gets w = 0, d = 0, as in the double path. Each input
  // of eq 4.7 is affine in (t, u, v): it is computed in double at (lo, u, v), where the row's
  // values are (the ray's hull reaches there), then stepped in float along the row, so
  // nothing large cancels. REQUIRES: 0 ≤ lo ≤ hi, lattice coordinates below 2^20.
  void EvaluateRow(int u, int v, int lo, int hi, float* w, float* d,
                   FloatLanes lanes = FloatLanes::kAuto) const;

 private:
  FloatRay() = default;

  // The inputs of eq 4.7 that are affine on the lattice: x_∥, the two whitened lateral
  // coordinates at each end (L_Aᵀx_⊥, L_Cᵀx_⊥), and z_p; each as y0 + t·yt + u·yu + v·yv.
  enum Input { kPar, kA1, kA2, kC1, kC2, kZp, kInputs };
  double y0_[kInputs] = {}, yt_[kInputs] = {}, yu_[kInputs] = {}, yv_[kInputs] = {};
  float det_a_ = 0, det_c_ = 0, mix_ = 0;  // det A, det C, tr(adj A · C)
  float inv_length_ = 0;
  float inv_sqrt2_sigma_s_ = 0;
};

// e^−x for 0 ≤ x ≤ 87 in single precision (within 2 ulp; 0 below that range is the caller's):
// Cody–Waite reduction by ln 2 and a degree-7 polynomial, as cephes' expf. Scalar reference of
// the lanes of FloatRay::EvaluateRow, for tests.
[[nodiscard]] float ExpNegFloat(float x);
// erfc(z) in single precision for any z (absolute error < 5e−7): Abramowitz & Stegun 7.1.26
// (a rational fit times e^−z², absolute error < 1.5e−7 for z ≥ 0) and erfc(−z) = 2 − erfc(z).
[[nodiscard]] float ErfcFloat(float z);

}  // namespace carvemap
