#include "services/mesh/planar_mesh.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <iostream>
#include <limits>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_regions.h"
#include "services/mesh/planar_work_mesh.h"
#include "services/mesh/self_intersections.h"
#ifdef CARVEMAP_PLANAR_CARVED_ONLY
#include "services/building/building.h"
#include "services/building/building_presets.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/tile_set.h"
#include "tests/support/carved_preset.h"
#include "tests/support/truth_distance.h"
#endif

namespace carvemap {
namespace {

#ifndef CARVEMAP_PLANAR_CARVED_ONLY

// ---------------------------------------------------------------------------------------------
// Synthetic octrees: a uniform grid of interior/exterior labels, optionally merged into aligned
// octree leaves (so that big faces sit next to small ones), turned into BoundaryFace records.

struct VoxelWorld {
  Eigen::Vector3i dims;
  std::vector<char> interior;
  explicit VoxelWorld(const Eigen::Vector3i& d) : dims(d), interior(d.prod(), 0) {}
  [[nodiscard]] bool Inside(const Eigen::Vector3i& c) const {
    return (c.array() >= 0).all() && (c.array() < dims.array()).all();
  }
  [[nodiscard]] int Index(const Eigen::Vector3i& c) const {
    return c.x() + dims.x() * (c.y() + dims.y() * c.z());
  }
  [[nodiscard]] bool At(const Eigen::Vector3i& c) const { return Inside(c) && interior[Index(c)]; }
  // Sets cells [lo, hi) to `value`.
  void Fill(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi, bool value) {
    for (int z = lo.z(); z < hi.z(); ++z)
      for (int y = lo.y(); y < hi.y(); ++y)
        for (int x = lo.x(); x < hi.x(); ++x) interior[Index({x, y, z})] = value;
  }
};

// Faces between interior and exterior leaves. `max_leaf_cells` (a power of two) merges uniform
// aligned blocks into leaves up to that size. Isosurface points are moved `iso_offset_cells`
// along the normal (into free space), as Fig 4.9's offset would.
std::vector<BoundaryFace> FacesOf(const VoxelWorld& world, const OctreeGrid& grid,
                                  int max_leaf_cells = 1, double iso_offset_cells = 0) {
  const double res = grid.resolution_m();
  struct Leaf {
    Eigen::Vector3i min;
    int size;
  };
  std::vector<Leaf> leaves;
  std::vector<int> leaf_of(world.interior.size(), -1);
  for (int s = max_leaf_cells; s >= 1; s /= 2) {
    for (int z = 0; z + s <= world.dims.z(); z += s)
      for (int y = 0; y + s <= world.dims.y(); y += s)
        for (int x = 0; x + s <= world.dims.x(); x += s) {
          const Eigen::Vector3i lo(x, y, z);
          if (leaf_of[world.Index(lo)] >= 0) continue;
          const bool label = world.At(lo);
          bool uniform = true;
          for (int k = 0; k < s * s * s && uniform; ++k) {
            const Eigen::Vector3i c = lo + Eigen::Vector3i(k % s, (k / s) % s, k / (s * s));
            uniform = world.At(c) == label;
          }
          if (!uniform && s > 1) continue;
          for (int k = 0; k < s * s * s; ++k) {
            leaf_of[world.Index(lo + Eigen::Vector3i(k % s, (k / s) % s, k / (s * s)))] =
                static_cast<int>(leaves.size());
          }
          leaves.push_back({lo, s});
        }
  }
  // Finest faces grouped by (interior leaf, exterior leaf, direction): one face per pair, the
  // square of the smaller leaf.
  std::map<std::tuple<int, int, int>, std::vector<Eigen::Vector3i>> groups;
  for (int z = 0; z < world.dims.z(); ++z)
    for (int y = 0; y < world.dims.y(); ++y)
      for (int x = 0; x < world.dims.x(); ++x) {
        const Eigen::Vector3i c(x, y, z);
        if (!world.At(c)) continue;
        for (int dir = 0; dir < 6; ++dir) {
          const int axis = dir / 2, sign = dir % 2 ? 1 : -1;
          Eigen::Vector3i n = c;
          n[axis] += sign;
          if (world.At(n)) continue;
          EXPECT_TRUE(world.Inside(n)) << "keep an exterior margin around the interior";
          groups[{leaf_of[world.Index(c)], leaf_of[world.Index(n)], dir}].push_back(c);
        }
      }
  std::vector<BoundaryFace> faces;
  for (const auto& [key, cells] : groups) {
    const auto [li, le, dir] = key;
    const int axis = dir / 2, sign = dir % 2 ? 1 : -1;
    const Leaf& in = leaves[li];
    const Leaf& ex = leaves[le];
    const int size = std::min(in.size, ex.size);
    Eigen::Vector3i lo = cells[0];
    for (const Eigen::Vector3i& c : cells) lo = lo.cwiseMin(c);
    BoundaryFace f;
    f.axis = static_cast<int8_t>(axis);
    f.sign = static_cast<int8_t>(-sign);  // from the exterior leaf into the interior one
    f.size_m = size * res;
    Eigen::Vector3d center = lo.cast<double>() + Eigen::Vector3d::Constant(0.5 * size);
    center[axis] = sign > 0 ? lo[axis] + 1.0 : lo[axis];
    f.center = center * res;
    f.isosurface_m = f.center[axis] + iso_offset_cells * res * f.sign;
    f.exterior_observed = true;
    f.exterior_weight = 1.5f;
    faces.push_back(f);
  }
  return faces;
}

std::array<Eigen::Vector3d, 4> FaceCorners(const BoundaryFace& f) {
  const int u = (f.axis + 1) % 3, w = (f.axis + 2) % 3;
  const Eigen::Vector3d shift = f.isosurface() - f.center;
  std::array<Eigen::Vector3d, 4> c;
  for (int i = 0; i < 4; ++i) {
    c[i] = f.center + shift;
    c[i][u] += (i & 1 ? 0.5 : -0.5) * f.size_m;
    c[i][w] += (i & 2 ? 0.5 : -0.5) * f.size_m;
  }
  return c;
}

// Regions from a label per face (labels need not be dense): planes by area-weighted PCA on the
// faces' corners moved to their isosurface (§4.2.4), normals oriented like the faces.
PlanarRegionSet RegionsFromLabels(const std::vector<BoundaryFace>& faces,
                                  const std::vector<int64_t>& label) {
  PlanarRegionSet set;
  std::map<int64_t, int> id;
  set.face_region.resize(faces.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    auto [it, inserted] = id.try_emplace(label[f], static_cast<int>(set.regions.size()));
    if (inserted) {
      set.regions.emplace_back();
      set.regions.back().id = it->second;
    }
    set.face_region[f] = it->second;
    set.regions[it->second].faces.push_back(static_cast<uint32_t>(f));
  }
  for (PlanarRegion& r : set.regions) {
    double w = 0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero(), nsum = Eigen::Vector3d::Zero();
    for (uint32_t f : r.faces) {
      for (const Eigen::Vector3d& c : FaceCorners(faces[f])) mean += faces[f].area_m2() * c;
      w += 4 * faces[f].area_m2();
      nsum += faces[f].area_m2() * faces[f].normal().cast<double>();
      r.area_m2 += faces[f].area_m2();
    }
    mean /= w;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (uint32_t f : r.faces) {
      for (const Eigen::Vector3d& c : FaceCorners(faces[f])) {
        cov += faces[f].area_m2() * (c - mean) * (c - mean).transpose();
      }
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov / w);
    Eigen::Vector3d n = eig.eigenvectors().col(0);
    if (n.dot(nsum) < 0) n = -n;
    r.normal = n;
    r.centroid = mean;
    r.eigenvalues = eig.eigenvalues();
  }
  return set;
}

// The usual axis-aligned labelling: one region per (axis, normal sign, plane).
PlanarRegionSet AxisRegions(const std::vector<BoundaryFace>& faces, double res) {
  std::vector<int64_t> label;
  for (const BoundaryFace& f : faces) {
    const int sign = f.normal()[f.axis] > 0 ? 1 : 0;
    const int64_t plane = std::llround(f.center[f.axis] / res);
    label.push_back((plane + 100000) * 8 + f.axis * 2 + sign);
  }
  return RegionsFromLabels(faces, label);
}

// V − E + F of the mesh's used vertices: 2 − 2·genus for a closed orientable surface.
int64_t EulerCharacteristic(const TriangleMesh& mesh) {
  std::set<int> used;
  std::set<std::pair<int, int>> edges;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    for (int i = 0; i < 3; ++i) {
      used.insert(t[i]);
      edges.insert({std::min(t[i], t[(i + 1) % 3]), std::max(t[i], t[(i + 1) % 3])});
    }
  }
  return static_cast<int64_t>(used.size()) - static_cast<int64_t>(edges.size()) +
         static_cast<int64_t>(mesh.triangles.size());
}

double MaxPlaneDistance(const PlanarMesh& pm, const PlanarRegionSet& regions, int region) {
  double worst = 0;
  const PlanarRegion& r = regions.regions[region];
  for (size_t t = 0; t < pm.mesh.triangles.size(); ++t) {
    if (pm.triangle_region[t] != region) continue;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d x = pm.mesh.vertices[pm.mesh.triangles[t][i]].cast<double>();
      worst = std::max(worst, std::abs(r.normal.dot(x - r.centroid)));
    }
  }
  return worst;
}

// Every triangle faces like its region: normal into free space.
int MisorientedTriangles(const PlanarMesh& pm, const PlanarRegionSet& regions) {
  int bad = 0;
  for (size_t t = 0; t < pm.mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = pm.mesh.triangles[t];
    const Eigen::Vector3d a = pm.mesh.vertices[tri[0]].cast<double>();
    const Eigen::Vector3d b = pm.mesh.vertices[tri[1]].cast<double>();
    const Eigen::Vector3d c = pm.mesh.vertices[tri[2]].cast<double>();
    // Against the normal. A triangle standing across its plane (a step of the region seen
    // edge-on, planar_mesh.cc RetriangulateRegion) is not folded, though rounding may tilt it
    // a hair past 90°.
    const Eigen::Vector3d cross = (b - a).cross(c - a);
    if (cross.dot(regions.regions[pm.triangle_region[t]].normal) < -0.01 * cross.norm()) ++bad;
  }
  return bad;
}

int64_t FinestFaceCount(const std::vector<BoundaryFace>& faces) {
  int64_t n = 0;
  for (const BoundaryFace& f : faces) n += std::llround(f.area_m2() / (0.0625 * 0.0625));
  return n;
}

OctreeGrid Grid() { return OctreeGrid{5}; }  // 6.25 cm

PlanarMeshOptions NoQuadtree() {
  PlanarMeshOptions o;
  o.quadtree_points = false;
  return o;
}

// Checks shared by all cases; returns the mesh.
PlanarMesh MeshAndCheck(const std::vector<BoundaryFace>& faces, const PlanarRegionSet& regions,
                        const PlanarMeshOptions& options, int64_t euler) {
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, regions, Grid(), options);
  EXPECT_TRUE(pm.ok()) << pm.status();
  if (!pm.ok()) return {};
  const MeshCheck check = CheckMesh(pm->mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  EXPECT_EQ(EulerCharacteristic(pm->mesh), euler);
  EXPECT_EQ(pm->triangle_region.size(), pm->mesh.triangles.size());
  EXPECT_EQ(MisorientedTriangles(*pm, regions), 0);
  // The dense mesh has about two triangles per finest face; the planar one far fewer.
  EXPECT_LT(pm->mesh.triangles.size() * 10, 2 * FinestFaceCount(faces)) << "far fewer triangles";
  return *pm;
}

// ---------------------------------------------------------------------------------------------

class BoxRoomTest : public ::testing::TestWithParam<int> {};  // param: max leaf size (cells)

TEST_P(BoxRoomTest, TwelveTrianglesAtTheCorners) {
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  VoxelWorld world({24, 24, 24});
  world.Fill({4, 4, 4}, {20, 20, 20}, true);
  const double offset = 0.3;  // Fig 4.9 offset, cells
  const std::vector<BoundaryFace> faces = FacesOf(world, grid, GetParam(), offset);
  const PlanarRegionSet regions = AxisRegions(faces, res);
  ASSERT_EQ(regions.regions.size(), 6u);
  const PlanarMesh pm = MeshAndCheck(faces, regions, NoQuadtree(), 2);
  EXPECT_EQ(pm.mesh.triangles.size(), 12u);
  ASSERT_EQ(pm.mesh.vertices.size(), 8u);
  // Corners: the planes moved `offset` into the room.
  const double lo = (4 + offset) * res, hi = (20 - offset) * res;
  for (const Eigen::Vector3f& v : pm.mesh.vertices) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(std::min(std::abs(v[a] - lo), std::abs(v[a] - hi)), 0.0, 1e-6) << v.transpose();
    }
  }
}

TEST_P(BoxRoomTest, QuadtreeKeepsItWatertightAndSmall) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({40, 24, 24});
  world.Fill({4, 4, 4}, {36, 20, 14}, true);  // 2 × 1 × 0.625 m: non-square walls
  const std::vector<BoundaryFace> faces = FacesOf(world, grid, GetParam());
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  const PlanarMesh pm = MeshAndCheck(faces, regions, PlanarMeshOptions{}, 2);
  for (int r = 0; r < 6; ++r) EXPECT_LT(MaxPlaneDistance(pm, regions, r), 1e-5);
  EXPECT_GT(pm.mesh.triangles.size(), 12u);   // interior points were added
  EXPECT_LT(pm.mesh.triangles.size(), 200u);  // 2624 faces
}

INSTANTIATE_TEST_SUITE_P(LeafSizes, BoxRoomTest, ::testing::Values(1, 4));

TEST(PlanarMeshTest, PillarMakesHolesInFloorAndCeiling) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({24, 24, 16});
  world.Fill({2, 2, 2}, {22, 22, 12}, true);
  world.Fill({10, 10, 2}, {14, 14, 12}, false);  // a column from floor to ceiling
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  ASSERT_EQ(regions.regions.size(), 10u);
  // A room around a column is a torus: χ = 0.
  const PlanarMesh pm = MeshAndCheck(faces, regions, NoQuadtree(), 0);
  // Floor and ceiling annuli: 8 triangles each; 8 walls: 2 each.
  EXPECT_EQ(pm.mesh.triangles.size(), 32u);
  const PlanarMesh with_quadtree = MeshAndCheck(faces, regions, PlanarMeshOptions{}, 0);
  EXPECT_GE(with_quadtree.mesh.triangles.size(), 32u);
}

TEST(PlanarMeshTest, LShapedRoom) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({20, 20, 12});
  world.Fill({2, 2, 2}, {18, 8, 10}, true);
  world.Fill({2, 2, 2}, {8, 18, 10}, true);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  ASSERT_EQ(regions.regions.size(), 8u);
  const PlanarMesh pm = MeshAndCheck(faces, regions, NoQuadtree(), 2);
  EXPECT_EQ(pm.mesh.triangles.size(), 4u + 4u + 6u * 2u);
  EXPECT_EQ(pm.mesh.vertices.size(), 12u);
}

TEST(PlanarMeshTest, BumpOnCoarseFloorHasTJunctions) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({32, 32, 32});
  world.Fill({4, 4, 4}, {28, 28, 28}, true);
  world.Fill({13, 13, 4}, {14, 14, 5}, false);  // a one-cell bump on the floor
  world.Fill({20, 6, 27}, {22, 8, 28}, false);  // a small box hanging from the ceiling
  const std::vector<BoundaryFace> fine = FacesOf(world, grid, 1);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid, 8);
  std::set<double> sizes;
  for (const BoundaryFace& f : faces) sizes.insert(f.size_m);
  ASSERT_GE(sizes.size(), 3u) << "leaves of several sizes";
  ASSERT_LT(faces.size(), fine.size());
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  for (const PlanarMeshOptions& options : {NoQuadtree(), PlanarMeshOptions{}}) {
    const PlanarMesh pm = MeshAndCheck(faces, regions, options, 2);
    for (int r = 0; r < static_cast<int>(regions.regions.size()); ++r) {
      EXPECT_LT(MaxPlaneDistance(pm, regions, r), 1e-5) << "region " << r;
    }
  }
  // The same surface from finest faces gives the same planar mesh size.
  const PlanarRegionSet fine_regions = AxisRegions(fine, grid.resolution_m());
  absl::StatusOr<PlanarMesh> a = BuildPlanarMesh(faces, regions, grid, NoQuadtree());
  absl::StatusOr<PlanarMesh> b = BuildPlanarMesh(fine, fine_regions, grid, NoQuadtree());
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->mesh.triangles.size(), b->mesh.triangles.size());
}

// A ramp at 45° made of a staircase of voxel faces, merged into one sloped region.
TEST(PlanarMeshTest, SlopedStaircaseRegionLiesOnItsPlane) {
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  VoxelWorld world({32, 12, 20});
  auto floor_z = [](int x) { return x < 10 ? 2 : x < 16 ? 2 + (x - 10) : 8; };
  for (int x = 2; x < 30; ++x) world.Fill({x, 2, floor_z(x)}, {x + 1, 10, 17}, true);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  std::vector<int64_t> label;
  for (const BoundaryFace& f : faces) {
    const double x = f.center.x() / res, z = f.center.z() / res;
    const bool tread = f.axis == 2 && f.normal().z() > 0 && x > 10 && x < 16;
    const bool riser = f.axis == 0 && f.normal().x() < 0 && x > 10.5 && x < 16.5 && z < 8;
    if (tread || riser) {
      label.push_back(-1);
    } else {
      const int sign = f.normal()[f.axis] > 0 ? 1 : 0;
      label.push_back((std::llround(f.center[f.axis] / res) + 1000) * 8 + f.axis * 2 + sign);
    }
  }
  const PlanarRegionSet regions = RegionsFromLabels(faces, label);
  int ramp = -1;
  for (size_t f = 0; f < faces.size(); ++f) {
    if (label[f] == -1) ramp = regions.face_region[f];
  }
  ASSERT_GE(ramp, 0);
  EXPECT_NEAR(std::abs(regions.regions[ramp].normal.x()), std::sqrt(0.5), 1e-9);
  for (const PlanarMeshOptions& options : {NoQuadtree(), PlanarMeshOptions{}}) {
    const PlanarMesh pm = MeshAndCheck(faces, regions, options, 2);
    for (int r = 0; r < static_cast<int>(regions.regions.size()); ++r) {
      EXPECT_LT(MaxPlaneDistance(pm, regions, r), 1e-5) << "region " << r;
    }
    int ramp_triangles = 0;
    for (int r : pm.triangle_region) ramp_triangles += r == ramp;
    EXPECT_GE(ramp_triangles, 2);
    if (!options.quadtree_points) {
      EXPECT_LE(ramp_triangles, 4);  // a rectangle, really
    }
  }
}

// A one-cell step in a wall whose step faces were merged with the farther wall: two regions
// 14° apart share the step's edge. Intersecting their planes would throw its vertices far away
// (Fig 4.10); the α rule of eq 4.9 keeps them at the step.
TEST(PlanarMeshTest, NearlyParallelRegionsDoNotExplode) {
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  VoxelWorld world({24, 24, 14});
  world.Fill({2, 2, 2}, {22, 22, 12}, true);
  world.Fill({2, 2, 2}, {3, 12, 12}, false);  // the wall at x = 2 steps to x = 3 for y < 12
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  std::vector<int64_t> label;
  for (const BoundaryFace& f : faces) {
    const double x = f.center.x() / res, y = f.center.y() / res;
    const bool step = f.axis == 1 && std::abs(y - 12) < 1e-9 && x < 3;
    const bool near_wall = f.axis == 0 && f.normal().x() > 0 && std::abs(x - 3) < 1e-9;
    if (step || near_wall) {
      label.push_back(-1);
    } else {
      const int sign = f.normal()[f.axis] > 0 ? 1 : 0;
      label.push_back((std::llround(f.center[f.axis] / res) + 1000) * 8 + f.axis * 2 + sign);
    }
  }
  const PlanarRegionSet regions = RegionsFromLabels(faces, label);
  ASSERT_EQ(regions.regions.size(), 7u);
  auto outside_room = [&](const PlanarMesh& pm) {
    double worst = 0;
    for (const Eigen::Vector3f& v : pm.mesh.vertices) {
      for (int a = 0; a < 3; ++a) {
        const double lo = 2 * res, hi = (a == 2 ? 12 : 22) * res;
        worst = std::max({worst, lo - v[a], v[a] - hi});
      }
    }
    return worst / res;  // cells
  };
  const PlanarMesh pm = MeshAndCheck(faces, regions, NoQuadtree(), 2);
  EXPECT_LT(outside_room(pm), 1.0);
  const PlanarMesh pm_q = MeshAndCheck(faces, regions, PlanarMeshOptions{}, 2);
  EXPECT_LT(outside_room(pm_q), 1.0);
  // Without the α rule and without the displacement cap, eq 4.9 sends the same vertices far
  // off (the nearly parallel planes meet far away); they stay in the room all the same, as no
  // vertex moves farther than its triangles allow without turning over (MoveWithoutFolds).
  PlanarMeshOptions naive = NoQuadtree();
  naive.alpha_fraction = 0;
  naive.max_displacement_cells = 1e6;
  absl::StatusOr<PlanarMesh> naive_mesh = BuildPlanarMesh(faces, regions, grid, naive);
  ASSERT_TRUE(naive_mesh.ok()) << naive_mesh.status();
  EXPECT_LT(outside_room(*naive_mesh), 1.0);
  EXPECT_EQ(CountSelfIntersections(naive_mesh->mesh).pairs, 0u);
}

// Labels faces like region growing with the grid-size tolerance would (§4.2.4): each face joins
// the nearest of the true planes (inward normal n, point q) that it does not face away from.
std::vector<int64_t> NearestPlaneLabels(const std::vector<BoundaryFace>& faces,
                                        const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& planes) {
  std::vector<int64_t> label;
  for (const BoundaryFace& f : faces) {
    int best = -1;
    double best_d = 1e300;
    for (size_t i = 0; i < planes.size(); ++i) {
      if (planes[i].first.dot(f.normal().cast<double>()) < -1e-9) continue;
      const double d = std::abs(planes[i].first.dot(f.isosurface() - planes[i].second));
      if (d < best_d) best_d = d, best = static_cast<int>(i);
    }
    // Faces farther than a grid cell or two from every plane (pockets) are no part of them.
    label.push_back(best_d <= 2.0 * f.size_m ? best : -1);
  }
  return label;
}

// A room whose walls are rotated about z: every wall is a staircase of x and y faces fitted by
// one sloped plane, and the four vertical corners come from eq 4.9 with non-axis normals.
class RotatedRoomTest : public ::testing::TestWithParam<std::tuple<double, int>> {};

TEST_P(RotatedRoomTest, WatertightOnThePlanes) {
  const auto [angle_deg, leaf] = GetParam();
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  const double th = angle_deg * M_PI / 180;
  const Eigen::Vector2d c(24, 24), ax(std::cos(th), std::sin(th)), ay(-std::sin(th), std::cos(th));
  const double hx = 14, hy = 9;
  VoxelWorld world({48, 48, 16});
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 48; ++x) {
      const Eigen::Vector2d d = Eigen::Vector2d(x + 0.5, y + 0.5) - c;
      if (std::abs(d.dot(ax)) < hx && std::abs(d.dot(ay)) < hy) world.Fill({x, y, 4}, {x + 1, y + 1, 12}, true);
    }
  const std::vector<BoundaryFace> faces = FacesOf(world, grid, leaf);
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> planes;
  for (int s : {-1, 1}) {
    const Eigen::Vector2d qx = c + s * hx * ax, qy = c + s * hy * ay;
    planes.push_back({Eigen::Vector3d(-s * ax.x(), -s * ax.y(), 0), Eigen::Vector3d(qx.x(), qx.y(), 8) * res});
    planes.push_back({Eigen::Vector3d(-s * ay.x(), -s * ay.y(), 0), Eigen::Vector3d(qy.x(), qy.y(), 8) * res});
  }
  planes.push_back({Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, 0, 4 * res)});
  planes.push_back({-Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, 0, 12 * res)});
  const PlanarRegionSet regions = RegionsFromLabels(faces, NearestPlaneLabels(faces, planes));
  ASSERT_EQ(regions.regions.size(), 6u);
  for (const PlanarMeshOptions& options : {NoQuadtree(), PlanarMeshOptions{}}) {
    const PlanarMesh pm = MeshAndCheck(faces, regions, options, 2);
    for (int r = 0; r < 6; ++r) EXPECT_LT(MaxPlaneDistance(pm, regions, r), 1e-4) << "region " << r;
    if (!options.quadtree_points) {
      EXPECT_LE(pm.mesh.triangles.size(), 16u);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Angles, RotatedRoomTest,
                         ::testing::Combine(::testing::Values(10.0, 30.0, 45.0), ::testing::Values(1, 4)));

// A box room whose walls got one-cell bumps and dents (seeded) away from its edges: regions
// hold faces of several planes and axes, as region growing leaves them, with pinched corners,
// non-manifold edges and closed pockets.
class NoisyRoomTest : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(NoisyRoomTest, Watertight) {
  const auto [seed, leaf] = GetParam();
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  VoxelWorld world({32, 32, 24});
  world.Fill({4, 4, 4}, {28, 28, 20}, true);
  std::mt19937 rng(seed);
  std::bernoulli_distribution flip(0.15);
  for (int z = 3; z < 21; ++z)
    for (int y = 3; y < 29; ++y)
      for (int x = 3; x < 29; ++x) {
        const Eigen::Vector3i cell(x, y, z);
        // Bumps and dents on the walls, floor and ceiling, away from the room's edges.
        const int near_x = x == 3 || x == 4 || x == 27 || x == 28;
        const int near_y = y == 3 || y == 4 || y == 27 || y == 28;
        const int near_z = z == 3 || z == 4 || z == 19 || z == 20;
        const bool inner_x = x >= 7 && x < 25, inner_y = y >= 7 && y < 25, inner_z = z >= 7 && z < 17;
        const bool shell = (near_x && inner_y && inner_z) || (near_y && inner_x && inner_z) ||
                           (near_z && inner_x && inner_y);
        if (shell && flip(rng)) world.interior[world.Index(cell)] = !world.At(cell);
      }
  const std::vector<BoundaryFace> faces = FacesOf(world, grid, leaf);
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> planes;
  for (int a = 0; a < 3; ++a) {
    const double lo = 4, hi = a == 2 ? 20 : 28;
    planes.push_back({Eigen::Vector3d::Unit(a), Eigen::Vector3d::Unit(a) * lo * res});
    planes.push_back({-Eigen::Vector3d::Unit(a), Eigen::Vector3d::Unit(a) * hi * res});
  }
  std::vector<int64_t> label = NearestPlaneLabels(faces, planes);
  // Faces far from every plane (interior islands) keep their own axis-plane region.
  for (size_t f = 0; f < faces.size(); ++f) {
    const int sign = faces[f].normal()[faces[f].axis] > 0 ? 1 : 0;
    if (label[f] < 0) label[f] = 100 + (std::llround(faces[f].center[faces[f].axis] / res) + 1000) * 8 + faces[f].axis * 2 + sign;
  }
  const PlanarRegionSet regions = RegionsFromLabels(faces, label);
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, regions, grid);
  ASSERT_TRUE(pm.ok()) << pm.status();
  EXPECT_TRUE(CheckMesh(pm->mesh).watertight()) << CheckMesh(pm->mesh).ToString();
  // Known limitation: where a bump's faces meet a region border, chain vertices placed by
  // eq 4.9 can leave a few sliver triangles folded against their region's normal (topology
  // stays closed). Today 0–16 of 90–160 triangles, 58 in all 24 rooms: the same slivers as
  // with chains straightened to half a cell, around which the mesh then had 1.6× the
  // triangles. Keep it bounded.
  const int folded = MisorientedTriangles(*pm, regions);
  EXPECT_LE(folded * 8, static_cast<int>(pm->mesh.triangles.size()));
  EXPECT_LT(pm->mesh.triangles.size() * 10, 2 * FinestFaceCount(faces));
  RecordProperty("faces", static_cast<int>(faces.size()));
  RecordProperty("triangles", static_cast<int>(pm->mesh.triangles.size()));
  RecordProperty("folded", folded);
}

INSTANTIATE_TEST_SUITE_P(Seeds, NoisyRoomTest,
                         ::testing::Combine(::testing::Range(1, 13), ::testing::Values(1, 4)));

#ifdef CARVEMAP_HAVE_MESH_REGIONS
// The same synthetic octrees with the regions of the real stage (FitPlanarRegions, §4.2.4).
VoxelWorld FittedWorld(int which) {
  switch (which) {
    case 0: {  // box
      VoxelWorld w({24, 24, 24});
      w.Fill({4, 4, 4}, {20, 20, 20}, true);
      return w;
    }
    case 1: {  // pillar
      VoxelWorld w({24, 24, 16});
      w.Fill({2, 2, 2}, {22, 22, 12}, true);
      w.Fill({10, 10, 2}, {14, 14, 12}, false);
      return w;
    }
    case 2: {  // L-shaped with a one-cell step in one wall
      VoxelWorld w({24, 24, 12});
      w.Fill({2, 2, 2}, {20, 8, 10}, true);
      w.Fill({2, 2, 2}, {8, 20, 10}, true);
      w.Fill({2, 12, 2}, {3, 20, 10}, false);
      return w;
    }
    default: {  // room rotated by 30° about z
      VoxelWorld w({48, 48, 16});
      const double th = 30 * M_PI / 180;
      const Eigen::Vector2d c(24, 24), ax(std::cos(th), std::sin(th)), ay(-std::sin(th), std::cos(th));
      for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 48; ++x) {
          const Eigen::Vector2d d = Eigen::Vector2d(x + 0.5, y + 0.5) - c;
          if (std::abs(d.dot(ax)) < 14 && std::abs(d.dot(ay)) < 9) w.Fill({x, y, 4}, {x + 1, y + 1, 12}, true);
        }
      return w;
    }
  }
}

// FitPlanarRegions with the default growth (levels, floor plans) or mesh_growth (building.ply).
absl::StatusOr<PlanarRegionSet> FitRegions(const std::vector<BoundaryFace>& faces,
                                           const OctreeGrid& grid, bool mesh_growth) {
  PlanarRegionOptions options;
  options.mesh_growth = mesh_growth;
  return FitPlanarRegions(faces, grid, options);
}

class FittedRegionsTest : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(FittedRegionsTest, WatertightWithFitPlanarRegions) {
  const auto [which, leaf] = GetParam();
  const OctreeGrid grid = Grid();
  const std::vector<BoundaryFace> faces = FacesOf(FittedWorld(which), grid, leaf, 0.2);
  // Both growths: the levels' and floor plans' (default) and the building mesh's (mesh_growth).
  for (const bool mesh_growth : {false, true}) {
    SCOPED_TRACE(mesh_growth ? "mesh_growth" : "default growth");
    absl::StatusOr<PlanarRegionSet> regions = FitRegions(faces, grid, mesh_growth);
    ASSERT_TRUE(regions.ok()) << regions.status();
    const int64_t euler = which == 1 ? 0 : 2;
    for (const PlanarMeshOptions& options : {NoQuadtree(), PlanarMeshOptions{}}) {
      const PlanarMesh pm = MeshAndCheck(faces, *regions, options, euler);
      if (!mesh_growth) {
        RecordProperty(options.quadtree_points ? "triangles_quadtree" : "triangles",
                       static_cast<int>(pm.mesh.triangles.size()));
      }
      if (which == 0 && !options.quadtree_points) {
        EXPECT_EQ(pm.mesh.triangles.size(), 12u);
      }
    }
    if (!mesh_growth) RecordProperty("regions", static_cast<int>(regions->regions.size()));
  }
  RecordProperty("faces", static_cast<int>(faces.size()));
}

INSTANTIATE_TEST_SUITE_P(Worlds, FittedRegionsTest,
                         ::testing::Combine(::testing::Values(0, 1, 2, 3), ::testing::Values(1, 4)));

// Robustness (always watertight, no degenerate triangles): rooms with seeded carving
// noise of every kind the carved scans show, through the real region fitting. Bumps and dents
// on the shell, specks of solid in the room, one-cell pockets of free space inside the walls,
// a slanted wall, and isosurface points jittered by up to 0.45 cell (Fig 4.9's clamp).
class NoisyFittedRoomTest : public ::testing::TestWithParam<std::tuple<int, int>> {};

std::vector<BoundaryFace> NoisyFittedRoomFaces(int seed, int leaf, const OctreeGrid& grid) {
  const double res = grid.resolution_m();
  VoxelWorld world({40, 36, 24});
  world.Fill({4, 4, 4}, {36, 32, 20}, true);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  for (int z = 3; z < 21; ++z)
    for (int y = 3; y < 33; ++y)
      for (int x = 3; x < 37; ++x) {
        const Eigen::Vector3i c(x, y, z);
        const bool wall = x < 5 || x > 34 || y < 5 || y > 30 || z < 5 || z > 18;
        if (x + y > 60) world.interior[world.Index(c)] = 0;  // a slanted wall (45°, zig-zag)
        if (wall && u(rng) < 0.2) world.interior[world.Index(c)] = !world.At(c);
        if (!wall && u(rng) < 0.003) world.interior[world.Index(c)] = 0;  // specks
      }
  for (int k = 0; k < 6; ++k) {  // pockets: lone free cells two cells inside the walls
    const int x = 1 + int(u(rng) * 38), y = 1 + int(u(rng) * 34);
    world.interior[world.Index({x, y, 1 + int(u(rng) * 2)})] = 1;
  }
  std::vector<BoundaryFace> faces = FacesOf(world, grid, leaf);
  for (BoundaryFace& f : faces) {
    f.isosurface_m += (u(rng) - 0.5) * 0.9 * std::min(f.size_m, res);
  }
  return faces;
}

TEST_P(NoisyFittedRoomTest, AlwaysWatertight) {
  const auto [seed, leaf] = GetParam();
  const OctreeGrid grid = Grid();
  const std::vector<BoundaryFace> faces = NoisyFittedRoomFaces(seed, leaf, grid);
  RecordProperty("faces", static_cast<int>(faces.size()));
  for (const bool mesh_growth : {false, true}) {
    SCOPED_TRACE(mesh_growth ? "mesh_growth" : "default growth");
    absl::StatusOr<PlanarRegionSet> regions = FitRegions(faces, grid, mesh_growth);
    ASSERT_TRUE(regions.ok()) << regions.status();
    absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, *regions, grid);
    ASSERT_TRUE(pm.ok()) << pm.status();
    const MeshCheck check = CheckMesh(pm->mesh);
    EXPECT_TRUE(check.watertight()) << check.ToString();
    EXPECT_EQ(pm->triangle_region.size(), pm->mesh.triangles.size());
    const std::string suffix = mesh_growth ? "_mesh_growth" : "";
    RecordProperty("regions" + suffix, static_cast<int>(regions->regions.size()));
    RecordProperty("triangles" + suffix, static_cast<int>(pm->mesh.triangles.size()));
  }
}

INSTANTIATE_TEST_SUITE_P(Seeds, NoisyFittedRoomTest,
                         ::testing::Combine(::testing::Range(1, 31), ::testing::Values(1, 4)));

// The noisy rooms above cross themselves where the simplification brought the two faces of a
// one-cell bump or wall into each other, or folded a fan at a vertex. Untangling (collapses and
// short moves of the meeting triangles' vertices; the test at the re-triangulation runs in
// both) removes most of it: 1,992 → 739 pairs over these 12 rooms, fewer in every one.
TEST(PlanarMeshUntangleTest, NoisyRoomsCrossThemselvesLess) {
  const OctreeGrid grid = Grid();
  uint64_t total[2] = {0, 0};
  for (int seed = 1; seed <= 6; ++seed) {
    for (int leaf : {1, 4}) {
      SCOPED_TRACE(::testing::Message() << "seed " << seed << " leaf " << leaf);
      const std::vector<BoundaryFace> faces = NoisyFittedRoomFaces(seed, leaf, grid);
      absl::StatusOr<PlanarRegionSet> regions = FitRegions(faces, grid, /*mesh_growth=*/true);
      ASSERT_TRUE(regions.ok()) << regions.status();
      uint64_t pairs[2];
      for (const bool untangle : {false, true}) {
        PlanarMeshOptions options;
        if (!untangle) options.untangle_edge_cells = options.untangle_move_cells = 0;
        absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, *regions, grid, options);
        ASSERT_TRUE(pm.ok()) << pm.status();
        EXPECT_TRUE(CheckMesh(pm->mesh).watertight()) << CheckMesh(pm->mesh).ToString();
        pairs[untangle] = CountSelfIntersections(pm->mesh).pairs;
        total[untangle] += pairs[untangle];
        if (untangle) {
          EXPECT_GT(pm->untangle_collapses + pm->untangle_moves, 0);
        } else {
          EXPECT_EQ(pm->untangle_collapses + pm->untangle_moves, 0);
        }
      }
      EXPECT_LT(pairs[1], pairs[0]);
    }
  }
  RecordProperty("pairs_without", static_cast<int>(total[0]));
  RecordProperty("pairs_with", static_cast<int>(total[1]));
  EXPECT_LT(total[1], total[0] / 2);
}

// Carved walls that are a little off the lattice are staircases: mesh_growth gives each wall
// one region with its one-cell steps and risers (planar_regions.h), some risers facing a
// little away from the wall's normal. Projected orthogonally onto the plane those risers were
// reversed slivers, and the vertices where walls, floor and ceiling meet, moved by eq 4.9 up
// to three cells over one-cell triangles, folded the regions over themselves: their outlines
// crossed, the re-triangulation failed and the folded triangles stayed (up to 70 intersecting
// pairs in 4 of these 40 rooms). Along the dominant axis, with the moves stopped where a
// triangle would turn over, none remain. (With more noise, 3 % of the cells next to the
// surface flipped, some still do: 2–46 pairs in 16 of 20 rooms before, 3–13 in 6 after.)
class SteppedRoomTest : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(SteppedRoomTest, NoSelfIntersections) {
  const auto [seed, noise_percent] = GetParam();
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  VoxelWorld world({48, 44, 28});
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  // Walls turned by 2–6° about z, a floor and a ceiling tilted by up to 3°.
  const double a = (2 + 4 * u(rng)) * M_PI / 180, b = (2 + 4 * u(rng)) * M_PI / 180;
  const double tx = 3 * u(rng) * M_PI / 180, ty = 3 * u(rng) * M_PI / 180;
  for (int z = 1; z < 27; ++z)
    for (int y = 1; y < 43; ++y)
      for (int x = 1; x < 47; ++x) {
        const double cx = x + 0.5, cy = y + 0.5, cz = z + 0.5;
        const bool inside = cx > 5 + std::tan(a) * cy && cx < 42 - std::tan(a) * cy &&
                            cy > 5 + std::tan(b) * cx && cy < 39 - std::tan(b) * cx &&
                            cz > 4 + std::tan(tx) * cx && cz < 23 - std::tan(ty) * cy;
        world.interior[world.Index({x, y, z})] = inside;
      }
  // Carving noise: cells next to the surface flipped (bumps and dents).
  std::vector<char> flip(world.interior.size(), 0);
  for (int z = 2; z < 26; ++z)
    for (int y = 2; y < 42; ++y)
      for (int x = 2; x < 46; ++x) {
        bool border = false;
        for (int d = 0; d < 6; ++d) {
          Eigen::Vector3i n(x, y, z);
          n[d / 2] += d % 2 ? 1 : -1;
          border = border || world.At(n) != world.At({x, y, z});
        }
        flip[world.Index({x, y, z})] = border && u(rng) < 0.01 * noise_percent;
      }
  for (size_t i = 0; i < flip.size(); ++i) {
    if (flip[i]) world.interior[i] = !world.interior[i];
  }
  std::vector<BoundaryFace> faces = FacesOf(world, grid);
  for (BoundaryFace& f : faces) f.isosurface_m += (u(rng) - 0.5) * 0.9 * res;
  absl::StatusOr<PlanarRegionSet> regions = FitRegions(faces, grid, /*mesh_growth=*/true);
  ASSERT_TRUE(regions.ok()) << regions.status();
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, *regions, grid);
  ASSERT_TRUE(pm.ok()) << pm.status();
  const MeshCheck check = CheckMesh(pm->mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  const SelfIntersections si = CountSelfIntersections(pm->mesh);
  EXPECT_EQ(si.pairs, 0u);
  EXPECT_EQ(si.unchecked, 0u);
  RecordProperty("regions", static_cast<int>(regions->regions.size()));
  RecordProperty("not_retriangulated", pm->regions_not_retriangulated);
  RecordProperty("triangles", static_cast<int>(pm->mesh.triangles.size()));
  RecordProperty("pairs", static_cast<int>(si.pairs));
}

INSTANTIATE_TEST_SUITE_P(Seeds, SteppedRoomTest,
                         ::testing::Combine(::testing::Range(1, 21), ::testing::Values(0, 1)));
#endif  // CARVEMAP_HAVE_MESH_REGIONS

TEST(PlanarMeshTest, Deterministic) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({32, 32, 32});
  world.Fill({4, 4, 4}, {28, 28, 28}, true);
  world.Fill({13, 13, 4}, {16, 15, 6}, false);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid, 8);
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  absl::StatusOr<PlanarMesh> a = BuildPlanarMesh(faces, regions, grid);
  absl::StatusOr<PlanarMesh> b = BuildPlanarMesh(faces, regions, grid);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->mesh.vertices.size(), b->mesh.vertices.size());
  ASSERT_EQ(a->mesh.triangles.size(), b->mesh.triangles.size());
  for (size_t i = 0; i < a->mesh.vertices.size(); ++i) EXPECT_EQ(a->mesh.vertices[i], b->mesh.vertices[i]);
  for (size_t i = 0; i < a->mesh.triangles.size(); ++i) EXPECT_EQ(a->mesh.triangles[i], b->mesh.triangles[i]);
  EXPECT_EQ(a->triangle_region, b->triangle_region);
}

// A region that laps over itself along its axis (the floors of two rooms, one above the other
// and shifted, given one horizontal region) has an outline that crosses itself in its 2D
// coordinates: it keeps its simplified triangles, which cross each other, and the mesh counts
// it. Every other region is re-triangulated.
TEST(PlanarMeshTest, CountsARegionItCannotRetriangulate) {
  const OctreeGrid grid = Grid();
  const double res = grid.resolution_m();
  VoxelWorld world({28, 28, 16});
  world.Fill({4, 4, 2}, {18, 18, 6}, true);
  world.Fill({10, 10, 8}, {24, 24, 14}, true);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  const PlanarRegionSet by_axis = AxisRegions(faces, res);
  ASSERT_EQ(by_axis.regions.size(), 12u);
  auto is_floor = [](const BoundaryFace& f) { return f.axis == 2 && f.normal().z() > 0; };
  std::vector<int64_t> label;
  for (size_t f = 0; f < faces.size(); ++f) {
    label.push_back(is_floor(faces[f]) ? -1 : by_axis.face_region[f]);
  }
  PlanarRegionSet regions = RegionsFromLabels(faces, label);
  ASSERT_EQ(regions.regions.size(), 11u);
  const int both =
      regions.face_region[std::find_if(faces.begin(), faces.end(), is_floor) - faces.begin()];
  regions.regions[both].normal = Eigen::Vector3d::UnitZ();  // PCA would tilt it
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, regions, grid, NoQuadtree());
  ASSERT_TRUE(pm.ok()) << pm.status();
  EXPECT_TRUE(CheckMesh(pm->mesh).watertight()) << CheckMesh(pm->mesh).ToString();
  EXPECT_EQ(pm->regions_not_retriangulated, 1);
  size_t kept = 0;
  for (int r : pm->triangle_region) kept += r == both;
  EXPECT_EQ(pm->triangles_not_retriangulated, kept);
  EXPECT_GT(kept, 0u);
  EXPECT_GT(CountSelfIntersections(pm->mesh).pairs, 0u);
}

// Two interior cells touching only along an edge: the faces around it are paired per
// interior quadrant, so the result stays watertight (two boxes → χ = 2 + 2... joined at an edge
// as separate sheets: two spheres).
TEST(PlanarMeshTest, CellsTouchingAlongAnEdge) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({12, 12, 12});
  world.Fill({2, 2, 2}, {6, 6, 6}, true);
  world.Fill({6, 6, 2}, {10, 10, 6}, true);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, regions, grid, NoQuadtree());
  ASSERT_TRUE(pm.ok()) << pm.status();
  EXPECT_TRUE(CheckMesh(pm->mesh).watertight()) << CheckMesh(pm->mesh).ToString();
  EXPECT_EQ(EulerCharacteristic(pm->mesh), 4);
  // The two sheets' vertices along the edge were moved apart into their own sheets: the
  // surface does not touch itself there.
  const SelfIntersections si = CountSelfIntersections(pm->mesh);
  EXPECT_EQ(si.pairs, 0u);
  EXPECT_EQ(si.unchecked, 0u);
  std::set<std::array<float, 3>> positions;
  for (const Eigen::Vector3f& v : pm->mesh.vertices) positions.insert({v.x(), v.y(), v.z()});
  EXPECT_EQ(positions.size(), pm->mesh.vertices.size());
}

// Two interior cells touching only at a corner: one vertex per sheet there, moved apart.
TEST(PlanarMeshTest, CellsTouchingAtACornerDoNotTouchInTheMesh) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({12, 12, 12});
  world.Fill({2, 2, 2}, {6, 6, 6}, true);
  world.Fill({6, 6, 6}, {10, 10, 10}, true);
  const std::vector<BoundaryFace> faces = FacesOf(world, grid);
  const PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(faces, regions, grid, NoQuadtree());
  ASSERT_TRUE(pm.ok()) << pm.status();
  EXPECT_TRUE(CheckMesh(pm->mesh).watertight()) << CheckMesh(pm->mesh).ToString();
  EXPECT_EQ(CountSelfIntersections(pm->mesh).pairs, 0u);
  // The corner's two copies lie 0.02 cells from it, each inside its own box's corner.
  const Eigen::Vector3f corner = (6 * grid.resolution_m()) * Eigen::Vector3f::Ones();
  int near = 0;
  for (const Eigen::Vector3f& v : pm->mesh.vertices) {
    const Eigen::Vector3f d = v - corner;
    if (d.norm() > 0.1 * grid.resolution_m()) continue;
    ++near;
    EXPECT_NEAR(d.norm(), 0.02 * grid.resolution_m(), 1e-5);
  }
  EXPECT_EQ(near, 2);
}

// What counts as meeting for the untangling, as CountSelfIntersections counts it.
TEST(PlanarMeshTest, TrianglesMeetOtherThanAtWhatTheyShare) {
  using planar_mesh_internal::TrianglesMeet;
  using P = std::array<Eigen::Vector3d, 3>;
  const P flat = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(2, 0, 0), Eigen::Vector3d(0, 2, 0)};
  // Apart, and crossing without a shared vertex.
  EXPECT_FALSE(TrianglesMeet(
      {0, 1, 2}, flat, {3, 4, 5},
      {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(2, 0, 1), Eigen::Vector3d(0, 2, 1)}));
  EXPECT_TRUE(TrianglesMeet(
      {0, 1, 2}, flat, {3, 4, 5},
      {Eigen::Vector3d(0.5, 0.5, -1), Eigen::Vector3d(0.5, 0.5, 1), Eigen::Vector3d(0.5, -1, 0)}));
  // One shared vertex: meeting there only, or passing through the other beyond it.
  EXPECT_FALSE(TrianglesMeet({0, 1, 2}, flat, {0, 4, 5},
                             {flat[0], Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(-1, -1, 1)}));
  EXPECT_TRUE(TrianglesMeet({0, 1, 2}, flat, {0, 4, 5},
                            {flat[0], Eigen::Vector3d(1, 0.5, 1), Eigen::Vector3d(1, 0.5, -1)}));
  // A shared edge: a crease is not meeting, a fold in one plane onto the same side is.
  EXPECT_FALSE(
      TrianglesMeet({0, 1, 2}, flat, {1, 0, 5}, {flat[1], flat[0], Eigen::Vector3d(1, -1, 0)}));
  EXPECT_FALSE(
      TrianglesMeet({0, 1, 2}, flat, {1, 0, 5}, {flat[1], flat[0], Eigen::Vector3d(1, 1, 1)}));
  EXPECT_TRUE(
      TrianglesMeet({0, 1, 2}, flat, {1, 0, 5}, {flat[1], flat[0], Eigen::Vector3d(1, 0.5, 0)}));
  // Vertices on one point count as shared (sheets touching at a corner are the repair's).
  EXPECT_FALSE(TrianglesMeet({0, 1, 2}, flat, {6, 4, 5},
                             {flat[0], Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(-1, -1, 1)}));
  // A triangle without area is its longest edge.
  const P needle = {Eigen::Vector3d(0.5, 0.5, -1), Eigen::Vector3d(0.5, 0.5, 0.5),
                    Eigen::Vector3d(0.5, 0.5, 1)};
  EXPECT_TRUE(TrianglesMeet({0, 1, 2}, flat, {3, 4, 5}, needle));
  EXPECT_FALSE(TrianglesMeet(
      {0, 1, 2}, flat, {3, 4, 5},
      {Eigen::Vector3d(3, 3, -1), Eigen::Vector3d(3, 3, 0), Eigen::Vector3d(3, 3, 1)}));
}

TEST(PlanarMeshTest, RejectsBadInput) {
  const OctreeGrid grid = Grid();
  VoxelWorld world({8, 8, 8});
  world.Fill({2, 2, 2}, {6, 6, 6}, true);
  std::vector<BoundaryFace> faces = FacesOf(world, grid);
  PlanarRegionSet regions = AxisRegions(faces, grid.resolution_m());
  PlanarRegionSet short_set = regions;
  short_set.face_region.pop_back();
  EXPECT_EQ(BuildPlanarMesh(faces, short_set, grid).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::vector<BoundaryFace> open = faces;
  open.pop_back();
  regions.face_region.pop_back();
  EXPECT_EQ(BuildPlanarMesh(open, regions, grid).status().code(),
            absl::StatusCode::kInvalidArgument);
  PlanarMeshOptions bad;
  bad.alpha_fraction = 2;
  EXPECT_FALSE(bad.Validate().ok());
}

#endif  // CARVEMAP_PLANAR_CARVED_ONLY

#ifdef CARVEMAP_PLANAR_CARVED_ONLY
// ---------------------------------------------------------------------------------------------
// Real carved data: a simulated preset carved to tiles in this process (tests/support), its
// boundary faces and dense mesh found out of core through a TileSet (as the merge does),
// regions fitted, planar mesh built.

struct CarvedMeshes {
  testing::CarvedPreset preset;
  std::unique_ptr<TileSet> tiles;
  std::vector<BoundaryFace> faces;
  PlanarRegionSet regions;
  TriangleMesh dense;
  std::vector<uint8_t> dense_vertex_observed;  // DenseMeshResult::vertex_observed
  PlanarMesh planar;
  double planar_s = 0;  // regions + planar mesh, wall seconds
};

absl::StatusOr<CarvedMeshes> CarveAndMesh(const testing::CarvedPresetOptions& options,
                                          const std::string& root,
                                          const PlanarRegionOptions& region_options = {}) {
  CarvedMeshes out;
  absl::StatusOr<testing::CarvedPreset> preset = testing::CarvePreset(options, root);
  if (!preset.ok()) return preset.status();
  out.preset = *std::move(preset);
  absl::StatusOr<std::unique_ptr<TileSet>> tiles =
      TileSet::Open(out.preset.tiles_dir, options.resolution_m, uint64_t{1} << 30);
  if (!tiles.ok()) return tiles.status();
  out.tiles = *std::move(tiles);
  absl::StatusOr<std::vector<BoundaryFace>> faces = CollectBoundaryFaces(*out.tiles);
  if (!faces.ok()) return faces.status();
  out.faces = *std::move(faces);
  absl::StatusOr<DenseMeshResult> dense = BuildDenseMesh(*out.tiles);
  if (!dense.ok()) return dense.status();
  out.dense = std::move(dense->mesh);
  out.dense_vertex_observed = std::move(dense->vertex_observed);
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<PlanarRegionSet> regions =
      FitPlanarRegions(out.faces, out.preset.grid, region_options);
  if (!regions.ok()) return regions.status();
  out.regions = *std::move(regions);
  absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(out.faces, out.regions, out.preset.grid);
  if (!pm.ok()) return pm.status();
  out.planar = *std::move(pm);
  out.planar_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "%s at %.4f m: %zu faces, %zu regions (%s growth; flood fill %zu, grown %zu), dense %zu "
      "triangles, planar %zu triangles (%.2f %%), regions + planar mesh %.1f s\n",
      options.preset.c_str(), options.resolution_m, out.faces.size(),
      out.regions.regions.size(), region_options.mesh_growth ? "mesh" : "default",
      out.regions.flood_fill_groups, out.regions.grown_regions, out.dense.triangles.size(),
      out.planar.mesh.triangles.size(),
      100.0 * double(out.planar.mesh.triangles.size()) / double(out.dense.triangles.size()),
      out.planar_s);
  return out;
}

// Both meshes watertight, and the planar one at most `max_ratio` of the dense one's
// triangles (the goal is 10 %: the dissertation's planar building meshes are thousands of triangles
// where the dense ones are millions, §4.3.3, Fig 4.12 vs 4.13).
void CheckWatertightAndSmall(const CarvedMeshes& m, double max_ratio) {
  const MeshCheck dense = CheckMesh(m.dense);
  EXPECT_TRUE(dense.watertight()) << "dense: " << dense.ToString();
  const MeshCheck planar = CheckMesh(m.planar.mesh);
  EXPECT_TRUE(planar.watertight()) << "planar: " << planar.ToString();
  EXPECT_EQ(m.planar.triangle_region.size(), m.planar.mesh.triangles.size());
  EXPECT_LE(double(m.planar.mesh.triangles.size()), max_ratio * double(m.dense.triangles.size()));
  ::testing::Test::RecordProperty("planar_triangles", static_cast<int>(planar.triangles));
  ::testing::Test::RecordProperty("dense_triangles", static_cast<int>(dense.triangles));
}

// The room's sides: regions of ≥ 10 m², each within 3° of an axis.
int BigAxisRegions(const PlanarRegionSet& regions) {
  int sides = 0;
  for (const PlanarRegion& r : regions.regions) {
    if (r.area_m2 < 10) continue;
    ++sides;
    EXPECT_GT(r.normal.cwiseAbs().maxCoeff(), std::cos(3 * M_PI / 180)) << "region " << r.id;
  }
  return sides;
}

TEST(PlanarMeshCarvedTest, RoomIsWatertightAndSmall) {
  absl::StatusOr<CarvedMeshes> m =
      CarveAndMesh(testing::CarvedPresetOptions{}, ::testing::TempDir() + "/planar_carved");
  ASSERT_TRUE(m.ok()) << m.status();
  {
    SCOPED_TRACE("default growth (levels, floor plans)");
    // The 10 % goal: 8.7 % (7.3 k of 84 k triangles) since rays carry their share of the
    // gaps between them (SamplingCovariance). Before, with the rays ~1 mm wide, the carve was a
    // speckle and this was 38 % (215 k of 573 k triangles, 45 k regions): the carved volume's
    // noisy closure against the unobserved gaps between rays (§4.3.2: unobserved is exterior).
    CheckWatertightAndSmall(*m, 0.10);
    // The room's four walls, its ceiling and its floor (truth: 5.85 × 4.85 × 2.7 m, walls
    // 7.5 cm from the origin) are one region of ≥ 10 m² each. The walls' planes lean up to 2°
    // (normals tilted up): the dense mesh puts a wall ~3 cm inside the truth below 1.5 m (seen
    // at grazing angles) and ~1 cm at the scanners' height, and PCA over the whole wall follows
    // that within §4.2.4's one-cell tolerance.
    EXPECT_EQ(BigAxisRegions(m->regions), 6);
  }
  {
    SCOPED_TRACE("mesh_growth (mesh/building.ply)");
    // The regions the merge meshes mesh/building.ply from: 4.9 % (29 % with the speckle).
    PlanarRegionOptions region_options;
    region_options.mesh_growth = true;
    absl::StatusOr<PlanarRegionSet> regions =
        FitPlanarRegions(m->faces, m->preset.grid, region_options);
    ASSERT_TRUE(regions.ok()) << regions.status();
    m->regions = *std::move(regions);
    absl::StatusOr<PlanarMesh> pm = BuildPlanarMesh(m->faces, m->regions, m->preset.grid);
    ASSERT_TRUE(pm.ok()) << pm.status();
    m->planar = *std::move(pm);
    std::printf("room, mesh_growth: %zu regions (grown %zu), planar %zu triangles (%.2f %%)\n",
                m->regions.regions.size(), m->regions.grown_regions,
                m->planar.mesh.triangles.size(),
                100.0 * double(m->planar.mesh.triangles.size()) /
                    double(m->dense.triangles.size()));
    CheckWatertightAndSmall(*m, 0.10);
    EXPECT_EQ(BigAxisRegions(m->regions), 6);
  }
  ASSERT_TRUE(WritePly(::testing::TempDir() + "/planar_carved/building.ply", m->planar.mesh,
                       &m->planar.triangle_region, "region")
                  .ok());
}

// Points on the surface of a mesh, about one per spacing² of area (seeded), with the
// triangle's unit normal (into free space for the meshes and the truth solids' outside).
struct SurfaceSample {
  Eigen::Vector3d x, n;
  size_t triangle = 0;  // index in mesh.triangles
};
std::vector<SurfaceSample> SampleSurface(const TriangleMesh& mesh, double spacing_m,
                                         uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<SurfaceSample> out;
  for (size_t ti = 0; ti < mesh.triangles.size(); ++ti) {
    const Eigen::Vector3i& t = mesh.triangles[ti];
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[t[2]].cast<double>();
    const Eigen::Vector3d cr = (b - a).cross(c - a);
    const double area = 0.5 * cr.norm();
    if (!(area > 0)) continue;
    const int count = static_cast<int>(std::floor(area / (spacing_m * spacing_m) + u(rng)));
    for (int k = 0; k < count; ++k) {
      double s1 = u(rng), s2 = u(rng);
      if (s1 + s2 > 1) s1 = 1 - s1, s2 = 1 - s2;
      out.push_back({a + s1 * (b - a) + s2 * (c - a), cr.normalized(), ti});
    }
  }
  return out;
}

// The building's solids (walls, slabs, steps, object parts): convex prisms.
bool InsideAnySolid(const std::vector<Prism>& solids, const Eigen::Vector3d& x) {
  for (const Prism& p : solids) {
    if (!(x.z() > p.z0 && x.z() < p.z1)) continue;
    bool inside = true;
    const size_t n = p.footprint.size();
    for (size_t e = 0; e < n && inside; ++e) {
      const Eigen::Vector2d a = p.footprint[e], b = p.footprint[(e + 1) % n];
      inside = (b - a).x() * (x.y() - a.y()) - (b - a).y() * (x.x() - a.x()) > 0;
    }
    if (inside) return true;
  }
  return false;
}

// Whether a planar-mesh point of region `region` lies on observed exterior: the flag of the
// nearest boundary face of that region (its exterior leaf observed, i.e. scan points stand
// behind it), searched in buckets of 4 cells out to 3 buckets (0.375 m at 3.125 cm); a point
// with no face of its region that near counts as observed, so geometry eq 4.9 moved far from
// its faces is held against the mesh.
class RegionFaceObserved {
 public:
  RegionFaceObserved(const std::vector<BoundaryFace>& faces, const PlanarRegionSet& regions,
                     double res)
      : bucket_m_(4 * res) {
    for (size_t i = 0; i < faces.size(); ++i) {
      buckets_[Key(regions.face_region[i], faces[i].center)].push_back(
          {faces[i].center, faces[i].exterior_observed});
    }
  }
  [[nodiscard]] bool operator()(int region, const Eigen::Vector3d& x) const {
    const Key4 k = Key(region, x);
    for (int reach : {1, 3}) {
      double best = std::numeric_limits<double>::infinity();
      bool observed = true;
      for (int dx = -reach; dx <= reach; ++dx) {
        for (int dy = -reach; dy <= reach; ++dy) {
          for (int dz = -reach; dz <= reach; ++dz) {
            auto it = buckets_.find(Key4{region, k[1] + dx, k[2] + dy, k[3] + dz});
            if (it == buckets_.end()) continue;
            for (const auto& [c, o] : it->second) {
              const double d = (c - x).squaredNorm();
              if (d < best) best = d, observed = o;
            }
          }
        }
      }
      if (best < std::numeric_limits<double>::infinity()) return observed;
    }
    return true;
  }

 private:
  using Key4 = std::array<int, 4>;
  [[nodiscard]] Key4 Key(int region, const Eigen::Vector3d& x) const {
    return {region, int(std::floor(x.x() / bucket_m_)), int(std::floor(x.y() / bucket_m_)),
            int(std::floor(x.z() / bucket_m_))};
  }
  double bucket_m_;
  std::map<Key4, std::vector<std::pair<Eigen::Vector3d, bool>>> buckets_;
};

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  const size_t k = static_cast<size_t>(q * double(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

// The accuracy goal on `office` at 3.125 cm against gt/surfaces.ply + gt/objects.ply:
// mesh to truth median ≤ 1.5 cm and 90th percentile ≤ 4 cm, over the mesh where its exterior
// side was observed (elsewhere the mesh closes the carved volume against unobserved space,
// which no truth describes), as the meshes record it (dense: vertex_observed; planar: the
// nearest boundary face of the sample's region, RegionFaceObserved); completeness: ≥ 95 % of
// the observed truth (samples whose free side one cell out was observed, minus faces where
// two solids touch) within 5 cm of the mesh. A short walk (the hallway and first rooms) keeps
// it affordable in CI; both meshes are held to it, and to watertightness and the 10 % rule.
// Measured, the 30 s walk at 3.125 cm, both meshes watertight every time:
// - as here (the simulator's /path_cov rotation std-dev 1e-4 rad; regions with mesh_growth,
//   as then in the tree for everything): 8.51 M faces over 8406 m²,
//   7720 m² of them on no true surface with their exterior unobserved (the closure of a
//   speckled carve, planar_mesh_bench --gt); dense 19.5 M triangles, planar 3.96 M (20 %),
//   planar meshing 462 s CPU; the test passed 6 GB RSS and was killed by the OOM killer.
// - mesh_growth, with a rotation std-dev of 0.1° (0.5°) written into /path_cov, before the
//   carve-speed merge (c30cc03): 2.06 M (1.84 M) faces; planar 5.0 % (4.2 %) of dense; dense median
//   1.39 (1.78) cm, p90 11.1 (17.9) cm, completeness 83.5 (64.8) %; planar median 1.35
//   (2.65) cm, p90 29.7 (24.9) cm, completeness 82.3 (63.6) %.
// - as here, after single-ray wedges were narrowed to 1σ (1ec8c95): 8.84 M faces, dense 20.3 M
//   triangles, planar 4.31 M (21.3 %); dense median 42 cm, p90 ≥ 50 cm over the 2.24 M of 8.79 M
//   samples whose exterior was observed (the speckle's faces dominate), completeness 100 %;
//   planar median 46 cm, completeness 84.8 %; 906 s to carve and mesh, 6.8 GB peak RSS.
// - since rays carry their share of the gaps between them (SamplingCovariance, fef5e6f):
//   1.70 M faces, dense 4.34 M triangles, planar 255 k (5.9 %); dense median 1.15 cm, p90
//   18.3 cm, completeness 97.4 %; planar median 0.97 cm, p90 29.6 cm, completeness 94.75 %;
//   77 s, 1.3 GB peak RSS. Only the p90s and the planar completeness are not met: the samples
//   more than 10 cm from any truth cluster at 1.5–2.5 m (the scanners' height and the lights')
//   along the corridor (x 8–16 m, y 4–8 m).
// - the same meshes, with the mesh's exterior side told by the meshes' own record instead of
//   the leaf one cell behind each sample (measured later): dense median 0.90 cm, p90 2.2 cm over
//   501 k of 1.73 M samples; planar median 0.66 cm, p90 3.65 cm over 513 k of 1.68 M;
//   completeness unchanged (97.4 %, 94.75 %). Dense samples more than 10 cm from truth: 78.9 k
//   (13.3 %) by the old probe, 6.0 k (1.2 %) now. The old probe's were mostly surfaces whose
//   exterior is not observed: the one-cell step from a surface that closes a thin unobserved
//   pocket (or a free-space slab whose underside was never seen, e.g. at z 1.5 and 1.75 m in
//   the corridor) lands in observed space on the pocket's other side. Of the boundary faces whose
//   exterior leaf is observed, 1.8 % lie more than 10 cm from truth. Only the planar
//   completeness was not met: 47 % of its misses (12.4 k of 26.6 k truth samples more than
//   5 cm from it) lay on the lobby's curved wall (x ≈ 37 m), whose facets relaxation chained
//   into one plane.
// - since relaxation with mesh_growth keeps each union within the tolerance in RMS: 14 298
//   regions (was 14 260), planar 252 k triangles (5.8 %); planar median 0.63 cm, p90 2.4 cm,
//   completeness 97.4 %; dense unchanged. Everything is met (until then a DISABLED_ variant
//   held the goals and this test regression bounds).
// - since the isosurface takes each leaf's p at the finest cell beside the face, not at a big
//   leaf's centre (IsosurfaceOffsetM): dense median 0.72 cm, p90 2.1 cm; planar median 0.41 cm,
//   p90 2.4 cm, 13 892 regions, 240 k triangles (5.5 %); completeness 97.4 % for both.
TEST(PlanarMeshCarvedTest, OfficeMeshesAgainstTruth) {
  testing::CarvedPresetOptions options;
  options.preset = "office";
  options.resolution_m = 0.03125;
  const char* walk = std::getenv("PLANAR_OFFICE_WALK_S");
  options.walk_s = walk != nullptr ? std::atof(walk) : 30;
  const auto t0 = std::chrono::steady_clock::now();
  PlanarRegionOptions region_options;  // as the merge fits them for mesh/building.ply
  region_options.mesh_growth = true;
  absl::StatusOr<CarvedMeshes> m =
      CarveAndMesh(options, ::testing::TempDir() + "/planar_office", region_options);
  ASSERT_TRUE(m.ok()) << m.status();
  std::printf("office carved and meshed in %.0f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  CheckWatertightAndSmall(*m, 0.10);

  absl::StatusOr<Building> building = MakePresetBuilding("office", options.seed);
  ASSERT_TRUE(building.ok()) << building.status();
  std::vector<Prism> solids = building->structure;
  for (const ObjectTruth& o : building->objects) {
    solids.insert(solids.end(), o.parts.begin(), o.parts.end());
  }
  TriangleMesh truth = StructureMesh(*building);
  truth.Append(ObjectsMesh(*building));
  const double r = options.resolution_m;
  TileSet& tiles = *m->tiles;
  auto carved = [&](const Eigen::Vector3d& x) {
    absl::StatusOr<LeafQuery> q = tiles.Query(x);
    return q.ok() && q->stored && q->stats.observed() && q->stats.p() > 0.5;
  };
  // Observed truth: samples whose free side one cell out was carved (seen as free space by
  // the scans). Observed exterior there does not count: the 3σ tails of rays that hit a wall
  // (§4.3.1) make the space behind it observed, and no scan saw the wall's back.
  std::vector<Eigen::Vector3d> seen_truth;
  for (const SurfaceSample& s : SampleSurface(truth, 0.03, 7)) {
    if (InsideAnySolid(solids, s.x + 2e-3 * s.n)) continue;  // two solids touching
    if (carved(s.x + r * s.n)) seen_truth.push_back(s.x);
  }
  ASSERT_GT(seen_truth.size(), 10000u);
  std::vector<std::array<Eigen::Vector3d, 3>> truth_tris;
  for (const Eigen::Vector3i& t : truth.triangles) {
    truth_tris.push_back({truth.vertices[t[0]].cast<double>(), truth.vertices[t[1]].cast<double>(),
                          truth.vertices[t[2]].cast<double>()});
  }
  const testing::TruthDistance to_truth(truth_tris, 0.25, 0.5);
  // Where the mesh's exterior was observed, by the mesh's own record: a dense triangle whose
  // three vertices lie between interior and observed exterior leaves (vertex_observed), a
  // planar point whose nearest boundary face of its region has an observed exterior leaf.
  const RegionFaceObserved planar_observed(m->faces, m->regions, r);
  for (const auto& [name, mesh] : {std::pair<const char*, const TriangleMesh*>{"dense", &m->dense},
                                   {"planar", &m->planar.mesh}}) {
    SCOPED_TRACE(name);
    std::vector<double> d;
    size_t samples = 0;
    for (const SurfaceSample& s : SampleSurface(*mesh, 0.03, 11)) {
      ++samples;
      const Eigen::Vector3i& t = mesh->triangles[s.triangle];
      const bool on_observed =
          mesh == &m->dense
              ? m->dense_vertex_observed[t[0]] && m->dense_vertex_observed[t[1]] &&
                    m->dense_vertex_observed[t[2]]
              : planar_observed(m->planar.triangle_region[s.triangle], s.x);
      if (on_observed) d.push_back(to_truth(s.x));
    }
    const testing::TruthDistance to_mesh(testing::MeshTriangles(*mesh), 0.25, 0.05);
    size_t near = 0;
    for (const Eigen::Vector3d& x : seen_truth) near += to_mesh(x) < 0.05;
    const double median = Percentile(d, 0.5), p90 = Percentile(d, 0.9);
    const double completeness = double(near) / double(seen_truth.size());
    std::printf(
        "%s: mesh to truth over %zu of %zu samples (exterior observed): median %.4f m, "
        "p90 %.4f m; %.1f %% of %zu observed truth samples within 5 cm\n",
        name, d.size(), samples, median, p90, 100 * completeness, seen_truth.size());
    EXPECT_LE(median, 0.015);
    EXPECT_LE(p90, 0.04);
    EXPECT_GE(completeness, 0.95);
  }
}

#endif  // CARVEMAP_PLANAR_CARVED_ONLY

}  // namespace
}  // namespace carvemap
