// The Delaunay triangulation of the wall samples that both floor-plan methods build on (seed
// §3.2.2 Eigencrust, §3.3.1 room labelling): CGAL's, flattened to arrays, with CGAL's point
// location and circumcentres. CGAL stays in delaunay_mesh.cc (pimpl): it is slow to compile.
#ifndef CARVEMAP_SERVICES_FLOORPLAN_DELAUNAY_MESH_H_
#define CARVEMAP_SERVICES_FLOORPLAN_DELAUNAY_MESH_H_

#include <Eigen/Core>
#include <array>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"

namespace carvemap::floorplan_internal {

// Where a point lies in the triangulation: on a vertex, inside a face, on an edge (the face
// and the index in it of the vertex opposite the edge; a hull edge is named by its finite
// face), or outside the convex hull (kNone).
struct PointLocation {
  enum Kind { kNone, kVertex, kFace, kEdge } kind = kNone;
  int id = -1;  // the vertex or the face
  int edge = -1;
};

class DelaunayMesh {
 public:
  // Triangulates `points` (distinct; vertex ids are their indices). Deterministic: Hilbert order
  // (unlike spatial_sort's shuffle) and one-by-one insertion with the previous vertex as hint
  // give the same triangulation for the same positions, even where four are cocircular.
  // A CGAL failure is INTERNAL "<who>: CGAL triangulation failed: …".
  static absl::StatusOr<DelaunayMesh> Build(const std::vector<Eigen::Vector2d>& points,
                                            const char* who);
  DelaunayMesh(DelaunayMesh&&) noexcept;
  DelaunayMesh& operator=(DelaunayMesh&&) noexcept;
  ~DelaunayMesh();

  // 2 for a triangulation with faces; less when the points are collinear (no faces).
  [[nodiscard]] int dimension() const;
  // The finite faces in CGAL's order: counter-clockwise vertex ids, and neighbours[f][i] the
  // face across the edge opposite triangles[f][i] (−1 outside the hull).
  [[nodiscard]] const std::vector<std::array<int, 3>>& triangles() const { return triangles_; }
  [[nodiscard]] const std::vector<std::array<int, 3>>& neighbours() const { return neighbours_; }
  // CGAL point location of `q`, starting from face *hint (−1: anywhere); *hint becomes the
  // finite face where `q` was found (unchanged outside the hull).
  [[nodiscard]] PointLocation Locate(const Eigen::Vector2d& q, int* hint) const;

 private:
  struct Impl;
  DelaunayMesh();
  std::unique_ptr<Impl> impl_;
  std::vector<std::array<int, 3>> triangles_;
  std::vector<std::array<int, 3>> neighbours_;
};

// The circumcentre of each triangle of `points` (CGAL's construction).
std::vector<Eigen::Vector2d> Circumcentres(const std::vector<Eigen::Vector2d>& points,
                                           const std::vector<std::array<int, 3>>& triangles);

}  // namespace carvemap::floorplan_internal

#endif  // CARVEMAP_SERVICES_FLOORPLAN_DELAUNAY_MESH_H_
