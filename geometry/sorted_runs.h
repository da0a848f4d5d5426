// The runs of equal keys in a sorted array: how the meshes pair the faces or corners that share
// an edge (planar_regions.cc, planar_mesh.cc) after sorting the edges' keys, which holds 8–16
// bytes per edge where a hash map of edges would hold several times that.
#pragma once

#include <cstddef>
#include <type_traits>

namespace carvemap {

// Calls run(begin, end) for each maximal range [begin, end) of `items` (sorted, or at least
// grouped, by key) whose elements have equal key(item), in order. A `run` that returns bool
// stops the walk by returning false.
template <typename Items, typename Key, typename Run>
void ForEachRun(const Items& items, Key key, Run run) {
  for (size_t begin = 0; begin < items.size();) {
    size_t end = begin + 1;
    while (end < items.size() && key(items[end]) == key(items[begin])) ++end;
    if constexpr (std::is_same_v<std::invoke_result_t<Run&, size_t, size_t>, bool>) {
      if (!run(begin, end)) return;
    } else {
      run(begin, end);
    }
    begin = end;
  }
}

}  // namespace carvemap
