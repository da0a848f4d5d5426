#include "services/mesh/mesh_checks.h"

#include <gtest/gtest.h>

namespace carvemap {
namespace {

// A unit cube as 12 outward-facing triangles.
TriangleMesh Cube() {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) m.vertices.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.emplace_back(q[0], q[1], q[2]);
    m.triangles.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

TEST(CheckMesh, ClosedCubeIsWatertight) {
  const MeshCheck c = CheckMesh(Cube());
  EXPECT_TRUE(c.watertight()) << c.ToString();
  EXPECT_EQ(c.edges, 18u);
}

TEST(CheckMesh, MissingTriangleLeavesBoundaryEdges) {
  TriangleMesh m = Cube();
  m.triangles.pop_back();
  const MeshCheck c = CheckMesh(m);
  EXPECT_FALSE(c.watertight());
  EXPECT_EQ(c.boundary_edges, 3u);
}

TEST(CheckMesh, FlippedTriangleIsMisoriented) {
  TriangleMesh m = Cube();
  std::swap(m.triangles[0][1], m.triangles[0][2]);
  const MeshCheck c = CheckMesh(m);
  EXPECT_FALSE(c.watertight());
  EXPECT_EQ(c.misoriented_edges, 3u);
}

TEST(CheckMesh, DuplicateDegenerateAndBadIndices) {
  TriangleMesh m = Cube();
  m.triangles.push_back(m.triangles[0]);
  m.triangles.emplace_back(0, 0, 1);
  m.triangles.emplace_back(0, 1, 99);
  const MeshCheck c = CheckMesh(m);
  EXPECT_EQ(c.duplicate_triangles, 1u);
  EXPECT_EQ(c.degenerate_triangles, 1u);
  EXPECT_EQ(c.bad_indices, 1u);
  EXPECT_GT(c.nonmanifold_edges, 0u);
  EXPECT_FALSE(c.watertight());
}

TEST(CheckMesh, ZeroAreaTriangleIsDegenerate) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  m.triangles = {{0, 1, 2}};
  EXPECT_EQ(CheckMesh(m).degenerate_triangles, 1u);
}

}  // namespace
}  // namespace carvemap
