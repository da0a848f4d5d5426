// RasterizeHull lists exactly the leaves HullIntersectsBox accepts, along each axis, sorted.
#include "worker/hull_raster.h"

#include <algorithm>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

RayModel Ray(const Eigen::Vector3d& s, const Eigen::Vector3d& p, float sigma) {
  RayModel r;
  r.sensor_mean = s.cast<float>();
  r.point_mean = p.cast<float>();
  const float var = sigma * sigma;
  r.sensor_cov = {var, 0, 0, var, 0, var};
  r.point_cov = {var, 0.1f * var, 0, 2 * var, 0, var};
  return r;
}

// A random wedge near chunk `chunk`: two sensor positions a few cm apart, four points in a
// small patch 0.5–4 m away (a line scanner's frame pair), or a single ray.
Wedge RandomWedge(std::mt19937& rng, const ChunkKey& chunk, bool single) {
  std::uniform_real_distribution<double> in(-0.5, 2.5), small(-0.05, 0.05), sig(0.002, 0.03);
  const Eigen::Vector3d base = chunk.cast<double>() * kChunkSizeM;
  const Eigen::Vector3d s0 = base + Eigen::Vector3d(in(rng), in(rng), in(rng));
  const Eigen::Vector3d s1 = s0 + Eigen::Vector3d(small(rng), small(rng), small(rng));
  const Eigen::Vector3d p = base + Eigen::Vector3d(in(rng), in(rng), in(rng));
  const Eigen::Vector3d du(small(rng), small(rng), small(rng)), dv(small(rng), small(rng), small(rng));
  const float sigma = float(sig(rng));
  Wedge w;
  w.rays = {Ray(s0, p, sigma), Ray(s0, p + du, sigma), Ray(s1, p + dv, sigma),
            Ray(s1, p + du + dv, sigma)};
  w.num_rays = single ? 1 : 4;
  if (single) w.rays.fill(w.rays[0]);
  return w;
}

std::set<std::tuple<int, int, int>> BruteForce(const WedgeHull& hull, const OctreeGrid& grid,
                                               const ChunkKey& chunk, const ChunkRegion* region) {
  std::set<std::tuple<int, int, int>> leaves;
  const int n = grid.leaves_per_side();
  ChunkNode node;
  node.depth = grid.chunk_depth;
  for (int x = 0; x < n; ++x)
    for (int y = 0; y < n; ++y)
      for (int z = 0; z < n; ++z) {
        node.local = Eigen::Vector3i(x, y, z);
        if (region != nullptr && !region->Intersects(node)) continue;
        if (HullIntersectsBox(hull, NodeBox(grid, chunk, node))) leaves.emplace(x, y, z);
      }
  return leaves;
}

std::set<std::tuple<int, int, int>> FromRuns(const std::vector<LeafRun>& runs, int axis) {
  std::set<std::tuple<int, int, int>> leaves;
  for (LeafRun r : runs) {
    for (int t = RunLo(r); t <= RunHi(r); ++t) {
      Eigen::Vector3i l;
      l[axis] = t;
      l[(axis + 1) % 3] = RunU(r);
      l[(axis + 2) % 3] = RunV(r);
      EXPECT_TRUE(leaves.emplace(l.x(), l.y(), l.z()).second) << "leaf listed twice";
    }
  }
  return leaves;
}

TEST(HullRasterTest, RunPackingRoundTrips) {
  const LeafRun r = MakeLeafRun(1023, 5, 7, 900);
  EXPECT_EQ(RunU(r), 1023);
  EXPECT_EQ(RunV(r), 5);
  EXPECT_EQ(RunLo(r), 7);
  EXPECT_EQ(RunHi(r), 900);
  EXPECT_LT(MakeLeafRun(1000, 0, 0, 0), MakeLeafRun(0, 1, 0, 0));  // rows by v, then u
  EXPECT_LT(MakeLeafRun(1, 1, 900, 900), MakeLeafRun(2, 1, 0, 0));
}

TEST(HullRasterTest, ListsExactlyTheLeavesHullIntersectsBoxAccepts) {
  std::mt19937 rng(301);
  OctreeGrid grid;
  size_t total = 0;
  for (int trial = 0; trial < 120; ++trial) {
    grid.chunk_depth = 3 + trial % 3;  // 25, 12.5, 6.25 cm
    const ChunkKey chunk(trial % 2 ? -3 : 1, 0, trial % 3 - 1);
    const Wedge w = RandomWedge(rng, chunk, trial % 7 == 0);
    const WedgeHull hull = MakeWedgeHull(w, 3.0);
    const auto expected = BruteForce(hull, grid, chunk, nullptr);
    for (int axis = 0; axis < 3; ++axis) {
      std::vector<LeafRun> runs;
      const size_t n = RasterizeHull(hull, grid, chunk, axis, nullptr, runs);
      EXPECT_TRUE(std::is_sorted(runs.begin(), runs.end()));
      EXPECT_EQ(n, expected.size());
      EXPECT_EQ(FromRuns(runs, axis), expected) << "trial " << trial << " axis " << axis;
    }
    total += expected.size();
  }
  // The wedges do reach into their chunks (4764 leaves since single rays are 1σ wide, 1ec8c95).
  EXPECT_GT(total, 4000u);
}

TEST(HullRasterTest, RegionKeepsOnlyItsLeaves) {
  std::mt19937 rng(7);
  OctreeGrid grid;
  grid.chunk_depth = 5;
  const ChunkKey chunk(0, 0, 0);
  std::vector<Eigen::Vector3i> cells;
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x)
        if ((x + y + z) % 3 == 0) cells.emplace_back(x, y, z);
  const ChunkRegion region(3, cells);
  size_t total = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const WedgeHull hull = MakeWedgeHull(RandomWedge(rng, chunk, false), 3.0);
    const auto expected = BruteForce(hull, grid, chunk, &region);
    for (int axis = 0; axis < 3; ++axis) {
      std::vector<LeafRun> runs;
      EXPECT_EQ(RasterizeHull(hull, grid, chunk, axis, &region, runs), expected.size());
      EXPECT_TRUE(std::is_sorted(runs.begin(), runs.end()));
      EXPECT_EQ(FromRuns(runs, axis), expected);
    }
    total += expected.size();
  }
  EXPECT_GT(total, 100u);
}

// Regions at, above and below the leaves' depth (read row by row, or leaf by leaf when finer
// than the leaves), with random cells: the runs list exactly the leaves HullIntersectsBox
// accepts inside the region.
TEST(HullRasterTest, RegionsOfEveryDepthKeepOnlyTheirLeaves) {
  std::mt19937 rng(19);
  OctreeGrid grid;
  grid.chunk_depth = 4;
  const ChunkKey chunk(1, -1, 0);
  size_t total = 0;
  for (int depth : {2, 4, 5}) {
    const int n = 1 << depth;
    std::vector<Eigen::Vector3i> cells;
    std::bernoulli_distribution keep(0.3);
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x)
          if (keep(rng)) cells.emplace_back(x, y, z);
    const ChunkRegion region(depth, cells);
    for (int trial = 0; trial < 15; ++trial) {
      const WedgeHull hull = MakeWedgeHull(RandomWedge(rng, chunk, trial % 4 == 0), 3.0);
      const auto expected = BruteForce(hull, grid, chunk, &region);
      for (int axis = 0; axis < 3; ++axis) {
        std::vector<LeafRun> runs;
        EXPECT_EQ(RasterizeHull(hull, grid, chunk, axis, &region, runs), expected.size())
            << depth << " " << trial << " " << axis;
        EXPECT_TRUE(std::is_sorted(runs.begin(), runs.end()));
        EXPECT_EQ(FromRuns(runs, axis), expected);
      }
      total += expected.size();
    }
  }
  EXPECT_GT(total, 300u);
}

// Hulls whose faces are parallel, or nearly, to the rows (a ray along an axis, tilted by up
// to 1e−2): the row bounds of such faces come from divisions by their tiny slopes, where
// rounding is largest. Points and sensors on leaf boundaries too.
TEST(HullRasterTest, AxisAlignedAndNearlyAlignedHullsAreExact) {
  OctreeGrid grid;
  const ChunkKey chunk(0, -1, 1);
  const Eigen::Vector3d base = chunk.cast<double>() * kChunkSizeM;
  size_t total = 0;
  int trial = 0;
  for (const double tilt : {0.0, 1e-12, 1e-7, 1e-4, 9e-4, 1.1e-3, 1e-2}) {
    for (int depth : {3, 5}) {
      grid.chunk_depth = depth;
      const double s = grid.resolution_m();
      for (int along = 0; along < 3; ++along) {
        ++trial;
        Eigen::Vector3d dir = Eigen::Vector3d::Zero();
        dir[along] = 1;
        dir[(along + 1) % 3] = tilt;
        dir[(along + 2) % 3] = trial % 2 ? -tilt / 3 : 0;
        // On a leaf corner, or a third of a leaf off it.
        const Eigen::Vector3d s0 = base + Eigen::Vector3d(3, 5, 7) * s +
                                   (trial % 3 == 0 ? Eigen::Vector3d::Constant(s / 3)
                                                   : Eigen::Vector3d::Zero());
        Eigen::Vector3d du = Eigen::Vector3d::Zero(), dv = du;
        du[(along + 1) % 3] = 2 * s;
        dv[(along + 2) % 3] = s;
        const Eigen::Vector3d p = s0 + 1.5 * dir.normalized();
        Wedge w;
        w.rays = {Ray(s0, p, 0.002f), Ray(s0, p + du, 0.002f), Ray(s0 + dv * 0.1, p + dv, 0.002f),
                  Ray(s0 + dv * 0.1, p + du + dv, 0.002f)};
        for (int num_rays : {1, 4}) {
          w.num_rays = num_rays;
          const WedgeHull hull = MakeWedgeHull(w, 3.0);
          const auto expected = BruteForce(hull, grid, chunk, nullptr);
          for (int axis = 0; axis < 3; ++axis) {
            std::vector<LeafRun> runs;
            EXPECT_EQ(RasterizeHull(hull, grid, chunk, axis, nullptr, runs), expected.size());
            EXPECT_EQ(FromRuns(runs, axis), expected)
                << "tilt " << tilt << " depth " << depth << " along " << along << " rays "
                << num_rays << " axis " << axis;
          }
          total += expected.size();
        }
      }
    }
  }
  EXPECT_GT(total, 1000u);
}

TEST(HullRasterTest, HullOutsideTheChunkListsNothing) {
  std::mt19937 rng(11);
  OctreeGrid grid;
  const WedgeHull hull = MakeWedgeHull(RandomWedge(rng, ChunkKey(0, 0, 0), false), 3.0);
  std::vector<LeafRun> runs;
  EXPECT_EQ(RasterizeHull(hull, grid, ChunkKey(10, 0, 0), 0, nullptr, runs), 0u);
  EXPECT_TRUE(runs.empty());
}

}  // namespace
}  // namespace carvemap
