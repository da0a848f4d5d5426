// The carve map of one scan ray (§4.1.2, eq 4.7) and its weight w = f_⊥ (§4.3.2, eq 4.8).
//
// For a query x, split x − μ_s into x_∥ (signed distance along d = (μ_p − μ_s)/L, L = |μ_p − μ_s|)
// and x_⊥ (the rest). Then
//   p(x) = F_s(x_∥) f_⊥(x_⊥) (1 − F_p(x_∥)) + 0.5 (1 − f_⊥(x_⊥))          (eq 4.7)
// with F_s the CDF of the sensor Gaussian's marginal along d (mean 0, σ² = dᵀC_s d), F_p that of
// the point Gaussian's range along d given the lateral offset x_⊥ (PointRangeGivenLateral:
// mean L + k·x_⊥, σ² = 1/(dᵀC_p⁻¹d)), and
//   f_⊥(x_⊥) = exp(−½ x_⊥ᵀ C*⊥⁻¹ x_⊥),  C*⊥ the 2×2 block of C* across the ray,
//   C* = (1 − f) C_s + f C_p,  f = clamp(x_∥ / L, 0, 1).
// The dissertation takes F_p as the marginal along d (mean L, σ² = dᵀC_p d). When C_p is round, or
// spread only along d, the conditional is the same. When C_p is spread along a surface the ray
// meets obliquely (the sampling term, SamplingCovariance), the marginal would put the surface
// at range L beside the ray too, so the ray would carve behind the surface on one side and
// leave free space uncarved on the other; the conditional follows the surface.
// The dissertation calls f_⊥ "the marginal along the direction x_⊥" of N(x_∥, C*). We take the
// lateral Gaussian's density at x_⊥ (its slice along u = x_⊥/|x_⊥|), not the density of the
// projection onto u (exp(−|x_⊥|²/(2 uᵀC*u))). The two agree when C* is round across the ray; when
// it is flat (a ray spread along a surface by its sampling share, SamplingCovariance) the
// projection form leaks along the narrow axis: k σ_n off it and as far along the wide axis, the
// weight is e^(−2k²σ_n²/σ_w²), so for a 2.5 cm spread over the 1 mm floor a point 25 σ_n behind the
// surface still weighs e^−2 ≈ 0.14, and the ray votes "interior" there.
// The dissertation calls f_⊥ the "PMF" of the lateral marginal. We take it unnormalised (peak 1
// on the ray): a density normalised by 1/(σ_⊥√(2π)) would exceed 1 for σ_⊥ < 0.4 m, making
// 0.5(1 − f_⊥) negative and p leave [0, 1], which contradicts p: ℝ³ → [0, 1]. Unnormalised,
// f_⊥ ∈ [0, 1] is the fraction of "this ray speaks about x", p is a blend of the ray's
// along-ray vote F_s(1 − F_p) ∈ [0, 1] with "unknown" 0.5, and w = f_⊥ → 0 far from the ray.
//
// Hot path (billions of evaluations): prepare each ray once (PreparedRay), then Evaluate().
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <optional>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "geometry/carving_types.h"

namespace carvemap {

// The range of a point Gaussian N(μ, C) along the unit direction d given its offset x_⊥ across
// d: N(k·x_⊥, σ²) about μ's range, with σ² = 1/(dᵀC⁻¹d) and k = d − σ²C⁻¹d (k ⊥ d, so k·x_⊥
// only sees the offset across d). A C with no inverse (no spread in some direction) gives
// the marginal: σ² = dᵀCd, k = 0.
struct RangeGivenLateral {
  Eigen::Vector3d k;
  double sigma;  // m
};
[[nodiscard]] RangeGivenLateral PointRangeGivenLateral(const Eigen::Matrix3d& c,
                                                       const Eigen::Vector3d& d);

// One ray's vote about one location: p (eq 4.7) and its weight w = f_⊥ (eq 4.8).
struct CarveSample {
  double p = 0.5;  // in [0, 1]; > 0.5 interior
  double w = 0.0;  // in [0, 1]
};

// The per-ray constants of eq 4.7. Thread-compatible: Evaluate() is const and pure.
class PreparedRay {
 public:
  // Errors: InvalidArgument when a mean or covariance is not finite or the ray is shorter than
  // 1 µm (no direction: such a ray carves nothing).
  static absl::StatusOr<PreparedRay> Make(const RayModel& ray);
  // The unit direction Make gives the ray (bit for bit), without the rest of its work;
  // std::nullopt where Make fails for the length. REQUIRES: finite means.
  static std::optional<Eigen::Vector3d> Direction(const RayModel& ray);

  [[nodiscard]] CarveSample Evaluate(const Eigen::Vector3d& x) const;
  // Eq 4.7 at x0 + i·step for i = first … last (a row of leaf centres), calling
  // sink(i, CarveSample) for each; the same values as Evaluate up to rounding (~1e−16), at a
  // fraction of the cost (the projections are stepped, not recomputed). The value at i does
  // not depend on first and last.
  template <typename Sink>
  void EvaluateAlong(const Eigen::Vector3d& x0, const Eigen::Vector3d& step, int first, int last,
                     Sink&& sink) const;

  // x − μ_s in the ray's frame: (x_∥, and the two lateral coordinates). Affine in x, so a row
  // of leaf centres projects to p0 + i·dp with dp = ProjectStep(step).
  struct Projection {
    double par, a, b;
  };
  [[nodiscard]] Projection Project(const Eigen::Vector3d& x) const {
    const Eigen::Vector3d r = x - origin_;
    return {r.dot(dir_), r.dot(e1_), r.dot(e2_)};
  }
  [[nodiscard]] Projection ProjectStep(const Eigen::Vector3d& v) const {
    return {v.dot(dir_), v.dot(e1_), v.dot(e2_)};
  }
  // Eq 4.7 at n points given by their projections: p[i], w[i] are bit for bit what Evaluate
  // gives at each point (the same operations in the same order), two at a time with SSE2 where
  // the target has it. The hot loop of carving: most of its cost is e^−x and the divide.
  void EvaluateMany(const double* par, const double* a, const double* b, size_t n, double* p,
                    double* w) const;

  [[nodiscard]] const Eigen::Vector3d& origin() const { return origin_; }    // μ_s
  [[nodiscard]] const Eigen::Vector3d& direction() const { return dir_; }    // d, unit
  // The lateral basis (e1, e2 ⊥ d) and, in it, the blocks of C_s and C_p across the ray
  // (11, 12, 22) and F_p's shift k·x_⊥ = kp1·a + kp2·b: what another evaluator of eq 4.7
  // needs (carve_map_float.h).
  struct Lateral {
    Eigen::Vector3d e1, e2;
    double s11, s12, s22, p11, p12, p22, kp1, kp2;
  };
  [[nodiscard]] Lateral lateral() const {
    return {e1_, e2_, ls11_, ls12_, ls22_, ls11_ + ld11_, ls12_ + ld12_, ls22_ + ld22_, kp1_, kp2_};
  }
  [[nodiscard]] double length() const { return length_; }                    // L, m
  [[nodiscard]] double sensor_sigma_along() const { return sigma_s_par_; }   // m
  // σ of F_p: the point's range given the lateral offset (PointRangeGivenLateral).
  [[nodiscard]] double point_sigma_along() const { return sigma_p_par_; }    // m

 private:
  PreparedRay() = default;
  // Eq 4.7 from the projections of x − μ_s on d, e1, e2.
  [[nodiscard]] CarveSample EvaluateProjected(double x_par, double a, double b) const;

  Eigen::Vector3d origin_;
  Eigen::Vector3d dir_;
  // An orthonormal basis (e1, e2) of the plane orthogonal to d: the lateral covariances are
  // kept as 2×2 blocks in it, so f_⊥ needs two dot products and a 2×2 quadratic form.
  Eigen::Vector3d e1_, e2_;
  double length_ = 0;
  double inv_length_ = 0;
  double sigma_s_par_ = 0, sigma_p_par_ = 0;
  double inv_sqrt2_sigma_s_ = 0, inv_sqrt2_sigma_p_ = 0;  // 1/(σ√2), for erfc
  // F_p's mean moves by kp1·a + kp2·b at lateral offset (a, b): k of PointRangeGivenLateral.
  double kp1_ = 0, kp2_ = 0;
  // Lateral covariance blocks (e1e1, e1e2, e2e2) of C_s and of C_p − C_s (C* = C_s + f(C_p − C_s)).
  double ls11_ = 0, ls12_ = 0, ls22_ = 0;
  double ld11_ = 0, ld12_ = 0, ld22_ = 0;
};

// Eq 4.7 for a single query (prepares the ray each call: for tests and one-offs). A degenerate
// ray (see PreparedRay::Make) gives {0.5, 0}: no information.
[[nodiscard]] CarveSample EvaluateCarveMap(const RayModel& ray, const Eigen::Vector3d& x);

// Eq 4.8 accumulation of one ray's vote into a leaf.
inline void FuseInto(LeafStats& leaf, const CarveSample& s) { leaf.Add(s.p, s.w); }

// e^−x for x ≥ 0, 0 from x = 708 on (where e^−x leaves the normal doubles). Our own rather than
// std::exp: glibc picks an exp by CPU (an FMA variant where there is FMA), and the tiles must be
// byte-identical whichever worker carves them (docs/DESIGN.md §5). x = (32m + j)·ln2/32 + r with
// |r| ≤ ln2/64 (Cody–Waite), e^−x = 2^−m · 2^(−j/32) · e^−r with 2^(−j/32) from a table
// (correctly rounded) and e^−r a degree-6 Taylor polynomial (truncation < 4e−18), evaluated in
// Estrin's order to keep the dependency chain short: within 4 ulp of e^−x.
inline constexpr double kExp2NegJ32[32] = {
    1.0, 0.9785720620877001, 0.9576032806985737, 0.93708381705515,
    0.9170040432046712, 0.8973545375015536, 0.8781260801866497, 0.859309649061239,
    0.8408964152537145, 0.8228777390769825, 0.8052451659746271, 0.7879904225539432,
    0.7711054127039704, 0.7545822137967114, 0.7384130729697497, 0.7225904034885233,
    0.7071067811865476, 0.691954940981916, 0.6771277734684463, 0.6626183215798707,
    0.6484197773255048, 0.6345254785958666, 0.620928906036742, 0.6076236799902345,
    0.5946035575013605, 0.5818624293887887, 0.5693943173783458, 0.5571933712979462,
    0.5452538663326288, 0.5335702003384118, 0.5221368912137069, 0.5109485743270583};

[[nodiscard]] inline double ExpNeg(double x) {
  if (!(x < 708.0)) return x == x ? 0.0 : x;  // NaN stays NaN
  constexpr double k32OverLn2 = 46.166241308446828;
  // ln2/32 split so that k·hi is exact for k < 2^21 (hi has 32 significant bits).
  constexpr double kHi = 6.93147180369123816490e-01 / 32, kLo = 1.90821492927058770002e-10 / 32;
  const int k = int(x * k32OverLn2 + 0.5);  // x ≥ 0: truncation is floor
  const double r = (x - k * kHi) - k * kLo;
  const double r2 = r * r;
  const double p = (1.0 - r) + r2 * ((0.5 - r * (1.0 / 6)) +
                                     r2 * ((1.0 / 24 - r * (1.0 / 120)) + r2 * (1.0 / 720)));
  return p * kExp2NegJ32[k & 31] * std::bit_cast<double>(uint64_t(1023 - (k >> 5)) << 52);
}

// ---- implementation of the hot path (inline so callers' loops can keep it in registers) ----

inline CarveSample PreparedRay::EvaluateProjected(double x_par, double a, double b) const {
  constexpr double kNoWeightExponent = 39.0;
  const double perp2 = a * a + b * b;  // |x_⊥|²

  double f_perp = 1.0;
  // |x_⊥| ≈ 0 means x is on the ray: f_⊥ = 1 (the limit of the formula below).
  if (perp2 > 1e-24) {
    const double f = std::clamp(x_par * inv_length_, 0.0, 1.0);
    const double c11 = ls11_ + f * ld11_, c12 = ls12_ + f * ld12_, c22 = ls22_ + f * ld22_;
    // ½ x_⊥ᵀ C*⊥⁻¹ x_⊥ with the 2×2 inverse written out: adj(C*⊥) quadratic form over det.
    const double q = c22 * a * a - 2.0 * c12 * a * b + c11 * b * b;
    const double det = c11 * c22 - c12 * c12;
    // Past this f_⊥ < 1e-17 and p = 0.5 to double precision: skip the two erfc calls.
    const double exponent = det > 0 ? 0.5 * q / det : kNoWeightExponent + 1;
    if (exponent > kNoWeightExponent) return CarveSample{0.5, 0.0};
    f_perp = ExpNeg(exponent);
  }
  // Φ(z) = 0.5 erfc(−z/√2): F_s(x_∥) = Φ(x_∥/σ_s), 1 − F_p(x_∥) = Φ((L − x_∥)/σ_p).
  // erfc(z) rounds to exactly 2 for z ≤ −6 (2 − 2e−17): skip the call there, which is most
  // of the ray (x_∥ well past the sensor and well short of the point), bit-identically.
  const double z_s = -x_par * inv_sqrt2_sigma_s_;
  const double z_p = ((x_par - length_) - (kp1_ * a + kp2_ * b)) * inv_sqrt2_sigma_p_;
  const double F_s = z_s <= -6.0 ? 1.0 : 0.5 * std::erfc(z_s);
  const double one_minus_F_p = z_p <= -6.0 ? 1.0 : 0.5 * std::erfc(z_p);
  return CarveSample{F_s * f_perp * one_minus_F_p + 0.5 * (1.0 - f_perp), f_perp};
}

inline CarveSample PreparedRay::Evaluate(const Eigen::Vector3d& x) const {
  const Eigen::Vector3d r = x - origin_;
  return EvaluateProjected(r.dot(dir_), r.dot(e1_), r.dot(e2_));
}

template <typename Sink>
void PreparedRay::EvaluateAlong(const Eigen::Vector3d& x0, const Eigen::Vector3d& step,
                                int first, int last, Sink&& sink) const {
  const Eigen::Vector3d r0 = x0 - origin_;
  const double p0 = r0.dot(dir_), a0 = r0.dot(e1_), b0 = r0.dot(e2_);
  const double dp = step.dot(dir_), da = step.dot(e1_), db = step.dot(e2_);
  for (int i = first; i <= last; ++i) {
    sink(i, EvaluateProjected(p0 + i * dp, a0 + i * da, b0 + i * db));
  }
}

}  // namespace carvemap
