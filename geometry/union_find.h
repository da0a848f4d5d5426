// Disjoint sets over 0 … n−1: the connected pieces of meshes (planar_mesh.cc, object_meshes.cc),
// of boundary faces (planar_regions.cc) and of floor-plan graphs (eigencrust.cc,
// wall_curve_fit.cc, room_labeling.cc). Ours rather than Boost's disjoint_sets, which lives in
// boost/pending (no stable interface) and needs property maps for what is a dozen lines here.
#pragma once

#include <cstddef>
#include <numeric>
#include <utility>
#include <vector>

namespace carvemap {

template <typename Index = int>
class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), Index{0}); }

  // The root of x's set, halving the path on the way.
  Index Find(Index x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }

  // Joins the sets of a and b. The smaller root survives, so a set's root is its smallest
  // member whatever the order of the joins. Returns whether they were apart.
  bool Union(Index a, Index b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return false;
    if (b < a) std::swap(a, b);
    parent_[b] = a;
    return true;
  }

  [[nodiscard]] size_t size() const { return parent_.size(); }

 private:
  std::vector<Index> parent_;
};

}  // namespace carvemap
