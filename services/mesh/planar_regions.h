// Planar regions of the octree's boundary faces (§4.2.4, §4.3.3; docs/DESIGN.md §6 stage 2):
// flood fill of connected faces with the same direction, PCA region growing with the
// grid-size tolerance, then relaxation that merges adjacent regions whose planes are within
// 15°. Planes are fitted by PCA on the faces' isosurface positions (Fig 4.9), weighted by area.
//
// The three stages:
//  (a) flood fill: faces with the same axis and direction that share (part of) an edge;
//  (b) PCA region growing over those groups, largest first (the dissertation merges "adjacent
//  regions
//      of voxel faces", Fig 4.6c): a group joins a region when every isosurface point of the
//      group is within the tolerance of the union's plane and the region's own points stay
//      within max(tolerance, their previous maximum) (with mesh_growth: within max(tolerance,
//      the seed group's spread)). Whole groups, not single faces, so a lattice plane (a stair
//      riser, one side of a step) is never split between two regions;
//  (c) relaxation: adjacent regions within merge_angle_deg merge, smallest angle first, when
//      their planes also meet where the regions touch (boundary_tolerance_factor) and the
//      union's normal is within the angle of both (with mesh_growth: and the union lies
//      within the tolerance of its plane in RMS). (b) never adds a group facing away from
//      the region's normal (with mesh_growth: more than ~105° away; perpendicular risers and
//      steps do join) and (c) merges only planes within the angle, so the two sides of a thin
//      slab (a table top one cell thick) stay apart.
//
// A global stage: it takes the faces of the whole octree (or of one level).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"

namespace carvemap {

struct PlanarRegionOptions {
  // §4.2.4: a face joins a region when its isosurface point lies within this distance of the
  // region's plane. 0 = the grid resolution ("grid-size tolerance").
  double distance_tolerance_m = 0;
  // §4.2.4: relaxation merges adjacent regions whose normals differ by less than this.
  double merge_angle_deg = 15.0;
  // Relaxation also requires the two planes to meet where the regions touch: the mean of their
  // shared face edges lies within this many tolerances of both planes (so parallel planes with
  // a step between them, e.g. a floor and a stair tread, stay apart).
  double boundary_tolerance_factor = 2.0;
  // Growth (b) for the planar mesh (§4.3.3) rather than for the floor plans. Off (the
  // default): a region's own points may not get farther from its plane than before (within
  // max(tolerance, their current maximum), checked exactly within a budget of a few passes
  // over all faces), and only groups facing the region's side (< 90°) join; the wall samples
  // of the floor plans (§5.3.1) and the levels (§5.2) are built from these. On: the region's
  // points stay within max(tolerance, its seed group's spread), checked exactly without a
  // budget (through a convex hull of the points), and groups up to ~105° from the region's
  // normal join (the risers of a zig-zag, Fig 4.7a, and the one-cell steps of a carved wall;
  // those more than 45° off join without a say in the plane): far fewer, bigger regions, so
  // less than half the planar mesh's triangles on the simulated office. Its vertical regions
  // give worse wall samples, and its planes lie a little farther from the true walls
  // (docs/BENCHMARKS.md "Dense vs planar meshes"). The merge fits the default for the levels
  // and floor plans and this for mesh/building.ply. With it, relaxation (c) also requires
  // the union's RMS distance from its plane to stay within the tolerance (a curved wall's
  // facets would otherwise chain into one plane; the dissertation's relaxation has no distance
  // test).
  bool mesh_growth = false;

  // InvalidArgument for a negative or non-finite tolerance or factor, or a merge angle outside
  // [0, 90].
  [[nodiscard]] absl::Status Validate() const;
};

struct PlanarRegion {
  int id = 0;                     // index in PlanarRegionSet::regions
  Eigen::Vector3d normal;         // unit; oriented like its faces (into free space)
  Eigen::Vector3d centroid;       // area-weighted mean of the faces' isosurface points, m
  double area_m2 = 0;             // Σ face areas
  std::vector<uint32_t> faces;    // indices into the face list given to FitPlanarRegions
  // PCA eigenvalues of the face points (ascending; λ0 = spread off the plane), m².
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();
};

struct PlanarRegionSet {
  std::vector<PlanarRegion> regions;  // deterministic order (by smallest face index)
  std::vector<int> face_region;       // per input face: its region id
  // Region counts after each stage (job.json counts, tuning): (a) flood fill, (b) growing;
  // regions.size() is the count after (c) relaxation.
  size_t flood_fill_groups = 0;
  size_t grown_regions = 0;
};

// Faces are adjacent when they share an edge or part of one (mixed sizes allowed); their
// corners must lie on `grid`'s lattice. The result depends on the faces' geometry only, not on
// their order: shuffling the input permutes `faces` indices and region ids but gives the same
// partition. O(n log n) in the number of faces (edges are matched by sorting).
// Errors: InvalidArgument for bad options or a face that is not finite, has no size, or an
// axis outside 0..2, or when the faces span more than 2^20 cells along an axis.
[[nodiscard]] absl::StatusOr<PlanarRegionSet> FitPlanarRegions(std::span<const BoundaryFace> faces,
                                                              const OctreeGrid& grid,
                                                              const PlanarRegionOptions& options);

}  // namespace carvemap
