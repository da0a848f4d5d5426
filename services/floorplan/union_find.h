// Union-find with path halving, shared by the Eigencrust cleanup (eigencrust.cc, §3.2.3) and
// the wall curve fitting (wall_curve_fit.cc, §3.2.4). Join(a, b) puts a's root under b's.
#pragma once

#include <cstddef>
#include <numeric>
#include <vector>

namespace carvemap::floorplan_internal {

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void Join(int a, int b) { parent[Find(a)] = Find(b); }
};

}  // namespace carvemap::floorplan_internal
