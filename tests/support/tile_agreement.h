// How far two carves of one scan agree, leaf by leaf: what the fast evaluation is held to
// against the exact one (worker/chunk_octree.h CarveEvaluation).
//   labels — over every finest leaf observed in either carve (a stored leaf stands for the
//            finest leaves under it, §4.3.2), the share whose label (interior iff p > 0.5;
//            unobserved is exterior) is the same in both;
//   p      — over every stored leaf of the reference, |Δp| against the other carve's p over the
//            same node (the weighted mean of its sums there, §4.3.2's merge: where the two
//            simplified differently, the other's leaves inside the node are summed, or the
//            one holding it is read).
// Header-only test support: tests and benchmarks include it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "geometry/octree_keys.h"
#include "storage/tile_store.h"

namespace carvemap::testing {

struct TileAgreement {
  uint64_t finest_leaves = 0;      // observed in either carve
  uint64_t finest_same_label = 0;
  uint64_t stored_leaves = 0;      // of the reference
  uint64_t stored_within_0_01 = 0;  // |Δp| ≤ 0.01
  double max_dp = 0;
  std::vector<double> dp;  // per stored leaf of the reference

  [[nodiscard]] double LabelShare() const {
    return finest_leaves ? double(finest_same_label) / double(finest_leaves) : 1.0;
  }
  [[nodiscard]] double PShare() const {
    return stored_leaves ? double(stored_within_0_01) / double(stored_leaves) : 1.0;
  }
  // The q-quantile of |Δp| (0 ≤ q ≤ 1).
  [[nodiscard]] double DpQuantile(double q) const {
    if (dp.empty()) return 0;
    std::vector<double> s = dp;
    const size_t i = std::min(s.size() - 1, size_t(q * double(s.size() - 1) + 0.5));
    std::nth_element(s.begin(), s.begin() + i, s.end());
    return s[i];
  }
};

namespace tile_agreement_internal {

// Finest leaf (local x | y << 10 | z << 20) → index of the stored leaf that holds it.
inline absl::flat_hash_map<uint32_t, uint32_t> Owners(const TileData& tile) {
  absl::flat_hash_map<uint32_t, uint32_t> out;
  const int k = tile.grid.chunk_depth;
  for (uint32_t i = 0; i < tile.leaves.size(); ++i) {
    const TileLeaf& leaf = tile.leaves[i];
    const int span = 1 << (k - leaf.node.depth);
    const Eigen::Vector3i base = leaf.node.local * span;
    for (int z = 0; z < span; ++z)
      for (int y = 0; y < span; ++y)
        for (int x = 0; x < span; ++x) {
          const Eigen::Vector3i l = base + Eigen::Vector3i(x, y, z);
          out[uint32_t(l.x()) | uint32_t(l.y()) << 10 | uint32_t(l.z()) << 20] = i;
        }
  }
  return out;
}

}  // namespace tile_agreement_internal

// Adds one chunk's pair of tiles (same chunk and grid; either may be absent: nullptr).
inline void AddTilePair(const TileData* reference, const TileData* other, TileAgreement& out) {
  using tile_agreement_internal::Owners;
  static const TileData kEmpty;
  const TileData& ref = reference ? *reference : kEmpty;
  const TileData& oth = other ? *other : kEmpty;
  const int k = reference ? ref.grid.chunk_depth : oth.grid.chunk_depth;
  const auto ref_owner = Owners(ref), oth_owner = Owners(oth);
  const auto label = [](const TileData& t, const absl::flat_hash_map<uint32_t, uint32_t>& owner,
                        uint32_t key) {
    auto it = owner.find(key);
    return it != owner.end() && t.leaves[it->second].stats.interior();
  };
  for (const auto* owners : {&ref_owner, &oth_owner}) {
    for (const auto& [key, index] : *owners) {
      if (owners == &oth_owner && ref_owner.contains(key)) continue;  // counted once
      ++out.finest_leaves;
      if (label(ref, ref_owner, key) == label(oth, oth_owner, key)) ++out.finest_same_label;
    }
  }
  for (const TileLeaf& leaf : ref.leaves) {
    // The other carve's sums over this node.
    const int span = 1 << (k - leaf.node.depth);
    const Eigen::Vector3i base = leaf.node.local * span;
    std::map<uint32_t, bool> seen;  // the other's stored leaves met
    LeafStats sum;
    for (int z = 0; z < span; ++z)
      for (int y = 0; y < span; ++y)
        for (int x = 0; x < span; ++x) {
          const Eigen::Vector3i l = base + Eigen::Vector3i(x, y, z);
          auto it = oth_owner.find(uint32_t(l.x()) | uint32_t(l.y()) << 10 | uint32_t(l.z()) << 20);
          if (it == oth_owner.end() || !seen.emplace(it->second, true).second) continue;
          sum.Merge(oth.leaves[it->second].stats);
        }
    const double d = std::abs(leaf.stats.p() - sum.p());
    ++out.stored_leaves;
    if (d <= 0.01) ++out.stored_within_0_01;
    out.max_dp = std::max(out.max_dp, d);
    out.dp.push_back(d);
  }
}

}  // namespace carvemap::testing
