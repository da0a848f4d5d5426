#include "geometry/octree_keys.h"

#include <cmath>
#include <random>

#include <gmock/gmock.h>
#include <vector>

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

namespace carvemap {
namespace {

using ::testing::HasSubstr;

TEST(OctreeGridTest, FromResolutionAcceptsPowersOfTwo) {
  for (int k = kMinChunkDepth; k <= kMaxChunkDepth; ++k) {
    const double r = 2.0 / (1 << k);
    auto grid = OctreeGrid::FromResolution(r);
    ASSERT_TRUE(grid.ok()) << grid.status();
    EXPECT_EQ(grid->chunk_depth, k);
    EXPECT_EQ(grid->resolution_m(), r);
    EXPECT_EQ(grid->leaves_per_side(), 1 << k);
    // Within 1e-9 relative (a value that went through text or float conversion).
    EXPECT_TRUE(OctreeGrid::FromResolution(r * (1 + 5e-10)).ok());
  }
  EXPECT_EQ(OctreeGrid::FromResolution(0.0625)->chunk_depth, 5);
  EXPECT_EQ(OctreeGrid::FromResolution(0.03125)->chunk_depth, 6);
  EXPECT_EQ(OctreeGrid::FromResolution(0.015625)->chunk_depth, 7);
  EXPECT_EQ(OctreeGrid::FromResolution(0.0078125)->chunk_depth, 8);
}

TEST(OctreeGridTest, FromResolutionRejectsOthers) {
  for (double r : {0.05, 0.1, 0.0625 * (1 + 1e-6), 2.0, 4.0, 2.0 / 2048, 0.0, -0.0625,
                   std::nan(""), double(INFINITY)}) {
    auto grid = OctreeGrid::FromResolution(r);
    ASSERT_FALSE(grid.ok()) << r;
    EXPECT_EQ(grid.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(grid.status().message(), HasSubstr("0.0625"));
    EXPECT_THAT(grid.status().message(), HasSubstr("0.0078125"));
  }
}

TEST(OctreeKeysTest, FloorForNegativeCoordinates) {
  const OctreeGrid grid{5};
  EXPECT_EQ(ChunkOf({-0.001, 0.0, 1.999}), ChunkKey(-1, 0, 0));
  EXPECT_EQ(ChunkOf({-2.0, -2.001, 2.0}), ChunkKey(-1, -2, 1));
  EXPECT_EQ(LeafOf(grid, {-0.001, 0.0, 0.0625}), LeafKey(-1, 0, 1));
  EXPECT_EQ(LeafOf(grid, {-0.0625, -0.0626, 0.0624}), LeafKey(-1, -2, 0));
  EXPECT_EQ(ChunkOfLeaf(grid, LeafKey(-1, -32, -33)), ChunkKey(-1, -1, -2));
  EXPECT_EQ(ChunkOfLeaf(grid, LeafKey(0, 31, 32)), ChunkKey(0, 0, 1));
}

class OctreeKeysDepthTest : public ::testing::TestWithParam<int> {};

TEST_P(OctreeKeysDepthTest, RoundTripsAndConsistency) {
  const OctreeGrid grid{GetParam()};
  std::mt19937_64 rng(42 + GetParam());
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3d x(u(rng), u(rng), u(rng));
    const LeafKey leaf = LeafOf(grid, x);
    const ChunkKey chunk = ChunkOf(x);
    EXPECT_EQ(ChunkOfLeaf(grid, leaf), chunk);
    // Boxes are half-open [min, max): x lies in its leaf and chunk.
    const Eigen::AlignedBox3d lb = LeafBox(grid, leaf);
    EXPECT_TRUE((x.array() >= lb.min().array()).all() && (x.array() < lb.max().array()).all());
    const Eigen::AlignedBox3d cb = ChunkBox(chunk);
    EXPECT_TRUE((x.array() >= cb.min().array()).all() && (x.array() < cb.max().array()).all());
    EXPECT_EQ(LeafOf(grid, LeafCenter(grid, leaf)), leaf);
    EXPECT_EQ(ChunkOf(LeafCenter(grid, leaf)), chunk);
    // The leaf as a node of its chunk.
    const ChunkNode node{leaf - chunk * grid.leaves_per_side(), grid.chunk_depth};
    EXPECT_TRUE((node.local.array() >= 0).all() &&
                (node.local.array() < grid.leaves_per_side()).all());
    EXPECT_TRUE(NodeBox(grid, chunk, node).isApprox(lb));
    EXPECT_EQ(MortonDecode(MortonCode(node.local)), node.local);
  }
  // Points exactly on boundaries go to the upper cell.
  const double r = grid.resolution_m();
  EXPECT_EQ(LeafOf(grid, {3 * r, -3 * r, 0}), LeafKey(3, -3, 0));
  EXPECT_EQ(ChunkOf({-4.0, 4.0, 0}), ChunkKey(-2, 2, 0));
}

TEST_P(OctreeKeysDepthTest, LeafBoxesTileTheChunkExactly) {
  const OctreeGrid grid{GetParam()};
  const ChunkKey chunk(-3, 1, -1);
  const int n = grid.leaves_per_side();
  // All 2^3k leaves up to k = 6; deeper, three whole z-slices (2^2k leaves each) keep it quick.
  const bool all_slices = grid.chunk_depth <= 6;
  std::vector<int> zs;
  for (int z = 0; z < n; ++z) {
    if (all_slices || z == 0 || z == n / 2 || z == n - 1) zs.push_back(z);
  }
  const Eigen::AlignedBox3d cb = ChunkBox(chunk);
  double volume = 0;
  for (int x = 0; x < n; ++x) {
    for (int y = 0; y < n; ++y) {
      for (int z : zs) {
        const LeafKey leaf = chunk * n + Eigen::Vector3i(x, y, z);
        const Eigen::AlignedBox3d b = LeafBox(grid, leaf);
        volume += b.volume();
        ASSERT_TRUE(cb.contains(b));
        ASSERT_EQ(ChunkOfLeaf(grid, leaf), chunk);
        // Neighbours share faces exactly (no gaps or overlaps in floating point).
        const Eigen::AlignedBox3d nx = LeafBox(grid, leaf + Eigen::Vector3i::UnitX());
        ASSERT_EQ(b.max().x(), nx.min().x());
      }
    }
  }
  EXPECT_DOUBLE_EQ(volume, cb.volume() * zs.size() / n);
  const LeafKey first = chunk * n;
  const LeafKey last = first + Eigen::Vector3i::Constant(n - 1);
  EXPECT_EQ(LeafBox(grid, first).min(), cb.min());
  EXPECT_EQ(LeafBox(grid, last).max(), cb.max());
}

TEST_P(OctreeKeysDepthTest, NodeBoxesNest) {
  const OctreeGrid grid{GetParam()};
  const ChunkKey chunk(2, -5, 0);
  EXPECT_TRUE(NodeBox(grid, chunk, ChunkNode{}).isApprox(ChunkBox(chunk)));
  std::mt19937 rng(7);
  for (int i = 0; i < 1000; ++i) {
    const int d = std::uniform_int_distribution<int>(1, grid.chunk_depth)(rng);
    std::uniform_int_distribution<int> c(0, (1 << d) - 1);
    const ChunkNode node{Eigen::Vector3i(c(rng), c(rng), c(rng)), d};
    const ChunkNode parent{node.local / 2, d - 1};
    const Eigen::AlignedBox3d b = NodeBox(grid, chunk, node);
    EXPECT_TRUE(NodeBox(grid, chunk, parent).contains(b));
    EXPECT_DOUBLE_EQ(b.sizes().x(), kChunkSizeM / (1 << d));
    // Morton: the parent's code is the child's code without its last triple.
    EXPECT_EQ(MortonCode(parent.local), MortonCode(node.local) >> 3);
  }
}

INSTANTIATE_TEST_SUITE_P(Depths, OctreeKeysDepthTest,
                         ::testing::Range(kMinChunkDepth, kMaxChunkDepth + 1));

TEST(MortonTest, BitLayout) {
  EXPECT_EQ(MortonCode({0, 0, 0}), 0u);
  EXPECT_EQ(MortonCode({1, 0, 0}), 1u);
  EXPECT_EQ(MortonCode({0, 1, 0}), 2u);
  EXPECT_EQ(MortonCode({0, 0, 1}), 4u);
  EXPECT_EQ(MortonCode({2, 0, 0}), 8u);
  EXPECT_EQ(MortonCode({3, 3, 3}), 63u);
  const int max = (1 << kMaxChunkDepth) - 1;
  EXPECT_EQ(MortonCode({max, max, max}), (uint64_t{1} << (3 * kMaxChunkDepth)) - 1);
  EXPECT_EQ(MortonDecode((uint64_t{1} << 30) - 1), Eigen::Vector3i(max, max, max));
  // Z-order: codes of one depth sort by the curve, all codes distinct.
  std::vector<uint64_t> codes;
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z) codes.push_back(MortonCode({x, y, z}));
  std::sort(codes.begin(), codes.end());
  for (size_t i = 0; i < codes.size(); ++i) EXPECT_EQ(codes[i], i);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> c(0, max);
  for (int i = 0; i < 10000; ++i) {
    const Eigen::Vector3i v(c(rng), c(rng), c(rng));
    ASSERT_EQ(MortonDecode(MortonCode(v)), v);
  }
}

// Our leaf key + 32768 is OctoMap's key at the same resolution, and our chunks are its nodes at
// depth 16 − k, so tiles export to .bt without resampling.
class OctomapAlignmentTest : public ::testing::TestWithParam<int> {};

TEST_P(OctomapAlignmentTest, LeafKeysMatchOctomap) {
  const OctreeGrid grid{GetParam()};
  octomap::OcTree tree(grid.resolution_m());
  std::mt19937_64 rng(11);
  // OctoMap's 16-level tree spans ±32768 leaves.
  const double half = 0.99 * 32768 * grid.resolution_m();
  std::uniform_real_distribution<float> u(-std::min(half, 200.0), std::min(half, 200.0));
  for (int i = 0; i < 20000; ++i) {
    // OctoMap takes float coordinates: draw floats, so both sides see the same point.
    octomap::point3d p(u(rng), u(rng), u(rng));
    if (i < 8) {
      p = octomap::point3d((i & 1) ? -1e-4f : 0.f, (i & 2) ? -float(grid.resolution_m()) : 0.7f,
                           (i & 4) ? -2.f : 2.f);
    }
    const Eigen::Vector3d x(p.x(), p.y(), p.z());
    octomap::OcTreeKey key;
    ASSERT_TRUE(tree.coordToKeyChecked(p, key));
    const LeafKey leaf = LeafOf(grid, x);
    ASSERT_EQ(leaf.x() + 32768, key[0]) << x.transpose();
    ASSERT_EQ(leaf.y() + 32768, key[1]) << x.transpose();
    ASSERT_EQ(leaf.z() + 32768, key[2]) << x.transpose();
    // The chunk is OctoMap's node at depth 16 − k: its key with the low k bits cleared.
    const octomap::OcTreeKey chunk_key = tree.adjustKeyAtDepth(key, 16 - grid.chunk_depth);
    const ChunkKey chunk = ChunkOf(x);
    const octomap::point3d center = tree.keyToCoord(chunk_key, 16 - grid.chunk_depth);
    const Eigen::Vector3d expected_center = ChunkBox(chunk).center();
    EXPECT_NEAR(center.x(), expected_center.x(), 1e-4);
    EXPECT_NEAR(center.y(), expected_center.y(), 1e-4);
    EXPECT_NEAR(center.z(), expected_center.z(), 1e-4);
    // And the leaf centre.
    const octomap::point3d lc = tree.keyToCoord(key);
    EXPECT_NEAR(lc.x(), LeafCenter(grid, leaf).x(), 1e-4);
  }
}

INSTANTIATE_TEST_SUITE_P(Depths, OctomapAlignmentTest, ::testing::Values(5, 6, 7, 8));

}  // namespace
}  // namespace carvemap
