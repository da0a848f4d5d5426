// FloatRay (eq 4.7 in single precision) against PreparedRay (the double reference).
#include "geometry/carve_map_float.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

TEST(CarveMapFloatTest, ExpNegWithinTwoUlp) {
  for (double x = 0; x <= 87; x += 0.0137) {
    const double want = std::exp(-double(float(x)));
    const float got = ExpNegFloat(float(x));
    EXPECT_NEAR(got, want, 2.5e-7 * want) << x;
  }
  EXPECT_EQ(ExpNegFloat(0.0f), 1.0f);
}

TEST(CarveMapFloatTest, ErfcWithinFiveTenMillionths) {
  for (double z = -7; z <= 10; z += 0.00731) {
    EXPECT_NEAR(ErfcFloat(float(z)), std::erfc(double(float(z))), 5e-7) << z;
  }
}

// Covariances of the kinds the wedge builder makes: round (localization), flat along a
// surface (the sampling term over a 1 mm floor), long along the ray (range noise), and random.
Matrix3d Covariance(std::mt19937& rng, int kind, const Vector3d& d) {
  std::uniform_real_distribution<double> u(-1, 1), sig(0.001, 0.12);
  switch (kind) {
    case 0:
      return Matrix3d::Identity() * std::pow(sig(rng), 2);
    case 1: {
      const Vector3d n = Vector3d(u(rng), u(rng), u(rng)).normalized();
      return (Matrix3d::Identity() - n * n.transpose()) * std::pow(0.025, 2) +
             n * n.transpose() * 1e-6;
    }
    case 2:
      return d * d.transpose() * std::pow(0.03, 2) + Matrix3d::Identity() * 1e-6;
    default: {
      Matrix3d a;
      for (int i = 0; i < 9; ++i) a(i) = u(rng);
      return a * a.transpose() * std::pow(sig(rng), 2) + 1e-6 * Matrix3d::Identity();
    }
  }
}

// A ray from a random place (mostly horizontal, 0.2–25 m long) with covariances of the kinds
// above, the kinds chosen by `trial`.
RayModel RandomRay(std::mt19937& rng, int trial) {
  std::uniform_real_distribution<double> u(-1, 1), len(0.2, 25);
  RayModel m;
  const Vector3d s(u(rng) * 50, u(rng) * 50, u(rng) * 5);
  const Vector3d d = Vector3d(u(rng), u(rng), u(rng) * 0.5).normalized();
  m.sensor_mean = s.cast<float>();
  m.point_mean = (s + d * len(rng)).cast<float>();
  m.sensor_cov = ToSymCov(Covariance(rng, trial % 4, d));
  m.point_cov = ToSymCov(Covariance(rng, (trial / 4) % 4, d));
  return m;
}

// Rows of leaves around random rays, at every distance from the sensor to past the point and
// up to several σ across: w and p within 5e−6 of the double path (absolute), and a vote with
// weight in one exactly where the other has one, but at the edge of the cut (f_⊥ ≈ 1e−17).
TEST(CarveMapFloatTest, RowsAgreeWithTheDoublePath) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  const double leaf = 0.0625;
  size_t compared = 0, weighted = 0;
  double worst_w = 0, worst_p = 0;
  for (int trial = 0; trial < 400; ++trial) {
    absl::StatusOr<PreparedRay> ref = PreparedRay::Make(RandomRay(rng, trial));
    ASSERT_TRUE(ref.ok());
    const int axis = trial % 3;
    const Eigen::Vector3d lattice = ref->origin() - Vector3d(20.3, 19.7, 21.1) * leaf;
    std::optional<FloatRay> fast = FloatRay::Make(*ref, lattice, leaf, axis);
    ASSERT_TRUE(fast.has_value()) << trial;
    Vector3d et = Vector3d::Unit(axis) * leaf, eu = Vector3d::Unit((axis + 1) % 3) * leaf,
             ev = Vector3d::Unit((axis + 2) % 3) * leaf;
    // Rows through points along the ray, shifted across it by up to 4 leaves.
    for (int k = 0; k < 12; ++k) {
      const double along = (k / 11.0) * (ref->length() + 0.5);
      Vector3d x = ref->origin() + ref->direction() * along;
      x += Vector3d(u(rng), u(rng), u(rng)) * 4 * leaf;
      const Vector3d rel = x - lattice;
      const int t0 = std::max(0, int(std::lround(rel.dot(et) / (leaf * leaf))));
      const int ru = std::max(0, int(std::lround(rel.dot(eu) / (leaf * leaf))));
      const int rv = std::max(0, int(std::lround(rel.dot(ev) / (leaf * leaf))));
      const int lo = std::max(0, t0 - 10 + k % 4), hi = t0 + 10 + k % 3;
      std::vector<float> w(hi - lo + 1), p(hi - lo + 1);
      fast->EvaluateRow(ru, rv, lo, hi, w.data(), p.data());
      for (int t = lo; t <= hi; ++t) {
        const CarveSample want = ref->Evaluate(lattice + t * et + ru * eu + rv * ev);
        const double dw = std::abs(w[t - lo] - want.w);
        const double dp = std::abs((0.5 + double(p[t - lo])) - want.p);
        // Near the cut e^−39 either may drop the vote; elsewhere both must agree.
        if (want.w > 1e-16 || w[t - lo] > 1e-16) {
          worst_w = std::max(worst_w, dw);
          worst_p = std::max(worst_p, dp);
          ++weighted;
        }
        ++compared;
      }
    }
  }
  std::printf("worst |dw| %.3g |dp| %.3g over %zu weighted of %zu\n", worst_w, worst_p, weighted,
              compared);
  EXPECT_LT(worst_w, 5e-6);
  EXPECT_LT(worst_p, 5e-6);
  // Not vacuous: a good share of the rows lies within the rays' weight.
  EXPECT_GT(weighted, compared / 5);
}

// Eight lanes and four give the same bits for every leaf (tiles must not depend on the CPU a
// worker runs on), whatever the row's length and where it lies against the ray.
TEST(CarveMapFloatTest, EightLanesGiveTheBitsOfFour) {
  if (!EightFloatLanesAvailable()) GTEST_SKIP() << "this CPU has no AVX2";
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> u(-1, 1);
  const double leaf = 0.03125;
  size_t compared = 0, weighted = 0;
  for (int trial = 0; trial < 300; ++trial) {
    absl::StatusOr<PreparedRay> ref = PreparedRay::Make(RandomRay(rng, trial));
    ASSERT_TRUE(ref.ok());
    const int axis = trial % 3;
    const Vector3d lattice = ref->origin() - Vector3d(40.3, 39.7, 41.1) * leaf;
    std::optional<FloatRay> fast = FloatRay::Make(*ref, lattice, leaf, axis);
    ASSERT_TRUE(fast.has_value()) << trial;
    for (int k = 0; k < 16; ++k) {
      // Rows of 1 to 40 leaves through points along the ray and a little across it.
      const Vector3d x = ref->origin() + ref->direction() * (k / 15.0) * (ref->length() + 0.3) +
                         Vector3d(u(rng), u(rng), u(rng)) * 3 * leaf - lattice;
      const int t0 = std::max(0, int(x[axis] / leaf) - 20);
      const int ru = std::max(0, int(x[(axis + 1) % 3] / leaf));
      const int rv = std::max(0, int(x[(axis + 2) % 3] / leaf));
      const int n = 1 + (trial * 16 + k) % 40;
      std::vector<float> w4(n), d4(n), w8(n), d8(n);
      fast->EvaluateRow(ru, rv, t0, t0 + n - 1, w4.data(), d4.data(), FloatLanes::kFour);
      fast->EvaluateRow(ru, rv, t0, t0 + n - 1, w8.data(), d8.data(), FloatLanes::kEight);
      for (int i = 0; i < n; ++i) {
        ASSERT_EQ(std::bit_cast<uint32_t>(w4[i]), std::bit_cast<uint32_t>(w8[i]))
            << trial << " " << k << " " << i;
        ASSERT_EQ(std::bit_cast<uint32_t>(d4[i]), std::bit_cast<uint32_t>(d8[i]))
            << trial << " " << k << " " << i;
        weighted += w4[i] > 1e-12f;
        ++compared;
      }
    }
  }
  EXPECT_GT(weighted, compared / 5);
}

// Where a row starts moves a leaf's value by float rounding only.
TEST(CarveMapFloatTest, ValueAtALeafHardlyDependsOnTheRowsStart) {
  RayModel m;
  m.sensor_mean = Eigen::Vector3f(0.3f, 0.2f, 1.1f);
  m.point_mean = Eigen::Vector3f(4.1f, 1.7f, 0.4f);
  m.sensor_cov = ToSymCov(Matrix3d::Identity() * 4e-4);
  m.point_cov = ToSymCov(Matrix3d::Identity() * 9e-4);
  absl::StatusOr<PreparedRay> ref = PreparedRay::Make(m);
  ASSERT_TRUE(ref.ok());
  std::optional<FloatRay> fast = FloatRay::Make(*ref, Vector3d(0.03125, 0.03125, 0.03125), 0.0625, 0);
  ASSERT_TRUE(fast.has_value());
  std::vector<float> w_all(64), p_all(64);
  fast->EvaluateRow(3, 16, 0, 63, w_all.data(), p_all.data());
  for (int lo = 0; lo < 64; lo += 7) {
    for (int hi = lo; hi < 64; hi += 5) {
      std::vector<float> w(hi - lo + 1), p(hi - lo + 1);
      fast->EvaluateRow(3, 16, lo, hi, w.data(), p.data());
      for (int t = lo; t <= hi; ++t) {
        ASSERT_NEAR(w[t - lo], w_all[t], 1e-6) << lo << " " << hi << " " << t;
        ASSERT_NEAR(p[t - lo], p_all[t], 1e-6) << lo << " " << hi << " " << t;
      }
    }
  }
}

// A vote of tiny weight inside a ray's free stretch still says "interior": p − 0.5 > 0 however
// small f_⊥ is (worker/chunk_octree.cc counts weights down to 1e−15 for wide wedges' middles),
// and both keep their relative precision (the exponent's ~1e−7 relative error times e ≤ 39).
TEST(CarveMapFloatTest, TinyWeightsKeepTheirSign) {
  RayModel m;
  m.sensor_mean = Eigen::Vector3f(0, 0, 0);
  m.point_mean = Eigen::Vector3f(5, 0, 0);
  m.sensor_cov = ToSymCov(Matrix3d::Identity() * 1e-4);
  m.point_cov = ToSymCov(Matrix3d::Identity() * 1e-4);
  absl::StatusOr<PreparedRay> ref = PreparedRay::Make(m);
  ASSERT_TRUE(ref.ok());
  // Rows along x at 5 … 8 cm across the ray (σ 1 cm): f_⊥ from e^−12.5 down to e^−32.
  std::optional<FloatRay> fast = FloatRay::Make(*ref, Vector3d(0, 0, 0), 0.01, 0);
  ASSERT_TRUE(fast.has_value());
  for (int across = 5; across <= 8; ++across) {
    std::vector<float> w(301), d(301);
    fast->EvaluateRow(across, 0, 100, 400, w.data(), d.data());
    for (int i = 0; i <= 300; ++i) {
      const CarveSample want = ref->Evaluate(Vector3d(0.01 * (100 + i), 0.01 * across, 0));
      ASSERT_GT(want.w, 1e-15);
      EXPECT_NEAR(w[i], want.w, 1e-5 * want.w) << across << " " << i;
      EXPECT_GT(d[i], 0.0f) << across << " " << i;  // 0.5 + d > 0.5
      // The reference holds p itself, so its p − 0.5 is only good to double's 1e−16 at 0.5.
      EXPECT_NEAR(d[i], want.p - 0.5, 1e-5 * (want.p - 0.5) + 1e-16) << across << " " << i;
    }
  }
}

// A lateral block without an inverse has no Cholesky: the caller keeps the double path.
TEST(CarveMapFloatTest, SingularLateralCovarianceIsRefused) {
  RayModel m;
  m.sensor_mean = Eigen::Vector3f(0, 0, 0);
  m.point_mean = Eigen::Vector3f(3, 0, 0);
  m.sensor_cov = {1e-4f, 0, 0, 1e-4f, 0, 0};  // nothing along z
  m.point_cov = {1e-4f, 0, 0, 1e-4f, 0, 1e-4f};
  absl::StatusOr<PreparedRay> ref = PreparedRay::Make(m);
  ASSERT_TRUE(ref.ok());
  EXPECT_FALSE(FloatRay::Make(*ref, Vector3d::Zero(), 0.0625, 0).has_value());
}

}  // namespace
}  // namespace carvemap
