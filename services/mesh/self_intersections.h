// Self-intersections of a triangle mesh: a mesh can be watertight (mesh_checks.h: every edge
// shared by two consistently oriented triangles) and still pass through itself, which breaks
// what users do with a closed surface (volumes, booleans, 3D printing). The merge counts them
// for each mesh it writes (job.json "counts": <mesh>_self_intersections).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>

#include "storage/ply_io.h"

namespace carvemap {

struct SelfIntersections {
  // Pairs of triangles that meet other than at the vertex or edge they share (index-wise:
  // triangles are adjacent when they share vertex indices; callers weld equal positions
  // first). A degenerate triangle counts as meeting its neighbours.
  uint64_t pairs = 0;
  // Triangles that were not tested: a repeated or bad vertex index, or one an oriented
  // 2-manifold cannot hold beside the triangles before it in its slab (a third triangle on an
  // edge, an edge traversed twice in one direction). CheckMesh reports why; 0 for a watertight
  // mesh.
  uint64_t unchecked = 0;
};

// Triangles per slab: CGAL's boxes for one slab take ~110 bytes per triangle, ~30 MB.
inline constexpr size_t kSelfIntersectionTrianglesPerSlab = size_t{1} << 18;

// CGAL's Polygon_mesh_processing::self_intersections with exact predicates (EPICK): boxes of
// the triangles intersected first, then each candidate pair tested exactly. Run on slabs along
// x of about `triangles_per_slab` triangles each, each slab a Surface_mesh of the triangles
// that reach into it, on `threads` threads; the pairs counted depend on neither. Memory:
// 8 bytes per triangle plus, per thread, one slab's Surface_mesh and boxes (~180 bytes per
// triangle of the slab).
//
// A part of a larger mesh (a window of it along x) is counted with [count_x_lo, count_x_hi):
// only the pairs whose x* (the larger of the two triangles' minimum x) lies in it, and the
// triangles a manifold cannot hold whose minimum x lies in it; windows that tile x, each with
// every triangle that reaches into its range, sum to the whole mesh's counts. Triangles with a
// bad or repeated index are counted in every window.
[[nodiscard]] SelfIntersections CountSelfIntersections(
    const TriangleMesh& mesh, int threads = 1,
    size_t triangles_per_slab = kSelfIntersectionTrianglesPerSlab,
    double count_x_lo = -std::numeric_limits<double>::infinity(),
    double count_x_hi = std::numeric_limits<double>::infinity());

}  // namespace carvemap
