#include "services/mesh/planar_mesh_repair.h"

#include <algorithm>
#include <vector>

#include <gtest/gtest.h>

#include "services/mesh/mesh_checks.h"

namespace carvemap {
namespace {

// RepairPlanarMesh on hand-made closed meshes.

// The unit cube [0, 1]³ (12 triangles, counter-clockwise from outside), its front face (y = 0)
// split at M = (0.5, 0, 0) on the edge A–B: the triangle (A, B, M) has no area, and the front
// face is region 1, the rest region 0 (so no flip within a region can remove it).
PlanarMesh CubeWithFlatTriangle(float m_x = 0.5f) {
  PlanarMesh m;
  auto& v = m.mesh.vertices;
  for (int i = 0; i < 8; ++i) v.emplace_back(float(i & 1), float((i >> 1) & 1), float(i >> 2));
  v.emplace_back(m_x, 0.f, 0.f);  // 8: M
  auto quad = [&](int a, int b, int c, int d, int region) {
    m.mesh.triangles.emplace_back(a, b, c);
    m.mesh.triangles.emplace_back(a, c, d);
    m.triangle_region.insert(m.triangle_region.end(), {region, region});
  };
  auto tri = [&](int a, int b, int c, int region) {
    m.mesh.triangles.emplace_back(a, b, c);
    m.triangle_region.push_back(region);
  };
  quad(0, 2, 3, 1, 0);  // bottom z = 0, normal −z
  quad(4, 5, 7, 6, 0);  // top
  quad(0, 4, 6, 2, 0);  // x = 0
  quad(1, 3, 7, 5, 0);  // x = 1
  quad(2, 6, 7, 3, 0);  // y = 1
  // Front y = 0 (normal −y): A = 0, B = 1, E = 5, F = 4, through M.
  tri(0, 8, 4, 1);
  tri(8, 5, 4, 1);
  tri(8, 1, 5, 1);
  tri(0, 1, 8, 1);  // flat: A, B, M on one line
  return m;
}

// M in the middle of A–B gets nudged off the line (a collapse would move it half a metre); M
// a millimetre from A is collapsed into A.
class RepairFlatTriangleTest : public ::testing::TestWithParam<float> {};

TEST_P(RepairFlatTriangleTest, RemovesItAndStaysClosed) {
  PlanarMesh m = CubeWithFlatTriangle(GetParam());
  ASSERT_EQ(CheckMesh(m.mesh).degenerate_triangles, 1u);
  ASSERT_EQ(CheckMesh(m.mesh).boundary_edges, 0u);
  const PlanarMeshRepair r = RepairPlanarMesh(m, 0.0625);
  EXPECT_EQ(r.left, 0);
  EXPECT_EQ(r.flips, 0);
  EXPECT_EQ(r.nudges, GetParam() == 0.5f ? 1 : 0);
  EXPECT_EQ(r.collapses, GetParam() == 0.5f ? 0 : 1);
  EXPECT_EQ(m.mesh.triangles.size(), GetParam() == 0.5f ? 14u : 12u);
  const MeshCheck check = CheckMesh(m.mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  EXPECT_EQ(m.triangle_region.size(), m.mesh.triangles.size());
  double volume = 0;
  for (const Eigen::Vector3i& t : m.mesh.triangles) {
    const Eigen::Vector3d a = m.mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = m.mesh.vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = m.mesh.vertices[t[2]].cast<double>();
    volume += a.dot(b.cross(c)) / 6;
  }
  EXPECT_NEAR(volume, 1.0, 1e-3) << "the cube is still the cube";
}

INSTANTIATE_TEST_SUITE_P(MPositions, RepairFlatTriangleTest, ::testing::Values(0.5f, 0.001f));

// A flip is tried first: with the front face in the bottom's region, the flat triangle's
// longest edge (A–B) flips with the bottom triangle across it.
TEST(RepairPlanarMeshTest, FlipsWithinARegion) {
  PlanarMesh m = CubeWithFlatTriangle();
  for (int& r : m.triangle_region) r = 0;
  const PlanarMeshRepair r = RepairPlanarMesh(m, 0.0625);
  EXPECT_EQ(r.flips, 1);
  EXPECT_EQ(r.left, 0);
  EXPECT_TRUE(CheckMesh(m.mesh).watertight()) << CheckMesh(m.mesh).ToString();
  EXPECT_EQ(m.mesh.triangles.size(), 14u);
}

// Closed pieces with less than a grid cell of volume go (two triangles on one triangle's
// vertices: the "pillow" of a squashed one-cell pocket; a flat tetrahedron), bigger ones stay.
TEST(RepairPlanarMeshTest, DropsTinyPiecesWithoutVolume) {
  PlanarMesh m = CubeWithFlatTriangle();
  for (int& r : m.triangle_region) r = 0;
  const int base = static_cast<int>(m.mesh.vertices.size());
  auto add = [&](const std::vector<Eigen::Vector3f>& pts,
                 const std::vector<Eigen::Vector3i>& tris) {
    const int b = static_cast<int>(m.mesh.vertices.size());
    for (const auto& p : pts) m.mesh.vertices.push_back(p);
    for (const auto& t : tris) {
      m.mesh.triangles.push_back(t + Eigen::Vector3i::Constant(b));
      m.triangle_region.push_back(7);
    }
  };
  add({{3, 0, 0}, {3.1f, 0, 0}, {3, 0.1f, 0}}, {{0, 1, 2}, {0, 2, 1}});  // pillow
  // A tetrahedron of 0.0001 m³ (< 0.0625³ = 0.000244) and one of 0.01 m³.
  const std::vector<Eigen::Vector3i> tet = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  add({{5, 0, 0}, {5.06f, 0, 0}, {5, 0.1f, 0}, {5, 0, 0.1f}}, tet);
  add({{7, 0, 0}, {7.3f, 0, 0}, {7, 0.2f, 0}, {7, 0, 1}}, tet);
  ASSERT_GT(CheckMesh(m.mesh).duplicate_triangles, 0u);
  const PlanarMeshRepair r = RepairPlanarMesh(m, 0.0625);
  EXPECT_EQ(r.dropped_pieces, 2);
  EXPECT_EQ(r.left, 0);
  EXPECT_TRUE(CheckMesh(m.mesh).watertight()) << CheckMesh(m.mesh).ToString();
  EXPECT_EQ(std::count(m.triangle_region.begin(), m.triangle_region.end(), 7), 4);
  EXPECT_EQ(m.mesh.vertices.size(), size_t(base) + 4) << "unused vertices are dropped";
}

}  // namespace
}  // namespace carvemap
