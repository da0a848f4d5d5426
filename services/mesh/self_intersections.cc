#include "services/mesh/self_intersections.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <thread>
#include <utility>
#include <vector>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include <boost/function_output_iterator.hpp>

namespace carvemap {

SelfIntersections CountSelfIntersections(const TriangleMesh& mesh, int threads,
                                         size_t triangles_per_slab) {
  triangles_per_slab = std::max<size_t>(triangles_per_slab, 1);
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
  // Per face of `sm` (in the order added): its extent along x.
  std::vector<std::pair<float, float>> x_range;
  x_range.reserve(mesh.triangles.size());
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const bool valid = (t.array() >= 0).all() && (t.array().cast<int64_t>() < n).all() &&
                       t[0] != t[1] && t[1] != t[2] && t[0] != t[2];
    if (!valid || sm.add_face(vertex[t[0]], vertex[t[1]], vertex[t[2]]) == Mesh::null_face()) {
      ++out.unchecked;  // Surface_mesh refuses what would not be an oriented 2-manifold
      continue;
    }
    const float x0 = mesh.vertices[t[0]].x(), x1 = mesh.vertices[t[1]].x(),
                x2 = mesh.vertices[t[2]].x();
    x_range.emplace_back(std::min({x0, x1, x2}), std::max({x0, x1, x2}));
  }
  std::vector<Mesh::Vertex_index>().swap(vertex);
  // One call over all faces would hold CGAL's boxes for all of them at once (the merge's peak
  // on a dense mesh of millions of triangles), so the faces are tested in slabs along x,
  // each with every face whose extent reaches into it. Two faces that cross have overlapping
  // boxes, so both reach the slab holding x* = the larger of their minimum x; a pair is counted
  // only in that slab, hence once. Adjacency stays the whole mesh's (one Surface_mesh).
  std::vector<float> starts;  // slab s covers [starts[s], starts[s + 1]); the first from −∞
  {
    std::vector<float> lows(x_range.size());
    for (size_t f = 0; f < x_range.size(); ++f) lows[f] = x_range[f].first;
    std::sort(lows.begin(), lows.end());
    for (size_t i = triangles_per_slab; i < lows.size(); i += triangles_per_slab) {
      if (starts.empty() || lows[i] > starts.back()) starts.push_back(lows[i]);
    }
  }
  auto slab_of = [&starts](float x) {
    return size_t(std::upper_bound(starts.begin(), starts.end(), x) - starts.begin());
  };
  // Slabs are independent (CGAL only reads the mesh), so `threads` take them in turn, each
  // with its own count: the sum does not depend on which thread counted which slab.
  const size_t num_slabs = starts.size() + 1;
  std::atomic<size_t> next_slab{0};
  std::vector<uint64_t> counted(size_t(std::max(threads, 1)), 0);
  auto work = [&](uint64_t& pairs) {
    std::vector<Mesh::Face_index> slab_faces;
    for (size_t slab = next_slab++; slab < num_slabs; slab = next_slab++) {
      const float lo = slab == 0 ? -INFINITY : starts[slab - 1];
      const float hi = slab == starts.size() ? INFINITY : starts[slab];
      slab_faces.clear();
      for (size_t f = 0; f < x_range.size(); ++f) {
        if (x_range[f].second >= lo && x_range[f].first < hi) {
          slab_faces.push_back(Mesh::Face_index(Mesh::size_type(f)));
        }
      }
      // Counted as they come: the pairs themselves are not kept.
      CGAL::Polygon_mesh_processing::self_intersections(
          slab_faces, sm,
          boost::make_function_output_iterator(
              [&](const std::pair<Mesh::Face_index, Mesh::Face_index>& p) {
                const float x = std::max(x_range[size_t(p.first)].first,
                                         x_range[size_t(p.second)].first);
                if (slab_of(x) == slab) ++pairs;
              }));
    }
  };
  std::vector<std::thread> pool;
  for (size_t t = 1; t < counted.size() && t < num_slabs; ++t) {
    pool.emplace_back(work, std::ref(counted[t]));
  }
  work(counted[0]);
  for (std::thread& th : pool) th.join();
  uint64_t pairs = 0;
  for (uint64_t c : counted) pairs += c;
  out.pairs = pairs;
  return out;
}

}  // namespace carvemap
