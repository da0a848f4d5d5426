#include "services/building/building.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

namespace carvemap {
namespace {

// Signed volume of a closed mesh (divergence theorem): > 0 when normals point outwards.
double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d a = m.vertices[t[0]].cast<double>(), b = m.vertices[t[1]].cast<double>(),
                          c = m.vertices[t[2]].cast<double>();
    v += a.dot(b.cross(c)) / 6.0;
  }
  return v;
}

// Every directed edge appears once and its reverse once: closed and consistently oriented.
void ExpectWatertight(const TriangleMesh& m) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  }
  for (const auto& [e, n] : directed) {
    EXPECT_EQ(n, 1) << e.first << "->" << e.second;
    EXPECT_EQ(directed.count({e.second, e.first}), 1u) << e.first << "->" << e.second;
  }
}

Prism RegularPrism(int sides, double r, double z0, double z1) {
  Prism p;
  for (int i = 0; i < sides; ++i) {
    const double a = 2 * M_PI * i / sides;
    p.footprint.emplace_back(1.0 + r * std::cos(a), -2.0 + r * std::sin(a));
  }
  p.z0 = z0;
  p.z1 = z1;
  return p;
}

TEST(PrismMeshTest, WatertightAndOutward) {
  for (int sides : {3, 4, 5, 16}) {
    const Prism p = RegularPrism(sides, 0.7, 0.3, 2.8);
    const TriangleMesh m = PrismMesh(p);
    EXPECT_EQ(m.vertices.size(), size_t(2 * sides));
    EXPECT_EQ(m.triangles.size(), size_t(2 * sides + 2 * (sides - 2)));
    ExpectWatertight(m);
    EXPECT_NEAR(SignedVolume(m), SignedArea(p.footprint) * 2.5, 1e-5) << sides;
    EXPECT_GT(SignedVolume(m), 0);
  }
}

TEST(PrismMeshTest, ObjectsMeshLabelsTriangles) {
  Building b;
  ObjectTruth o;
  o.id = 7;
  o.parts = {RegularPrism(4, 0.5, 0, 1), RegularPrism(6, 0.2, 1, 1.5)};
  b.objects.push_back(o);
  std::vector<int> ids;
  const TriangleMesh m = ObjectsMesh(b, &ids);
  ASSERT_EQ(ids.size(), m.triangles.size());
  for (int id : ids) EXPECT_EQ(id, 7);
  const Eigen::AlignedBox3d box = o.Aabb();
  EXPECT_NEAR(box.min().z(), 0, 1e-12);
  EXPECT_NEAR(box.max().z(), 1.5, 1e-12);
}

TEST(PolygonTest, AreaAndContainment) {
  RoomTruth r;
  r.polygon = {{0, 0}, {4, 0}, {4, 3}, {0, 3}};
  r.holes = {{{1, 1}, {1, 2}, {2, 2}, {2, 1}}};  // CW
  EXPECT_NEAR(SignedArea(r.polygon), 12, 1e-12);
  EXPECT_NEAR(SignedArea(r.holes[0]), -1, 1e-12);
  EXPECT_NEAR(RoomArea(r), 11, 1e-12);
  EXPECT_TRUE(RoomContains(r, {0.5, 0.5}));
  EXPECT_FALSE(RoomContains(r, {1.5, 1.5}));
  EXPECT_FALSE(RoomContains(r, {5, 1}));
}

TEST(NavHelpersTest, DistanceTransformMatchesBruteForce) {
  const int w = 23, h = 17;
  std::vector<uint8_t> blocked(w * h, 0);
  for (int i = 0; i < w * h; i += 37) blocked[i] = 1;
  const std::vector<float> d = DistanceToBlocked(blocked, w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double best = 1e30;
      for (int j = 0; j < w * h; ++j) {
        if (blocked[j]) best = std::min(best, std::hypot(x - j % w, y - j / w));
      }
      EXPECT_NEAR(d[y * w + x], best, 1e-4);
    }
  }
  EXPECT_GT(DistanceToBlocked(std::vector<uint8_t>(12, 0), 4, 3)[5], 1e8);
}

TEST(NavHelpersTest, BlockedCellsUseHeightBand) {
  Building b;
  Prism wall = RegularPrism(4, 0.3, 0, 2.5);
  Prism light = RegularPrism(4, 0.3, 2.2, 2.3);
  for (auto& p : light.footprint) p.x() += 3;
  b.structure = {wall, light};
  NavGrid g;
  g.origin = {-1, -3};
  g.width = 60;
  g.height = 20;
  const auto blocked = BlockedCells(g, b, 0.05, 1.9);
  const Eigen::Vector2i wc = g.CellOf({1, -2}), lc = g.CellOf({4, -2});
  EXPECT_TRUE(blocked[wc.y() * g.width + wc.x()]);
  EXPECT_FALSE(blocked[lc.y() * g.width + lc.x()]);
}

}  // namespace
}  // namespace carvemap
