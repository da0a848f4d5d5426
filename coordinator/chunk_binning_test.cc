#include "coordinator/chunk_binning.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <set>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

using Eigen::Vector3d;

SymCov3f RandomCov(std::mt19937_64& rng, double max_sigma) {
  std::normal_distribution<double> n(0, 1);
  Eigen::Matrix3d a;
  for (int i = 0; i < 9; ++i) a(i) = n(rng);
  const double s = std::uniform_real_distribution<double>(0, max_sigma)(rng);
  return ToSymCov(s * s * a * a.transpose() / 3);
}

// Rays from near one sensor position, `max_range_m` long at most; every 5th is a single ray,
// every 7th flat.
Wedge RandomWedge(std::mt19937_64& rng, int i, double max_range_m) {
  std::uniform_real_distribution<double> u(-1, 1);
  auto uv = [&] { return Vector3d(u(rng), u(rng), u(rng)); };
  const Vector3d sensor = 8 * uv();
  const Vector3d dir = uv().normalized();
  const double range = std::uniform_real_distribution<double>(0.2, max_range_m)(rng);
  const double spread = std::uniform_real_distribution<double>(0.001, 0.1)(rng) * range;
  Wedge w;
  for (RayModel& r : w.rays) {
    const Vector3d s = i % 7 == 0 ? sensor : Vector3d(sensor + 0.03 * uv());
    Vector3d p = sensor + range * dir + spread * uv();
    if (i % 7 == 0) p = sensor + range * dir + spread * u(rng) * dir.unitOrthogonal();
    r = RayModel{s.cast<float>(), p.cast<float>(), RandomCov(rng, 0.01), RandomCov(rng, 0.04)};
  }
  w.num_rays = i % 5 == 0 ? 1 : 4;
  return w;
}

std::vector<ChunkKey> BruteForceChunks(const WedgeHull& hull) {
  std::vector<ChunkKey> out;
  const ChunkKey lo = ChunkOf(hull.box.min()), hi = ChunkOf(hull.box.max());
  for (int x = lo.x(); x <= hi.x(); ++x)
    for (int y = lo.y(); y <= hi.y(); ++y)
      for (int z = lo.z(); z <= hi.z(); ++z)
        if (HullIntersectsBox(hull, ChunkBox({x, y, z}))) out.emplace_back(x, y, z);
  return out;  // x-major: already sorted by ChunkKeyLess
}

TEST(ChunkBinningTest, SmallWedgeInsideOneChunk) {
  Wedge w;
  for (RayModel& r : w.rays) {
    r = RayModel{Eigen::Vector3f(0.5f, 0.5f, 0.5f), Eigen::Vector3f(1.5f, 0.6f, 0.7f), {}, {}};
  }
  w.rays[1].point_mean.y() = 0.9f;
  w.rays[2].point_mean.z() = 0.9f;
  EXPECT_EQ(ChunksOfWedge(w), std::vector<ChunkKey>{ChunkKey(0, 0, 0)});
}

TEST(ChunkBinningTest, NegativeCoordinatesAndBoundaries) {
  Wedge w;
  w.num_rays = 1;
  // Along x from −3 m to +1 m at y = z = −1 m: chunks x ∈ {−2, −1, 0}, y = z = −1.
  w.rays[0] = RayModel{Eigen::Vector3f(-3, -1, -1), Eigen::Vector3f(1, -1, -1), {}, {}};
  const std::vector<ChunkKey> got = ChunksOfWedge(w);
  // The 1 mm dilation keeps y, z = −1 ± 0.001 inside chunk −1.
  const std::vector<ChunkKey> want = {{-2, -1, -1}, {-1, -1, -1}, {0, -1, -1}};
  EXPECT_EQ(got, want);
  // On the face y = 0 between chunks: both sides.
  w.rays[0] = RayModel{Eigen::Vector3f(0.5, 0, 0.5), Eigen::Vector3f(1.5, 0, 0.5), {}, {}};
  const std::vector<ChunkKey> face = {{0, -1, 0}, {0, 0, 0}};
  EXPECT_EQ(ChunksOfWedge(w), face);
}

TEST(ChunkBinningTest, RejectsAbsurdHulls) {
  WedgeHull h;
  EXPECT_TRUE(ChunksOfWedge(h).empty());  // empty box
  h.box = Eigen::AlignedBox3d(Vector3d(0, 0, 0), Vector3d(1, 1, std::nan("")));
  EXPECT_TRUE(ChunksOfWedge(h).empty());
  h.box = Eigen::AlignedBox3d(Vector3d(0, 0, 0), Vector3d(1, 1, 1e9));
  EXPECT_TRUE(ChunksOfWedge(h).empty());
}

TEST(ChunkBinningTest, EqualsTestingEveryChunk) {
  std::mt19937_64 rng(17);
  for (int i = 0; i < 500; ++i) {
    const WedgeHull h = MakeWedgeHull(RandomWedge(rng, i, 30.0));
    const std::vector<ChunkKey> got = ChunksOfWedge(h);
    ASSERT_EQ(got, BruteForceChunks(h)) << i;
    ASSERT_FALSE(got.empty());
  }
}

// Chunking is complete: every finest leaf (6.25 cm) whose box intersects the hull, and every
// point of the wedge's volume, lies in a returned chunk.
TEST(ChunkBinningTest, ChunkingIsComplete) {
  const OctreeGrid grid{5};
  std::mt19937_64 rng(23);
  size_t leaves_checked = 0;
  for (int i = 0; i < 60; ++i) {
    const Wedge w = RandomWedge(rng, i, 4.0);
    const WedgeHull h = MakeWedgeHull(w);
    const std::vector<ChunkKey> chunks = ChunksOfWedge(h);
    const std::set<ChunkKey, ChunkKeyLess> set(chunks.begin(), chunks.end());
    const LeafKey lo = LeafOf(grid, h.box.min()), hi = LeafOf(grid, h.box.max());
    // Leaves a little beyond the hull's box too (they must not intersect, or be covered).
    for (int x = lo.x() - 1; x <= hi.x() + 1; ++x) {
      for (int y = lo.y() - 1; y <= hi.y() + 1; ++y) {
        for (int z = lo.z() - 1; z <= hi.z() + 1; ++z) {
          const LeafKey leaf(x, y, z);
          if (!HullIntersectsBox(h, LeafBox(grid, leaf))) continue;
          ++leaves_checked;
          ASSERT_TRUE(set.count(ChunkOfLeaf(grid, leaf))) << i << " " << leaf.transpose();
        }
      }
    }
    // Points of the volume (convex combinations of its corners).
    std::vector<Vector3d> corners;
    for (int r = 0; r < w.num_rays; ++r) {
      corners.push_back(w.rays[r].sensor_mean.cast<double>());
      corners.push_back(ExtendedPointMean(w.rays[r]));
    }
    std::uniform_real_distribution<double> u(0, 1);
    for (int s = 0; s < 2000; ++s) {
      Vector3d x = Vector3d::Zero();
      double sum = 0;
      for (const Vector3d& c : corners) {
        const double wt = std::pow(u(rng), 4);
        x += wt * c;
        sum += wt;
      }
      x /= sum;
      ASSERT_TRUE(set.count(ChunkOf(x))) << i;
    }
  }
  EXPECT_GT(leaves_checked, 10000u);
}

TEST(ChunkBinningTest, Timing) {
  std::mt19937_64 rng(29);
  for (double range : {3.0, 10.0, 30.0}) {
    std::vector<WedgeHull> hulls;
    for (int i = 0; i < 2000; ++i) hulls.push_back(MakeWedgeHull(RandomWedge(rng, i, range)));
    size_t n = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (const WedgeHull& h : hulls) n += ChunksOfWedge(h).size();
    const auto t1 = std::chrono::steady_clock::now();
    std::printf("ChunksOfWedge, rays up to %.0f m: %.2f us/wedge, %.2f chunks/wedge\n", range,
                std::chrono::duration<double, std::micro>(t1 - t0).count() / hulls.size(),
                double(n) / hulls.size());
  }
}

}  // namespace
}  // namespace carvemap
