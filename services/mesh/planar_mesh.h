// Planar meshing of the octree's boundary faces (§4.2.5, §4.3.3 "Planar region meshing";
// docs/DESIGN.md §6 stages 2 and 8): one watertight triangle mesh whose triangles lie on the planes
// of the planar regions.
//
// How: the faces become a closed polygon mesh on the finest lattice (T-junctions of big and
// small faces split, non-manifold octree edges separated into sheets). Each region is seen in
// 2D along its dominant axis (§4.2.5, Fig 4.7a), where its lattice faces do not overlap; the
// vertices inside a region go onto its plane along that axis, and the vertices where two or
// more regions meet move from their octree corners towards their eq 4.9 positions (SVD over
// the regions' planes with the α rule for nearly parallel planes) only as far as no triangle
// turns over and no region wraps around a vertex in its 2D coordinates. Edge collapses that
// keep the mesh a closed manifold, under the same two conditions, then remove region
// interiors and straight runs of the chains between two regions, so neighbouring regions keep
// exactly the same boundary vertices. Where the simplified surface then passes through itself
// (the two faces of a part one or two cells thick, a fan folded at a vertex), the meeting
// triangles' vertices are collapsed or moved a little where that leaves fewer meeting pairs
// (untangling; §4.2.5 does not look for self-intersections). Last, each region is
// re-triangulated in its 2D coordinates and lifted onto its plane (constrained Delaunay of its
// boundary plus quadtree points, §4.2.5), or keeps its collapsed triangles when its boundary
// does not make a valid polygon there or the lifted triangles would meet more of the other
// regions' triangles. The few self-intersections left are there.
#pragma once

#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/planar_regions.h"
#include "storage/ply_io.h"

namespace carvemap {

// Memory the planar regions (FitPlanarRegions) and then the planar mesh take per boundary
// face, on top of the faces themselves (sizeof(BoundaryFace)): what a merge checks a memory
// budget against before it starts them. Measured with tests/bench/planar_mesh_bench (each
// stage's own peak) on office2 at 6.25 cm, 1.19 M faces: 212 B per face while the regions are
// fitted, 201 B while the mesh is made with the regions kept (docs/BENCHMARKS.md "The planar
// stages' own memory"); rounded up for the allocator's slack.
inline constexpr uint64_t kPlanarBytesPerFace = 256;

struct PlanarMeshOptions {
  // eq 4.9: a singular direction of the stacked plane normals is trusted only when its singular
  // value is at least this fraction of the largest one (the dissertation's α = 0.2·s; see the .cc).
  double alpha_fraction = 0.2;
  // A vertex placed by eq 4.9 moves at most this many grid cells from its octree corner (the
  // move is clamped; §4.2.5: shared vertices are "allowed to be displaced up to a distance
  // threshold from their original position"), and less where a triangle would turn over.
  double max_displacement_cells = 3.0;
  // A vertex of a chain between two regions is removed only when it lies within this distance
  // (grid cells) of the segment joining its chain neighbours. 0 removes collinear ones only.
  // One cell, the resolution the walls were sampled at (as §3.3.3 simplifies a plan's walls):
  // at half a cell the chains keep more of their octree staircase, whose steps make many more
  // regions' outlines cross in their plane, and those regions keep their simplified triangles,
  // where the mesh crosses itself (docs/BENCHMARKS.md "Where building.ply still crosses itself").
  double chain_tolerance_cells = 1.0;
  // Where the simplified mesh passes through itself (the two faces of a part one or two cells
  // thick moved or collapsed into each other, a fan folded at a vertex), a vertex of the
  // meeting triangles is collapsed into a neighbour at most this many grid cells away, or else
  // moved up to `untangle_move_cells`, when that leaves fewer meeting pairs around it. Both 0:
  // not done. §4.2.5 does not check for self-intersection; CountSelfIntersections finds them.
  double untangle_edge_cells = 8.0;
  double untangle_move_cells = 1.0;
  // §4.2.5: add quadtree points inside regions (bounded angles, bigger triangles on bigger
  // regions). false: the regions' boundary vertices only (fewest triangles).
  bool quadtree_points = true;
  // Smallest quadtree cell that gets interior points, in grid cells (8: 0.5 m at 6.25 cm), so
  // narrow regions keep only their boundary vertices.
  int min_quadtree_cells = 8;

  [[nodiscard]] absl::Status Validate() const;
};

struct PlanarMesh {
  TriangleMesh mesh;              // counter-clockwise seen from free space (the faces' normals)
  std::vector<int> triangle_region;  // per triangle: its PlanarRegion id
  // Regions that could not be re-triangulated in their plane (mostly: their outline crosses
  // itself in their 2D coordinates), and the triangles they hold: they keep their simplified
  // triangles, which may fold through each other or a neighbour's; most of the mesh's
  // self-intersections are there (docs/BENCHMARKS.md). job.json counts both.
  int regions_not_retriangulated = 0;
  size_t triangles_not_retriangulated = 0;
  // Of those, the regions whose outline did make a polygon, but whose triangles lifted onto
  // their plane would have met more of their neighbours' triangles than the simplified ones.
  int regions_kept_off_plane = 0;
  // Untangle's work (PlanarMeshOptions::untangle_*): vertices collapsed, vertices moved.
  int untangle_collapses = 0;
  int untangle_moves = 0;
};

// The planar mesh of `faces` partitioned by `regions` (regions.face_region.size() ==
// faces.size()). Faces are the closed boundary of the interior (all chunks' faces together);
// their corners must lie on `grid`'s lattice. Deterministic for the same input. Its last
// step is RepairPlanarMesh (planar_mesh_repair.h). Errors: InvalidArgument for bad options,
// mismatched sizes, faces off the lattice or a face boundary that is not closed; Internal when
// a region cannot be triangulated.
[[nodiscard]] absl::StatusOr<PlanarMesh> BuildPlanarMesh(std::span<const BoundaryFace> faces,
                                                         const PlanarRegionSet& regions,
                                                         const OctreeGrid& grid,
                                                         const PlanarMeshOptions& options = {});

}  // namespace carvemap
