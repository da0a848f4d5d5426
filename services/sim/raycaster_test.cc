#include "services/sim/raycaster.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "services/sim/sim_test_util.h"

namespace carvemap {
namespace {

// Distance from p along unit d to the inside of the box [0, size]: the nearest exit plane.
double BoxExit(const Eigen::Vector3d& p, const Eigen::Vector3d& d, const Eigen::Vector3d& size) {
  double best = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3; ++k) {
    if (d[k] > 1e-12) best = std::min(best, (size[k] - p[k]) / d[k]);
    if (d[k] < -1e-12) best = std::min(best, -p[k] / d[k]);
  }
  return best;
}

class RayCasterTest : public ::testing::TestWithParam<CastMode> {
 protected:
  void SetUp() override {
    building_ = testing::MakeBoxRoom(size_, /*table=*/false);
    auto c = RayCaster::Create(StructureMesh(building_), ObjectsMesh(building_));
    ASSERT_TRUE(c.ok()) << c.status();
    caster_ = *std::move(c);
  }
  Eigen::Vector3d size_{6, 4, 2.6};
  Building building_;
  std::unique_ptr<RayCaster> caster_;
};

TEST_P(RayCasterTest, BoxRoomDistancesAreExact) {
  std::mt19937_64 rng(301);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> n(0, 1);
  std::vector<RayQuery> rays;
  std::vector<double> expected;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d p(0.1 + 5.8 * u(rng), 0.1 + 3.8 * u(rng), 0.1 + 2.4 * u(rng));
    const Eigen::Vector3d d = Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
    rays.push_back(RayQuery{p.cast<float>(), d.cast<float>(), 30.0f});
    expected.push_back(BoxExit(p.cast<float>().cast<double>(), d.cast<float>().cast<double>(),
                               size_));
  }
  std::vector<RayHitResult> hits(rays.size());
  caster_->Cast(rays, hits, GetParam());
  for (size_t i = 0; i < rays.size(); ++i) {
    ASSERT_TRUE(hits[i].hit()) << i;
    EXPECT_EQ(hits[i].geometry, kHitStructure);
    EXPECT_NEAR(hits[i].distance_m, expected[i], 1e-4) << i;
  }
}

TEST_P(RayCasterTest, MissBeyondMaxRange) {
  std::vector<RayQuery> rays = {RayQuery{{1, 1, 1}, {1, 0, 0}, 4.9f},
                                RayQuery{{1, 1, 1}, {1, 0, 0}, 5.1f},
                                RayQuery{{1, 1, 1}, {0, 0, 1}, 30.0f}};
  std::vector<RayHitResult> hits(3);
  caster_->Cast(rays, hits, GetParam());
  EXPECT_FALSE(hits[0].hit());
  EXPECT_TRUE(std::isinf(hits[0].distance_m));
  ASSERT_TRUE(hits[1].hit());
  EXPECT_NEAR(hits[1].distance_m, 5.0, 1e-5);
  EXPECT_NEAR(hits[2].distance_m, 1.6, 1e-5);
}

INSTANTIATE_TEST_SUITE_P(Modes, RayCasterTest,
                         ::testing::Values(CastMode::kSingle, CastMode::kStream,
                                           CastMode::kPacket));

TEST(RayCaster, ObjectsAreGeometryOne) {
  const Building b = testing::MakeBoxRoom();  // table at x ∈ [4.8, 5.8], y ∈ [3.2, 3.8], z ≤ 0.75
  std::vector<int> object_of_triangle;
  auto c = RayCaster::Create(StructureMesh(b), ObjectsMesh(b, &object_of_triangle));
  ASSERT_TRUE(c.ok()) << c.status();
  const RayHitResult h = (*c)->Cast(RayQuery{{5.3f, 3.5f, 2.0f}, {0, 0, -1}, 30.0f});
  ASSERT_TRUE(h.hit());
  EXPECT_EQ(h.geometry, kHitObject);
  EXPECT_NEAR(h.distance_m, 1.25, 1e-5);
  EXPECT_EQ(object_of_triangle.at(h.primitive), 1);
}

TEST(RayCaster, ClosestPointMatchesBruteForce) {
  const Building b = testing::MakeBoxRoom();
  const TriangleMesh s = StructureMesh(b), o = ObjectsMesh(b);
  auto c = RayCaster::Create(s, o);
  ASSERT_TRUE(c.ok()) << c.status();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(-0.5f, 6.5f);
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3f p(u(rng), u(rng) * 0.7f, u(rng) * 0.45f);
    float brute = std::numeric_limits<float>::infinity();
    for (const TriangleMesh* m : {&s, &o}) {
      for (const Eigen::Vector3i& t : m->triangles) {
        brute = std::min(brute, (ClosestPointOnTriangle(p, m->vertices[t[0]], m->vertices[t[1]],
                                                        m->vertices[t[2]]) - p).norm());
      }
    }
    EXPECT_NEAR((*c)->Closest(p).distance_m, brute, 1e-5) << p.transpose();
  }
  EXPECT_NEAR((*c)->Closest({1, 1, 1}).distance_m, 1.0, 1e-6);
}

TEST(RayCaster, RejectsBadIndices) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 3}};
  EXPECT_FALSE(RayCaster::Create(m, {}).ok());
}

}  // namespace
}  // namespace carvemap
