#include "geometry/chunk_region.h"

#include <random>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

ChunkNode Node(int depth, int x, int y, int z) { return ChunkNode{Eigen::Vector3i(x, y, z), depth}; }

TEST(ChunkRegionTest, EmptyIntersectsNothing) {
  const ChunkRegion none;
  EXPECT_TRUE(none.empty());
  EXPECT_FALSE(none.Intersects(Node(0, 0, 0, 0)));
  const ChunkRegion also_none(3, {{-1, 0, 0}, {8, 0, 0}});  // outside the chunk: ignored
  EXPECT_TRUE(also_none.empty());
  EXPECT_FALSE(also_none.Intersects(Node(0, 0, 0, 0)));
}

TEST(ChunkRegionTest, BoxesMeetTheCellsTheyOverlap) {
  // Cells (5, 2, 7) and (0, 0, 0) at depth 3: 25 cm cells.
  const ChunkRegion r(3, {{5, 2, 7}, {0, 0, 0}});
  const Eigen::Vector3d c(5 * 0.25, 2 * 0.25, 7 * 0.25);  // the first cell's low corner
  EXPECT_TRUE(r.IntersectsBox(c + Eigen::Vector3d::Constant(0.1), c + Eigen::Vector3d::Constant(0.2)));
  EXPECT_TRUE(r.IntersectsBox(c - Eigen::Vector3d::Constant(0.3), c));  // touches its corner
  const Eigen::Vector3d top = c + Eigen::Vector3d::Constant(0.25);   // its far corner
  EXPECT_TRUE(r.IntersectsBox(top, top + Eigen::Vector3d::Constant(0.1)));
  EXPECT_FALSE(r.IntersectsBox(c - Eigen::Vector3d::Constant(0.3), c - Eigen::Vector3d::Constant(0.01)));
  EXPECT_TRUE(r.IntersectsBox(Eigen::Vector3d(-5, -5, -5), Eigen::Vector3d(0.01, 0.01, 0.01)));
  EXPECT_FALSE(r.IntersectsBox(Eigen::Vector3d(1.0, 1.0, 0), Eigen::Vector3d(2.5, 2.5, 1.5)));
  EXPECT_FALSE(r.IntersectsBox(Eigen::Vector3d(3, 0, 0), Eigen::Vector3d(4, 1, 1)));  // outside
  EXPECT_FALSE(ChunkRegion().IntersectsBox(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones()));
  // Against the cell-by-cell answer on random boxes.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.5, 2.5);
  for (int i = 0; i < 2000; ++i) {
    Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const Eigen::Vector3d lo = a.cwiseMin(b), hi = a.cwiseMax(b);
    bool want = false;
    for (const Eigen::Vector3i& cell : {Eigen::Vector3i(5, 2, 7), Eigen::Vector3i(0, 0, 0)}) {
      const Eigen::Vector3d l = cell.cast<double>() * 0.25, h = l + Eigen::Vector3d::Constant(0.25);
      want |= (lo.array() <= h.array()).all() && (hi.array() >= l.array()).all();
    }
    EXPECT_EQ(r.IntersectsBox(lo, hi), want) << lo.transpose() << " / " << hi.transpose();
  }
}

// Scattered cells over a part of the chunk, as an object's region is: small boxes that fall
// between cells, inside the cells' bounding box, must say false; the answer is the
// cell-by-cell one on every box.
TEST(ChunkRegionTest, BoxesAmongScatteredCellsMatchCellByCell) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(3, 12);
  std::vector<Eigen::Vector3i> cells;
  for (int i = 0; i < 60; ++i) cells.emplace_back(coord(rng), coord(rng), coord(rng));
  const ChunkRegion r(4, cells);  // 12.5 cm cells
  const double cell = 0.125;
  std::uniform_real_distribution<double> start(-0.2, 2.2), size(0, 0.4);
  int hits = 0;
  for (int i = 0; i < 5000; ++i) {
    const Eigen::Vector3d lo(start(rng), start(rng), start(rng));
    const Eigen::Vector3d hi = lo + Eigen::Vector3d(size(rng), size(rng), size(rng));
    bool want = false;
    for (const Eigen::Vector3i& c : cells) {
      const Eigen::Vector3d l = c.cast<double>() * cell, h = l + Eigen::Vector3d::Constant(cell);
      want |= (lo.array() <= h.array()).all() && (hi.array() >= l.array()).all();
    }
    hits += want;
    ASSERT_EQ(r.IntersectsBox(lo, hi), want) << lo.transpose() << " / " << hi.transpose();
  }
  EXPECT_GT(hits, 500);  // both answers were tested
  EXPECT_LT(hits, 4500);
}

TEST(ChunkRegionTest, NodesOfEveryDepth) {
  // One cell (5, 2, 7) at depth 3 (25 cm cells).
  const ChunkRegion r(3, {{5, 2, 7}});
  EXPECT_EQ(r.count(), 1u);
  EXPECT_TRUE(r.Intersects(Node(0, 0, 0, 0)));   // the chunk
  EXPECT_TRUE(r.Intersects(Node(1, 1, 0, 1)));   // the octant holding it
  EXPECT_FALSE(r.Intersects(Node(1, 0, 0, 1)));  // another octant
  EXPECT_TRUE(r.Intersects(Node(2, 2, 1, 3)));
  EXPECT_FALSE(r.Intersects(Node(2, 2, 1, 2)));
  EXPECT_TRUE(r.Intersects(Node(3, 5, 2, 7)));
  EXPECT_FALSE(r.Intersects(Node(3, 5, 2, 6)));
  EXPECT_FALSE(r.Intersects(Node(3, 4, 2, 7)));
  // Finer nodes: inside the cell or not.
  EXPECT_TRUE(r.Intersects(Node(5, 5 * 4 + 3, 2 * 4, 7 * 4 + 1)));
  EXPECT_FALSE(r.Intersects(Node(5, 6 * 4, 2 * 4, 7 * 4)));
}

TEST(ChunkRegionTest, RowRunsAreTheRowsCells) {
  std::mt19937 rng(5);
  std::bernoulli_distribution keep(0.4);
  const int depth = 3, n = 1 << depth;
  std::vector<Eigen::Vector3i> cells;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        if (keep(rng)) cells.emplace_back(x, y, z);
  const ChunkRegion region(depth, cells);
  for (int axis = 0; axis < 3; ++axis) {
    for (int v = 0; v < n; ++v) {
      for (int u = 0; u < n; ++u) {
        std::vector<bool> in_runs(n, false);
        int previous_last = -2;
        for (const ChunkRegion::CellRun& r : region.RowRuns(axis, u, v)) {
          EXPECT_LE(r.first, r.last);
          EXPECT_GT(int(r.first), previous_last + 1);  // ascending and maximal
          previous_last = r.last;
          for (int t = r.first; t <= r.last; ++t) in_runs[t] = true;
        }
        for (int t = 0; t < n; ++t) {
          Eigen::Vector3i c;
          c[axis] = t;
          c[(axis + 1) % 3] = u;
          c[(axis + 2) % 3] = v;
          EXPECT_EQ(in_runs[t], region.Intersects(ChunkNode{c, depth})) << axis << u << v << t;
        }
      }
    }
  }
  EXPECT_TRUE(ChunkRegion().RowRuns(0, 0, 0).empty());
}

TEST(ChunkRegionTest, EncodeDecodeRoundTrip) {
  const ChunkRegion r(5, {{0, 0, 0}, {31, 31, 31}, {3, 17, 9}, {4, 17, 9}});
  const std::string bits = r.Encode();
  EXPECT_EQ(bits.size(), 32u * 32 * 32 / 8);
  absl::StatusOr<ChunkRegion> back = ChunkRegion::Decode(5, bits);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->count(), 4u);
  EXPECT_EQ(back->Encode(), bits);
  for (int d = 0; d <= 7; ++d) {
    const int s = 1 << d;
    for (const Eigen::Vector3i& probe :
         {Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(s - 1, s - 1, s - 1),
                                        Eigen::Vector3i(s / 2, s / 2, s / 2)}) {
      EXPECT_EQ(back->Intersects(ChunkNode{probe, d}), r.Intersects(ChunkNode{probe, d}));
    }
  }
  EXPECT_FALSE(ChunkRegion::Decode(5, bits.substr(1)).ok());
  EXPECT_FALSE(ChunkRegion::Decode(9, bits).ok());
  EXPECT_FALSE(ChunkRegion::Decode(-1, "").ok());
  // Depth 1: 8 cells in one byte.
  absl::StatusOr<ChunkRegion> tiny = ChunkRegion::Decode(1, std::string(1, char(0x81)));
  ASSERT_TRUE(tiny.ok());
  EXPECT_TRUE(tiny->Intersects(Node(1, 0, 0, 0)));
  EXPECT_TRUE(tiny->Intersects(Node(1, 1, 1, 1)));
  EXPECT_FALSE(tiny->Intersects(Node(1, 1, 0, 0)));
}

// What the tables hold: the rows' tables of the whole chunk (~87 KB at depth 6) and the
// summed-volume table over the cells' bounding box, which dominates for a region spread over
// the chunk (~1.2 MB at depth 6); an empty region holds nearly nothing.
TEST(ChunkRegionTest, MemoryBytesFollowTheBoundingBox) {
  EXPECT_LT(ChunkRegion().memory_bytes(), 64u);
  const ChunkRegion corner(6, {{0, 0, 0}, {1, 1, 1}});
  const ChunkRegion spread(6, {{0, 0, 0}, {63, 63, 63}});
  EXPECT_GE(spread.memory_bytes(), 65u * 65 * 65 * sizeof(uint32_t));
  EXPECT_LT(spread.memory_bytes(), 2 * 65u * 65 * 65 * sizeof(uint32_t));
  EXPECT_LT(corner.memory_bytes(), spread.memory_bytes() / 10);
  EXPECT_GT(corner.memory_bytes(), 3u * 3 * 3 * sizeof(uint32_t));
}

}  // namespace
}  // namespace carvemap
