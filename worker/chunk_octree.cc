#include "worker/chunk_octree.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "services/geometry/carve_map.h"
#include "services/geometry/wedge_geometry.h"

namespace carvemap {
namespace {

bool Finite(const RayModel& ray) {
  if (!ray.sensor_mean.allFinite() || !ray.point_mean.allFinite()) return false;
  for (int i = 0; i < 6; ++i) {
    if (!std::isfinite(ray.sensor_cov[i]) || !std::isfinite(ray.point_cov[i])) return false;
  }
  return true;
}

// One wedge's descent through the chunk: prune nodes the hull misses, fuse at finest leaves.
struct Carver {
  const OctreeGrid& grid;
  const ChunkKey& chunk;
  const WedgeHull& hull;
  const std::array<std::optional<PreparedRay>, 4>& rays;
  int num_rays;
  absl::flat_hash_map<uint64_t, LeafStats>& leaves;
  Eigen::Vector3d chunk_origin = chunk.cast<double>() * kChunkSizeM;
  uint64_t updates = 0;

  void Visit(const ChunkNode& node) {
    // NodeBox's arithmetic, inlined (it was a sixth of the carving time): chunk·2 m is exact,
    // local·size is exact (size is a power of two, local < 2^10), so the one rounding of the sum
    // is NodeBox's and the box is bit-identical to it — the coordinator binned this wedge with
    // the same chunk box, so it is never pruned at the root.
    const double size = kChunkSizeM / (1 << node.depth);
    const Eigen::Vector3d lo = chunk_origin + node.local.cast<double>() * size;
    const Eigen::AlignedBox3d box(lo, lo + Eigen::Vector3d::Constant(size));
    if (!HullIntersectsBox(hull, box)) return;
    if (node.depth == grid.chunk_depth) {
      Fuse(node, box.center());
      return;
    }
    ChunkNode child;
    child.depth = node.depth + 1;
    for (int c = 0; c < 8; ++c) {
      child.local = 2 * node.local + Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      Visit(child);
    }
  }

  // eq 4.8: "if any wedge intersects L, then all four scan rays from that wedge are used", each
  // evaluated at the leaf centre x_L.
  void Fuse(const ChunkNode& node, const Eigen::Vector3d& x_leaf) {
    std::array<CarveSample, 4> samples;
    int n = 0;
    for (int r = 0; r < num_rays; ++r) {
      const CarveSample s = rays[r]->Evaluate(x_leaf);
      // w = f_⊥ ∈ [0, 1] is how much the ray speaks about x_L. Below 1e-6 (x_L beyond ~5.3 σ_⊥
      // of the ray) its vote is 0.5 ± 1e-6, i.e. nothing, yet Add() would still count it and
      // make the leaf "observed": far corners of a wedge hull would become observed p ≈ 0.5
      // (exterior) leaves that block the "all observed or none" merge of §4.3.2 and inflate the
      // ray counts later stages read. Skipping also keeps sum_w clear of denormals.
      if (s.w >= kMinRayWeight) samples[n++] = s;
    }
    if (n == 0) return;  // no ray spoke: the leaf stays unobserved (stores nothing)
    LeafStats& stats = leaves[MortonCode(node.local)];
    for (int i = 0; i < n; ++i) stats.Add(samples[i].p, samples[i].w);
    updates += static_cast<uint64_t>(n);
  }
};

}  // namespace

ChunkOctree::ChunkOctree(const OctreeGrid& grid, const ChunkKey& chunk)
    : grid_(grid), chunk_(chunk), levels_(static_cast<size_t>(grid.chunk_depth) + 1) {
  assert(grid.chunk_depth >= kMinChunkDepth && grid.chunk_depth <= kMaxChunkDepth);
}

absl::Status ChunkOctree::CarveWedge(const Wedge& wedge) {
  if (simplified_) {
    return absl::FailedPreconditionError("chunk_octree: CarveWedge after Simplify");
  }
  if (wedge.num_rays < 1 || wedge.num_rays > 4) {
    return absl::InvalidArgumentError(
        absl::StrCat("chunk_octree: wedge with ", wedge.num_rays, " rays (expected 1 to 4)"));
  }
  std::array<std::optional<PreparedRay>, 4> rays;
  int num_rays = 0;
  for (int r = 0; r < wedge.num_rays; ++r) {
    if (!Finite(wedge.rays[r])) {
      return absl::InvalidArgumentError(
          absl::StrCat("chunk_octree: wedge ray ", r, " has a non-finite mean or covariance"));
    }
  }
  for (int r = 0; r < wedge.num_rays; ++r) {
    // With finite input, Make only fails for a ray shorter than 1 µm: it has no direction and
    // carves nothing, but its wedge's other rays still do.
    auto prepared = PreparedRay::Make(wedge.rays[r]);
    if (prepared.ok()) rays[num_rays++].emplace(*std::move(prepared));
  }
  ++num_wedges_;
  if (num_rays == 0) return absl::OkStatus();

  const WedgeHull hull = MakeWedgeHull(wedge, kWedgeHullSigmas);
  Carver carver{grid_, chunk_, hull, rays, num_rays, levels_[grid_.chunk_depth]};
  carver.Visit(ChunkNode{});
  num_leaf_updates_ += carver.updates;
  return absl::OkStatus();
}

void ChunkOctree::Simplify() {
  // Bottom-up (§4.3.2): a parent can only become a leaf once its children's levels are final,
  // so depth k is processed first and merged parents are considered again one level up.
  for (int d = grid_.chunk_depth; d >= 1; --d) {
    Level& level = levels_[d];
    if (level.size() < 8) continue;
    // Sorted, so siblings are adjacent (Morton: siblings share code >> 3) and merge sums run in
    // a fixed order: the result never depends on the hash map's iteration order.
    std::vector<std::pair<uint64_t, LeafStats>> sorted(level.begin(), level.end());
    std::sort(sorted.begin(), sorted.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    Level& parents = levels_[d - 1];
    for (size_t i = 0; i + 8 <= sorted.size();) {
      const uint64_t parent = sorted[i].first >> 3;
      if ((sorted[i + 7].first >> 3) != parent) {
        // Fewer than 8 observed siblings: the others are unobserved, so the children are
        // neither all observed nor all unobserved; no merge.
        ++i;
        while (i < sorted.size() && (sorted[i].first >> 3) == parent) ++i;
        continue;
      }
      const bool interior = sorted[i].second.interior();
      bool same_label = true;
      for (size_t j = i + 1; j < i + 8; ++j) same_label &= sorted[j].second.interior() == interior;
      if (same_label) {
        // Sums: the parent's p is the weight-averaged p of its children, which keeps the label
        // (a weighted mean of values all > 0.5, or all ≤ 0.5, stays on the same side).
        LeafStats merged;
        for (size_t j = i; j < i + 8; ++j) {
          merged.Merge(sorted[j].second);
          level.erase(sorted[j].first);
        }
        parents.emplace(parent, merged);
      }
      i += 8;
    }
  }
  simplified_ = true;
}

std::vector<TileLeaf> ChunkOctree::Leaves() const {
  std::vector<TileLeaf> leaves;
  leaves.reserve(num_leaves());
  for (int d = 0; d <= grid_.chunk_depth; ++d) {
    for (const auto& [code, stats] : levels_[d]) {
      TileLeaf leaf;
      leaf.node.local = MortonDecode(code);
      leaf.node.depth = d;
      leaf.stats = stats;
      leaves.push_back(leaf);
    }
  }
  // Hash-map order is arbitrary; the canonical order (distinct keys) makes the output depend
  // only on the contents.
  SortTileLeaves(grid_, leaves);
  return leaves;
}

LeafStats ChunkOctree::StatsAt(const Eigen::Vector3d& x_world, int* depth) const {
  if (depth != nullptr) *depth = -1;
  const int k = grid_.chunk_depth;
  const Eigen::Vector3i local = LeafOf(grid_, x_world) - chunk_ * grid_.leaves_per_side();
  if ((local.array() < 0).any() || (local.array() >= grid_.leaves_per_side()).any()) {
    return LeafStats{};
  }
  for (int d = k; d >= 0; --d) {
    const Level& level = levels_[d];
    if (level.empty()) continue;
    const Eigen::Vector3i ancestor(local.x() >> (k - d), local.y() >> (k - d), local.z() >> (k - d));
    auto it = level.find(MortonCode(ancestor));
    if (it != level.end()) {
      if (depth != nullptr) *depth = d;
      return it->second;
    }
  }
  return LeafStats{};
}

TileData ChunkOctree::ToTile(const std::string& job_id) const {
  TileData tile;
  tile.chunk = chunk_;
  tile.grid = grid_;
  tile.params.job_id = job_id;
  tile.params.num_wedges = num_wedges_;
  tile.params.hull_sigmas = kWedgeHullSigmas;
  tile.params.min_weight = kMinRayWeight;
  tile.params.simplified = simplified_;
  tile.leaves = Leaves();
  return tile;
}

size_t ChunkOctree::num_leaves() const {
  size_t n = 0;
  for (const Level& level : levels_) n += level.size();
  return n;
}

}  // namespace carvemap
