#include "services/mesh/self_intersections.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "services/mesh/cube_mesh_testing.h"

namespace carvemap {
namespace {

using testing::AddCube;

TEST(SelfIntersections, AClosedCubeHasNone) {
  TriangleMesh m;
  AddCube(m, Eigen::Vector3f::Zero(), 1);
  const SelfIntersections s = CountSelfIntersections(m);
  EXPECT_EQ(s.pairs, 0u);
  EXPECT_EQ(s.unchecked, 0u);
}

TEST(SelfIntersections, TwoApartCubesHaveNoneAndTwoOverlappingOnesDo) {
  TriangleMesh apart;
  AddCube(apart, Eigen::Vector3f::Zero(), 1);
  AddCube(apart, Eigen::Vector3f(2, 0, 0), 1);
  EXPECT_EQ(CountSelfIntersections(apart).pairs, 0u);
  // The second cube's corner pushed into the first: each watertight, together crossing. The
  // faces x = 1, y = 1, z = 1 of the first cross the faces x = .5, y = .5, z = .5 of the
  // second: every such pair of triangles whose squares' parts overlap.
  TriangleMesh crossing;
  AddCube(crossing, Eigen::Vector3f::Zero(), 1);
  AddCube(crossing, Eigen::Vector3f::Constant(0.5f), 1);
  const SelfIntersections s = CountSelfIntersections(crossing);
  EXPECT_GT(s.pairs, 0u);
  EXPECT_EQ(s.unchecked, 0u);
}

TEST(SelfIntersections, AFoldedNeighbourIsFound) {
  // Two triangles on the edge (0, 1), the second folded back onto the first (coplanar, on the
  // same side): they share an edge and overlap beyond it.
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0.5f, 1, 0}, {0.5f, 0.5f, 0}};
  m.triangles = {{0, 1, 2}, {1, 0, 3}};
  EXPECT_EQ(CountSelfIntersections(m).pairs, 1u);
  // Unfolded (the fourth vertex across the edge) they only share it.
  m.vertices[3] = {0.5f, -1, 0};
  EXPECT_EQ(CountSelfIntersections(m).pairs, 0u);
}

TEST(SelfIntersections, TheCountDoesNotDependOnTheSlabsNorTheThreads) {
  // A row of cubes along x, each pushed into the one before it (and a few apart): pairs cross
  // in many places, some at slab boundaries whatever the slab size.
  TriangleMesh m;
  for (int i = 0; i < 12; ++i) {
    AddCube(m, Eigen::Vector3f(0.7f * i + (i % 4 == 3 ? 0.4f : 0.f), 0.1f * (i % 3), 0), 1);
  }
  const SelfIntersections whole = CountSelfIntersections(m, 1, m.triangles.size());
  EXPECT_GT(whole.pairs, 0u);
  for (int threads : {1, 3}) {
    for (size_t per_slab : {1, 5, 12, 30, 100}) {
      const SelfIntersections s = CountSelfIntersections(m, threads, per_slab);
      EXPECT_EQ(s.pairs, whole.pairs) << per_slab << " triangles per slab, " << threads
                                      << " threads";
      EXPECT_EQ(s.unchecked, 0u);
    }
  }
}

TEST(SelfIntersections, WindowsAlongXSumToTheWholeCount) {
  TriangleMesh m;
  for (int i = 0; i < 12; ++i) {
    AddCube(m, Eigen::Vector3f(0.7f * i + (i % 4 == 3 ? 0.4f : 0.f), 0.1f * (i % 3), 0), 1);
  }
  const SelfIntersections whole = CountSelfIntersections(m);
  // Windows of 1.5 m, each given only the triangles reaching into it, as the dense mesh's
  // stream counts them.
  uint64_t sum = 0;
  for (double lo = -1.5; lo < 10; lo += 1.5) {
    TriangleMesh part;
    part.vertices = m.vertices;
    for (const Eigen::Vector3i& t : m.triangles) {
      float x0 = INFINITY, x1 = -INFINITY;
      for (int k = 0; k < 3; ++k) {
        x0 = std::min(x0, m.vertices[t[k]].x());
        x1 = std::max(x1, m.vertices[t[k]].x());
      }
      if (x1 >= lo && x0 < lo + 1.5) part.triangles.push_back(t);
    }
    const double first = lo == -1.5 ? -INFINITY : lo;
    sum += CountSelfIntersections(part, 1, 7, first, lo + 1.5).pairs;
  }
  EXPECT_GT(whole.pairs, 0u);
  EXPECT_EQ(sum, whole.pairs);
}

TEST(SelfIntersections, TrianglesAManifoldCannotHoldAreCountedNotTested) {
  TriangleMesh m;
  AddCube(m, Eigen::Vector3f::Zero(), 1);
  m.triangles.push_back(m.triangles[0]);  // the same triangle again: an edge used thrice
  m.triangles.emplace_back(0, 0, 1);      // a repeated index
  m.triangles.emplace_back(0, 1, 99);     // an index past the vertices
  const SelfIntersections s = CountSelfIntersections(m);
  EXPECT_EQ(s.unchecked, 3u);
  EXPECT_EQ(s.pairs, 0u);
  // The repeated triangle is refused in every slab that holds it and counted in one.
  for (size_t per_slab : {1, 2, 5}) {
    const SelfIntersections slabs = CountSelfIntersections(m, 1, per_slab);
    EXPECT_EQ(slabs.unchecked, 3u) << per_slab;
    EXPECT_EQ(slabs.pairs, 0u) << per_slab;
  }
}

}  // namespace
}  // namespace carvemap
