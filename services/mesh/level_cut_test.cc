#include "services/mesh/level_cut.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh.h"
#include "services/mesh/planar_regions.h"
#include "services/mesh/self_intersections.h"
#include "services/mesh/voxel_faces_testing.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Eigen::Vector3i;

constexpr double kRes = 0.0625;
OctreeGrid Grid() { return OctreeGrid{5}; }  // 6.25 cm
constexpr double kInf = std::numeric_limits<double>::infinity();

// Two rooms of 4 × 3 m stacked (floors at 0 and 3 m, ceilings at 2.5 and 5.5 m), joined by a
// 1 × 1 m shaft through the slab at x, y ∈ [1, 2); free space > 0.
double StackedRooms(const Vector3d& p) {
  auto box = [&p](const Vector3d& lo, const Vector3d& hi) {
    return std::min({p.x() - lo.x(), hi.x() - p.x(), p.y() - lo.y(), hi.y() - p.y(), p.z() - lo.z(),
                     hi.z() - p.z()});
  };
  return std::max(
      {box({0, 0, 0}, {4, 3, 2.5}), box({0, 0, 3.0}, {4, 3, 5.5}), box({1, 1, 2.0}, {2, 2, 3.5})});
}

absl::StatusOr<bool> InteriorAt(const Vector3d& p) { return StackedRooms(p) > 0; }

// The cut plane at z, crossings looked for over the rooms' footprint.
CutPlane Plane(double z, const InteriorAtFn& interior_at = InteriorAt) {
  absl::StatusOr<CutPlane> plane =
      FindCutPlane(Grid(), z, Vector2d(-0.1, -0.1), Vector2d(4.1, 3.1), interior_at);
  EXPECT_TRUE(plane.ok()) << plane.status();
  return plane.ok() ? *std::move(plane) : CutPlane{z, {}};
}

std::vector<BoundaryFace> Faces() {
  return VoxelFaces(kRes, Vector3i(-1, -1, -1), Vector3i(65, 49, 90), StackedRooms);
}

PlanarMesh Mesh(const std::vector<BoundaryFace>& faces) {
  PlanarRegionOptions growth;
  growth.mesh_growth = true;
  absl::StatusOr<PlanarRegionSet> regions = FitPlanarRegions(faces, Grid(), growth);
  EXPECT_TRUE(regions.ok()) << regions.status();
  absl::StatusOr<PlanarMesh> mesh = BuildPlanarMesh(faces, *regions, Grid());
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *std::move(mesh) : PlanarMesh{};
}

TEST(LevelCut, PartsAreClosedAndTogetherHoldEveryFace) {
  const std::vector<BoundaryFace> faces = Faces();
  const CutPlane split = Plane(2.76);
  // 2.76 rounds to the lattice plane at 2.75 m; the shaft's 16 × 16 cells cross it.
  EXPECT_EQ(split.z, 2.75);
  EXPECT_EQ(split.crossings.size(), 256u);
  absl::StatusOr<LevelPart> lower = CutLevelPart(faces, Grid(), Plane(-kInf), split);
  absl::StatusOr<LevelPart> upper = CutLevelPart(faces, Grid(), split, Plane(kInf));
  ASSERT_TRUE(lower.ok()) << lower.status();
  ASSERT_TRUE(upper.ok()) << upper.status();
  // Both parts are capped there.
  EXPECT_EQ(lower->caps, 256u);
  EXPECT_EQ(upper->caps, 256u);
  EXPECT_EQ(lower->faces.size() - lower->caps + upper->faces.size() - upper->caps, faces.size());
  for (size_t i = lower->faces.size() - lower->caps; i < lower->faces.size(); ++i) {
    EXPECT_EQ(lower->faces[i].sign, -1);
    EXPECT_NEAR(lower->faces[i].isosurface().z(), 2.75 - kRes / 4, 1e-12);
  }
  // Each part is a closed surface: its planar mesh is watertight; and the two shells, a half
  // cell apart in the shaft, do not cross.
  TriangleMesh both;
  for (const LevelPart* part : {&*lower, &*upper}) {
    const PlanarMesh mesh = Mesh(part->faces);
    const MeshCheck check = CheckMesh(mesh.mesh);
    EXPECT_TRUE(check.watertight()) << check.ToString();
    EXPECT_GT(mesh.mesh.triangles.size(), 12u);
    both.Append(mesh.mesh);
  }
  EXPECT_EQ(CountSelfIntersections(both).pairs, 0u);
  // No plane: the part is every face, uncapped.
  absl::StatusOr<LevelPart> all = CutLevelPart(faces, Grid(), Plane(-kInf), Plane(kInf));
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->faces.size(), faces.size());
  EXPECT_EQ(all->caps, 0u);
}

TEST(LevelCut, CoarseFacesAcrossThePlaneAreCutIntoCells) {
  BoundaryFace wall;  // 4 cells square, facing +x, from z = 2.5 to 2.75 m
  wall.axis = 0;
  wall.sign = 1;
  wall.size_m = 4 * kRes;
  wall.center = Vector3d(1.0, 1.125, 2.625);
  wall.isosurface_m = 1.0;
  const std::vector<BoundaryFace> faces = {wall};
  absl::StatusOr<LevelPart> lower =
      CutLevelPart(faces, Grid(), CutPlane{-kInf, {}}, CutPlane{2.625, {}});
  absl::StatusOr<LevelPart> upper =
      CutLevelPart(faces, Grid(), CutPlane{2.625, {}}, CutPlane{kInf, {}});
  ASSERT_TRUE(lower.ok() && upper.ok());
  ASSERT_EQ(lower->faces.size(), 8u);
  ASSERT_EQ(upper->faces.size(), 8u);
  for (const BoundaryFace& f : lower->faces) {
    EXPECT_EQ(f.size_m, kRes);
    EXPECT_LT(f.center.z(), 2.625);
    EXPECT_EQ(f.isosurface_m, 1.0);
  }
  // A plane along the face's edge leaves it whole.
  absl::StatusOr<LevelPart> whole =
      CutLevelPart(faces, Grid(), CutPlane{2.75, {}}, CutPlane{kInf, {}});
  ASSERT_TRUE(whole.ok());
  EXPECT_TRUE(whole->faces.empty());
}

TEST(LevelCut, RejectsEmptyPartsAndOddFaces) {
  EXPECT_EQ(CutLevelPart({}, Grid(), CutPlane{2.0, {}}, CutPlane{2.0, {}}).status().code(),
            absl::StatusCode::kInvalidArgument);
  BoundaryFace odd;
  odd.axis = 1;
  odd.size_m = 1.5 * kRes;
  odd.center = Vector3d(0, 0, 2.0);
  const std::vector<BoundaryFace> faces = {odd};
  EXPECT_EQ(CutLevelPart(faces, Grid(), CutPlane{2.0, {}}, CutPlane{kInf, {}}).status().code(),
            absl::StatusCode::kInvalidArgument);
  auto failing = [](const Vector3d&) -> absl::StatusOr<bool> {
    return absl::DataLossError("tile unreadable");
  };
  EXPECT_EQ(FindCutPlane(Grid(), 2.0, Vector2d(0, 0), Vector2d(1, 1), failing).status().code(),
            absl::StatusCode::kDataLoss);
  // No plane at infinity: nothing is looked up.
  absl::StatusOr<CutPlane> none =
      FindCutPlane(Grid(), kInf, Vector2d(0, 0), Vector2d(1, 1), failing);
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->crossings.empty());
  EXPECT_EQ(FindCutPlane(Grid(), 2.0, Vector2d(0, 0), Vector2d(1e6, 1e6), failing).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap
