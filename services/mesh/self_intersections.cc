#include "services/mesh/self_intersections.h"

#include <algorithm>
#include <array>
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

#include "absl/container/flat_hash_map.h"

namespace carvemap {

SelfIntersections CountSelfIntersections(const TriangleMesh& mesh, int threads,
                                         size_t triangles_per_slab, double count_x_lo,
                                         double count_x_hi) {
  auto counted_here = [count_x_lo, count_x_hi](float x) {
    return double(x) >= count_x_lo && double(x) < count_x_hi;
  };
  triangles_per_slab = std::max<size_t>(triangles_per_slab, 1);
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Mesh = CGAL::Surface_mesh<K::Point_3>;
  SelfIntersections out;
  const int64_t n = int64_t(mesh.vertices.size());
  // Per triangle: its extent along x; lo = +∞ for a triangle with a bad or repeated index.
  std::vector<std::pair<float, float>> x_range(mesh.triangles.size());
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Eigen::Vector3i& t = mesh.triangles[f];
    const bool valid = (t.array() >= 0).all() && (t.array().cast<int64_t>() < n).all() &&
                       t[0] != t[1] && t[1] != t[2] && t[0] != t[2];
    if (!valid) {
      ++out.unchecked;
      x_range[f] = {INFINITY, -INFINITY};
      continue;
    }
    const float x0 = mesh.vertices[t[0]].x(), x1 = mesh.vertices[t[1]].x(),
                x2 = mesh.vertices[t[2]].x();
    x_range[f] = {std::min({x0, x1, x2}), std::max({x0, x1, x2})};
  }
  // One Surface_mesh of the whole mesh (~70 bytes per triangle) and one call over all its
  // faces (CGAL's boxes, ~110 bytes per triangle) were the merge's peak on a dense mesh of
  // millions of triangles. So the triangles are tested in slabs along x, each slab a
  // Surface_mesh of every triangle whose extent reaches into it. Two triangles that cross have
  // overlapping boxes, so both reach the slab holding x* = the larger of their minimum x; a
  // pair is counted only in that slab, hence once. Triangles that share a vertex share it in
  // every slab that holds both, so adjacency is the whole mesh's.
  std::vector<float> starts;  // slab s covers [starts[s], starts[s + 1]); the first from −∞
  {
    std::vector<float> lows;
    lows.reserve(x_range.size());
    for (const auto& [lo, hi] : x_range) {
      if (lo <= hi) lows.push_back(lo);
    }
    std::sort(lows.begin(), lows.end());
    for (size_t i = triangles_per_slab; i < lows.size(); i += triangles_per_slab) {
      if (starts.empty() || lows[i] > starts.back()) starts.push_back(lows[i]);
    }
  }
  auto slab_of = [&starts](float x) {
    return size_t(std::upper_bound(starts.begin(), starts.end(), x) - starts.begin());
  };
  // Slabs are independent, so `threads` take them in turn, each with its own counts: the sums
  // do not depend on which thread counted which slab.
  const size_t num_slabs = starts.size() + 1;
  std::atomic<size_t> next_slab{0};
  std::vector<SelfIntersections> counted(size_t(std::max(threads, 1)));
  auto work = [&](SelfIntersections& c) {
    Mesh sm;
    absl::flat_hash_map<int, Mesh::Vertex_index> local;
    std::vector<uint32_t> triangle_of;  // per face of `sm`: its triangle in `mesh`
    std::vector<Mesh::Face_index> slab_faces;
    for (size_t slab = next_slab++; slab < num_slabs; slab = next_slab++) {
      const float lo = slab == 0 ? -INFINITY : starts[slab - 1];
      const float hi = slab == starts.size() ? INFINITY : starts[slab];
      sm.clear();
      local.clear();
      triangle_of.clear();
      slab_faces.clear();
      for (size_t f = 0; f < x_range.size(); ++f) {
        if (!(x_range[f].first <= x_range[f].second) || x_range[f].second < lo ||
            x_range[f].first >= hi) {
          continue;
        }
        std::array<Mesh::Vertex_index, 3> v;
        for (int k = 0; k < 3; ++k) {
          const int i = mesh.triangles[f][k];
          auto [it, added] = local.try_emplace(i);
          if (added) {
            const Eigen::Vector3f& p = mesh.vertices[size_t(i)];
            it->second = sm.add_vertex(K::Point_3(p.x(), p.y(), p.z()));
          }
          v[k] = it->second;
        }
        const Mesh::Face_index face = sm.add_face(v[0], v[1], v[2]);
        if (face == Mesh::null_face()) {
          // Surface_mesh refuses what would not be an oriented 2-manifold: counted once, in
          // the slab of the triangle's minimum x.
          if (slab_of(x_range[f].first) == slab && counted_here(x_range[f].first)) {
            ++c.unchecked;
          }
          continue;
        }
        triangle_of.push_back(uint32_t(f));
        slab_faces.push_back(face);
      }
      // Counted as they come: the pairs themselves are not kept.
      CGAL::Polygon_mesh_processing::self_intersections(
          slab_faces, sm,
          boost::make_function_output_iterator(
              [&](const std::pair<Mesh::Face_index, Mesh::Face_index>& p) {
                const float x = std::max(x_range[triangle_of[size_t(p.first)]].first,
                                         x_range[triangle_of[size_t(p.second)]].first);
                if (slab_of(x) == slab && counted_here(x)) ++c.pairs;
              }));
    }
  };
  std::vector<std::thread> pool;
  for (size_t t = 1; t < counted.size() && t < num_slabs; ++t) {
    pool.emplace_back(work, std::ref(counted[t]));
  }
  work(counted[0]);
  for (std::thread& th : pool) th.join();
  for (const SelfIntersections& c : counted) {
    out.pairs += c.pairs;
    out.unchecked += c.unchecked;
  }
  return out;
}

}  // namespace carvemap
