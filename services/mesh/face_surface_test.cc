#include "services/mesh/face_surface.h"

#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

constexpr double kRes = 0.0625;

// A face of `size` cells whose square's lowest lattice corner is `lo`, perpendicular to `axis`;
// sign +1 when the interior (free) cell is on its +axis side.
BoundaryFace Face(int axis, int sign, const Eigen::Vector3i& lo, int size = 1) {
  BoundaryFace f;
  f.axis = static_cast<int8_t>(axis);
  f.sign = static_cast<int8_t>(sign);
  f.size_m = size * kRes;
  for (int d = 0; d < 3; ++d) f.center[d] = (lo[d] + (d == axis ? 0.0 : 0.5 * size)) * kRes;
  f.isosurface_m = f.center[axis];
  return f;
}

// The unit faces around the interior box [lo, hi) (lattice cells), facing into it; with
// `big_floor`, its floor (z = lo.z) as one face of the box's width (a square box).
std::vector<BoundaryFace> BoxFaces(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi,
                                   bool big_floor = false) {
  std::vector<BoundaryFace> faces;
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, w = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      Eigen::Vector3i p;
      p[axis] = side == 0 ? lo[axis] : hi[axis];
      const int sign = side == 0 ? 1 : -1;
      if (big_floor && axis == 2 && side == 0) {
        faces.push_back(Face(axis, sign, lo, hi.x() - lo.x()));
        continue;
      }
      for (p[u] = lo[u]; p[u] < hi[u]; ++p[u]) {
        for (p[w] = lo[w]; p[w] < hi[w]; ++p[w]) faces.push_back(Face(axis, sign, p));
      }
    }
  }
  return faces;
}

// Every corner has a twin that runs the other way along the same edge.
void ExpectTwinsPaired(const FaceSurface& s) {
  ASSERT_EQ(s.twin.size(), s.corner_vertex.size());
  for (int c = 0; c < static_cast<int>(s.twin.size()); ++c) {
    const int t = s.twin[c];
    ASSERT_GE(t, 0) << "corner " << c;
    EXPECT_EQ(s.twin[t], c);
    EXPECT_EQ(s.corner_vertex[t], s.corner_vertex[s.Next(c)]);
    EXPECT_EQ(s.corner_vertex[s.Next(t)], s.corner_vertex[c]);
    EXPECT_EQ(s.tv_lattice[s.corner_tv[c]], s.corner_vertex[c]);
  }
}

TEST(FaceSurfaceTest, OneCellIsACubeFacingIn) {
  const std::vector<BoundaryFace> faces = BoxFaces({0, 0, 0}, {1, 1, 1});
  absl::StatusOr<FaceSurface> s = BuildSurface(faces, kRes);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->lattice.size(), 8u);
  EXPECT_EQ(s->corner_vertex.size(), 24u);
  EXPECT_EQ(s->num_tv, 8);
  ExpectTwinsPaired(*s);
  // Counter-clockwise seen from each face's normal.
  for (size_t f = 0; f < faces.size(); ++f) {
    const int c = s->poly_start[f];
    const Eigen::Vector3d p0 = s->lattice[s->corner_vertex[c]].cast<double>();
    const Eigen::Vector3d p1 = s->lattice[s->corner_vertex[c + 1]].cast<double>();
    const Eigen::Vector3d p2 = s->lattice[s->corner_vertex[c + 2]].cast<double>();
    EXPECT_GT((p1 - p0).cross(p2 - p0).dot(faces[f].normal().cast<double>()), 0) << "face " << f;
  }
}

// A 2-cell floor face beside unit wall faces: its edges get the walls' midpoints as corners.
TEST(FaceSurfaceTest, BigFaceIsSplitAtTJunctions) {
  const std::vector<BoundaryFace> faces = BoxFaces({0, 0, 0}, {2, 2, 2}, /*big_floor=*/true);
  ASSERT_EQ(faces.size(), 21u);
  absl::StatusOr<FaceSurface> s = BuildSurface(faces, kRes);
  ASSERT_TRUE(s.ok()) << s.status();
  int floor = -1;
  for (size_t f = 0; f < faces.size(); ++f) {
    if (faces[f].size_m > kRes) floor = static_cast<int>(f);
  }
  ASSERT_GE(floor, 0);
  EXPECT_EQ(s->poly_start[floor + 1] - s->poly_start[floor], 8);
  EXPECT_EQ(s->corner_vertex.size(), 8u + 20u * 4u);
  // The 3×3×3 lattice points but the box's centre and the floor's (inside the big face).
  EXPECT_EQ(s->lattice.size(), 25u);
  EXPECT_EQ(s->num_tv, 25);
  ExpectTwinsPaired(*s);
}

// Two cells touching only along an edge: its two lattice points each get one vertex per sheet.
TEST(FaceSurfaceTest, CellsTouchingAlongAnEdgeAreSeparateSheets) {
  std::vector<BoundaryFace> faces = BoxFaces({0, 0, 0}, {1, 1, 1});
  const std::vector<BoundaryFace> other = BoxFaces({1, 1, 0}, {2, 2, 1});
  faces.insert(faces.end(), other.begin(), other.end());
  absl::StatusOr<FaceSurface> s = BuildSurface(faces, kRes);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->lattice.size(), 14u);
  EXPECT_EQ(s->num_tv, 16);
  ExpectTwinsPaired(*s);
  // The twins stay within each cube: the sheets are not joined across the edge.
  for (int c = 0; c < static_cast<int>(s->twin.size()); ++c) {
    EXPECT_EQ(s->corner_face[c] < 6, s->corner_face[s->twin[c]] < 6) << "corner " << c;
  }
}

TEST(FaceSurfaceTest, RefusesOpenSurfacesAndFacesOffTheLattice) {
  std::vector<BoundaryFace> open = BoxFaces({0, 0, 0}, {1, 1, 1});
  open.pop_back();
  absl::StatusOr<FaceSurface> s = BuildSurface(open, kRes);
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("not a closed surface"), std::string::npos)
      << s.status();

  std::vector<BoundaryFace> off = BoxFaces({0, 0, 0}, {1, 1, 1});
  off[3].center.x() += kRes / 3;
  s = BuildSurface(off, kRes);
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("face 3"), std::string::npos) << s.status();
}

}  // namespace
}  // namespace carvemap
