// DelaunayMesh against triangulations known by hand (a square with its centre, cocircular
// corners, collinear points) and the empty-circle property on seeded random points.
#include "services/floorplan/rooms/delaunay_mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <utility>

namespace carvemap::floorplan_internal {
namespace {

using Eigen::Vector2d;

double Cross(const Vector2d& a, const Vector2d& b, const Vector2d& c) {
  return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
}

// Every face counter-clockwise, neighbours symmetric and sharing the edge they are across.
void ExpectConsistent(const std::vector<Vector2d>& pts, const DelaunayMesh& dt) {
  const auto& tri = dt.triangles();
  const auto& nbr = dt.neighbours();
  ASSERT_EQ(tri.size(), nbr.size());
  for (size_t f = 0; f < tri.size(); ++f) {
    EXPECT_GT(Cross(pts[tri[f][0]], pts[tri[f][1]], pts[tri[f][2]]), 0) << f;
    for (int i = 0; i < 3; ++i) {
      const int g = nbr[f][i];
      if (g < 0) continue;
      const int u = tri[f][(i + 1) % 3], w = tri[f][(i + 2) % 3];
      int back = -1;
      for (int j = 0; j < 3; ++j) {
        if (nbr[g][j] == static_cast<int>(f)) back = j;
      }
      ASSERT_GE(back, 0) << f << " " << g;
      EXPECT_EQ(tri[g][(back + 1) % 3], w);
      EXPECT_EQ(tri[g][(back + 2) % 3], u);
    }
  }
}

TEST(DelaunayMeshTest, SquareWithCentre) {
  const std::vector<Vector2d> pts = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {0.5, 0.5}};
  absl::StatusOr<DelaunayMesh> dt = DelaunayMesh::Build(pts, "test");
  ASSERT_TRUE(dt.ok()) << dt.status();
  EXPECT_EQ(dt->dimension(), 2);
  ASSERT_EQ(dt->triangles().size(), 4u);
  ExpectConsistent(pts, *dt);
  int hull = 0;
  for (size_t f = 0; f < 4; ++f) {
    const auto& t = dt->triangles()[f];
    EXPECT_NE(std::find(t.begin(), t.end(), 4), t.end()) << "every face has the centre";
    for (int g : dt->neighbours()[f]) hull += g < 0 ? 1 : 0;
  }
  EXPECT_EQ(hull, 4);

  int hint = -1;
  PointLocation at = dt->Locate({0.5, 0.5}, &hint);
  EXPECT_EQ(at.kind, PointLocation::kVertex);
  EXPECT_EQ(at.id, 4);
  EXPECT_GE(hint, 0);

  at = dt->Locate({0.5, 0.2}, &hint);  // inside the bottom face
  ASSERT_EQ(at.kind, PointLocation::kFace);
  EXPECT_EQ(hint, at.id);
  std::set<int> bottom(dt->triangles()[at.id].begin(), dt->triangles()[at.id].end());
  EXPECT_EQ(bottom, (std::set<int>{0, 1, 4}));

  // On the hull edge (0,0)-(1,0): named by its finite face, the edge opposite the centre.
  at = dt->Locate({0.5, 0}, &hint);
  ASSERT_EQ(at.kind, PointLocation::kEdge);
  EXPECT_EQ(dt->triangles()[at.id][at.edge], 4);
  EXPECT_EQ(dt->neighbours()[at.id][at.edge], -1);

  // On the inner edge (0,0)-(0.5,0.5): either face, the edge opposite neither end.
  at = dt->Locate({0.25, 0.25}, &hint);
  ASSERT_EQ(at.kind, PointLocation::kEdge);
  const int opposite = dt->triangles()[at.id][at.edge];
  EXPECT_TRUE(opposite == 1 || opposite == 3) << opposite;

  const int before = hint;
  at = dt->Locate({2, 2}, &hint);
  EXPECT_EQ(at.kind, PointLocation::kNone);
  EXPECT_EQ(hint, before) << "outside the hull the hint stays";
}

// Four cocircular corners have two Delaunay triangulations: the same one is chosen whatever
// the input order.
TEST(DelaunayMeshTest, CocircularPointsTriangulateTheSameInAnyOrder) {
  const std::vector<Vector2d> a = {{0, 0}, {2, 0}, {2, 2}, {0, 2}, {5, 1}};
  std::vector<Vector2d> b = a;
  std::reverse(b.begin(), b.end());
  auto faces = [](const std::vector<Vector2d>& pts) {
    absl::StatusOr<DelaunayMesh> dt = DelaunayMesh::Build(pts, "test");
    EXPECT_TRUE(dt.ok());
    std::set<std::set<std::pair<double, double>>> out;
    for (const auto& t : dt->triangles()) {
      std::set<std::pair<double, double>> corners;
      for (int v : t) corners.emplace(pts[v].x(), pts[v].y());
      out.insert(corners);
    }
    return out;
  };
  const auto fa = faces(a);
  EXPECT_EQ(fa.size(), 3u);
  EXPECT_EQ(fa, faces(b));
}

TEST(DelaunayMeshTest, CollinearPointsHaveNoFaces) {
  absl::StatusOr<DelaunayMesh> dt = DelaunayMesh::Build({{0, 0}, {1, 1}, {2, 2}, {3, 3}}, "test");
  ASSERT_TRUE(dt.ok()) << dt.status();
  EXPECT_LT(dt->dimension(), 2);
  EXPECT_TRUE(dt->triangles().empty());
}

// Random points: Euler's count of faces (2n − 2 − hull vertices), the empty-circle property,
// and circumcentres equidistant from their corners.
TEST(DelaunayMeshTest, RandomPointsAreDelaunay) {
  std::mt19937 rng(301);
  std::uniform_real_distribution<double> u(0, 10);
  std::vector<Vector2d> pts(300);
  for (Vector2d& p : pts) p = Vector2d(u(rng), u(rng));
  absl::StatusOr<DelaunayMesh> dt = DelaunayMesh::Build(pts, "test");
  ASSERT_TRUE(dt.ok()) << dt.status();
  ExpectConsistent(pts, *dt);
  std::set<int> hull_vertices;
  for (size_t f = 0; f < dt->triangles().size(); ++f) {
    for (int i = 0; i < 3; ++i) {
      if (dt->neighbours()[f][i] < 0) {
        hull_vertices.insert(dt->triangles()[f][(i + 1) % 3]);
        hull_vertices.insert(dt->triangles()[f][(i + 2) % 3]);
      }
    }
  }
  EXPECT_EQ(dt->triangles().size(), 2 * pts.size() - 2 - hull_vertices.size());
  const std::vector<Vector2d> centres = Circumcentres(pts, dt->triangles());
  ASSERT_EQ(centres.size(), dt->triangles().size());
  for (size_t f = 0; f < centres.size(); ++f) {
    const auto& t = dt->triangles()[f];
    const double r = (pts[t[0]] - centres[f]).norm();
    EXPECT_NEAR((pts[t[1]] - centres[f]).norm(), r, 1e-9 * (1 + r));
    EXPECT_NEAR((pts[t[2]] - centres[f]).norm(), r, 1e-9 * (1 + r));
    for (size_t v = 0; v < pts.size(); ++v) {
      EXPECT_GE((pts[v] - centres[f]).norm(), r * (1 - 1e-9)) << "vertex " << v << " in face " << f;
    }
  }
  // Every vertex is located on itself.
  int hint = -1;
  for (size_t v = 0; v < pts.size(); v += 37) {
    const PointLocation at = dt->Locate(pts[v], &hint);
    EXPECT_EQ(at.kind, PointLocation::kVertex);
    EXPECT_EQ(at.id, static_cast<int>(v));
  }
}

}  // namespace
}  // namespace carvemap::floorplan_internal
