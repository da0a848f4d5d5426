#include "services/mesh/mesh_checks.h"

#include <algorithm>
#include <array>
#include <utility>

#include <Eigen/Geometry>

#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_cat.h"

namespace carvemap {

std::string MeshCheck::ToString() const {
  return absl::StrCat(triangles, " triangles, ", edges, " edges: ", boundary_edges,
                      " boundary, ", nonmanifold_edges, " non-manifold, ", misoriented_edges,
                      " misoriented edges; ", degenerate_triangles, " degenerate, ",
                      duplicate_triangles, " duplicate triangles, ", bad_indices, " bad indices");
}

MeshCheck CheckMesh(const TriangleMesh& mesh, double area_epsilon_m2) {
  MeshCheck check;
  check.triangles = mesh.triangles.size();
  const int64_t n = static_cast<int64_t>(mesh.vertices.size());
  // Undirected edge (lo, hi) → (uses, uses traversing lo → hi).
  absl::flat_hash_map<std::pair<int, int>, std::pair<int, int>> edges;
  absl::flat_hash_set<std::array<int, 3>> seen;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    if ((t.array() < 0).any() || (t.array().cast<int64_t>() >= n).any()) {
      ++check.bad_indices;
      continue;
    }
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      ++check.degenerate_triangles;
      continue;
    }
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[t[2]].cast<double>();
    if (0.5 * (b - a).cross(c - a).norm() < area_epsilon_m2) ++check.degenerate_triangles;
    std::array<int, 3> key = {t[0], t[1], t[2]};
    std::sort(key.begin(), key.end());
    if (!seen.insert(key).second) ++check.duplicate_triangles;
    for (int i = 0; i < 3; ++i) {
      const int u = t[i], v = t[(i + 1) % 3];
      auto& e = edges[{std::min(u, v), std::max(u, v)}];
      ++e.first;
      if (u < v) ++e.second;
    }
  }
  check.edges = edges.size();
  for (const auto& [key, use] : edges) {
    if (use.first == 1) ++check.boundary_edges;
    if (use.first >= 3) ++check.nonmanifold_edges;
    // Two consistently oriented triangles traverse a shared edge once in each direction.
    if (use.first == 2 && use.second != 1) ++check.misoriented_edges;
  }
  return check;
}

}  // namespace carvemap
