#include "services/mesh/self_intersections.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include <boost/function_output_iterator.hpp>

namespace carvemap {

SelfIntersections CountSelfIntersections(const TriangleMesh& mesh) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Mesh = CGAL::Surface_mesh<K::Point_3>;
  SelfIntersections out;
  Mesh sm;
  sm.reserve(Mesh::size_type(mesh.vertices.size()), Mesh::size_type(mesh.triangles.size() * 3 / 2),
             Mesh::size_type(mesh.triangles.size()));
  std::vector<Mesh::Vertex_index> vertex;
  vertex.reserve(mesh.vertices.size());
  for (const Eigen::Vector3f& v : mesh.vertices) {
    vertex.push_back(sm.add_vertex(K::Point_3(v.x(), v.y(), v.z())));
  }
  const int64_t n = int64_t(vertex.size());
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const bool valid = (t.array() >= 0).all() && (t.array().cast<int64_t>() < n).all() &&
                       t[0] != t[1] && t[1] != t[2] && t[0] != t[2];
    if (!valid || sm.add_face(vertex[t[0]], vertex[t[1]], vertex[t[2]]) == Mesh::null_face()) {
      ++out.unchecked;  // Surface_mesh refuses what would not be an oriented 2-manifold
    }
  }
  // Counted as they come: the pairs themselves are not kept.
  uint64_t pairs = 0;
  CGAL::Polygon_mesh_processing::self_intersections(
      faces(sm), sm,
      boost::make_function_output_iterator(
          [&pairs](const std::pair<Mesh::Face_index, Mesh::Face_index>&) { ++pairs; }));
  out.pairs = pairs;
  return out;
}

}  // namespace carvemap
