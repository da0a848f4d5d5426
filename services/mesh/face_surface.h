// The octree's boundary faces as a closed polygon mesh on the finest lattice: the surface the
// planar mesh (planar_mesh.h, §4.3.3) simplifies and places on the regions' planes. Faces of
// any sizes meet in T-junctions (docs/DESIGN.md §6 stage 1), and interior cells touching only
// along an edge or at a corner make non-manifold places; both are resolved here, so that
// every edge has exactly one twin and every vertex one fan of faces.
#pragma once

#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "services/mesh/boundary_faces.h"

namespace carvemap {

// Face f's polygon is its corners [poly_start[f], poly_start[f+1]), counter-clockwise seen
// from its normal (into free space).
struct FaceSurface {
  std::vector<Eigen::Vector3i> lattice;  // lattice vertices (global finest-cell corners)
  std::vector<int> poly_start;           // face f's corners: [poly_start[f], poly_start[f+1])
  std::vector<int> corner_vertex;        // per corner: lattice vertex
  std::vector<int> corner_face;          // per corner: face
  std::vector<int> twin;                 // per corner c: the corner starting the twin edge
  std::vector<int> corner_tv;            // per corner: topological vertex
  int num_tv = 0;
  std::vector<int> tv_lattice;  // per topological vertex: its lattice vertex

  [[nodiscard]] int Next(int c) const {
    const int f = corner_face[c];
    return c + 1 == poly_start[f + 1] ? poly_start[f] : c + 1;
  }
};

// The polygon mesh of `faces` at lattice spacing `res` (m): corners split at every lattice
// vertex lying on a face's edges (T-junctions between big and small faces), edges paired with
// their twins, and corners grouped into topological vertices (one per fan of faces around a
// lattice vertex, so that the octree's non-manifold edges and corners, two interior cells
// touching along an edge, become separate sheets). InvalidArgument naming the face for a face
// off the lattice, and naming the lattice point for an edge used unevenly each way or more
// than twice (faces that are not a closed surface).
[[nodiscard]] absl::StatusOr<FaceSurface> BuildSurface(std::span<const BoundaryFace> faces,
                                                       double res);

}  // namespace carvemap
