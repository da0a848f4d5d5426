// The planar mesh's last step (§4.3.3, docs/DESIGN.md §6 stage 8), on the mesh as it is
// written: float positions, what CheckMesh and any reader see. BuildPlanarMesh runs it; the
// hand-made meshes of its test reach every branch.
#pragma once

#include <array>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "services/mesh/planar_mesh.h"

namespace carvemap {

// `mesh` must be closed and manifold; it stays so. (1) Closed pieces of at most 16 vertices
// that enclose less than one grid cell (res³) are dropped: a one-cell pocket whose corners
// eq 4.9 put onto (nearly) one plane, down to two triangles on the same three vertices. (2)
// Triangles of less than `min_area_m2` (three vertices on a line: eq 4.9 moved a chain vertex
// onto its neighbours' line, or float rounding did) are removed by flipping their longest edge
// within their region, else by collapsing their shortest edge (a region border moves by that
// edge), else by moving one of their vertices a hundredth of a cell off the line; none of
// these folds a triangle over. Unused vertices are dropped. (3) Where sheets of the surface
// meet only at a point (interior cells touching along an edge or at a corner), each keeps its
// own vertex there, so that the mesh is a manifold; those vertices coincide, and the surface
// would touch itself (a self-intersection to CGAL). Each moves 0.02 cells into its own sheet,
// unless a triangle would then fold.
struct PlanarMeshRepair {
  int dropped_pieces = 0;
  int flips = 0;
  int collapses = 0;
  int nudges = 0;
  int left = 0;       // triangles still below min_area_m2 (0 unless every repair was blocked)
  int separated = 0;  // coincident vertices moved apart
};
PlanarMeshRepair RepairPlanarMesh(PlanarMesh& mesh, double res, double min_area_m2 = 1e-10);

// Closed pieces of the surface with at most this many vertices are small enough to be carving
// noise when they also have no volume (TinyPieces); a whole room has 8.
inline constexpr int kTinyPieceVertices = 16;

// Per triangle: the id of its piece when that is a small closed piece (at most kTinyPieceVertices
// vertices) that enclose less than one grid cell (|volume| < res³) or hold a triangle `bad` says is
// flat or folded. Pieces are joined across shared edges, so a piece that touches the rest of the
// surface at a single vertex (a pocket sharing a corner) is a piece of its own; dropping it
// leaves every other edge's two triangles in place. −1 for triangles to keep (and dead ones).
// BuildPlanarMesh also drops such pieces while it simplifies, before the output exists.
[[nodiscard]] std::vector<int> TinyPieces(int num_tris,
                                          const std::function<std::array<int, 3>(int)>& tri,
                                          const std::function<bool(int)>& alive,
                                          const std::function<Eigen::Vector3d(int)>& pos,
                                          const std::function<bool(int)>& bad, double res);

}  // namespace carvemap
