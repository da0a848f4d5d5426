// Compares two carves of the same scan leaf by leaf (e.g. before and after a change to the
// carver): tile_compare DIR_A DIR_B, each a directory of tiles (storage/TILE_FORMAT.md).
// Every finest leaf observed in either is compared (a simplified leaf stands for all the finest
// leaves under it, §4.3.2): label (interior iff p > 0.5) agreement, observed-ness agreement,
// and |Δp| (max, mean, quantiles) over the stored leaves both tiles hold as the same node
// (where simplification merged differently, the finest labels are compared, not p). Prints one
// report.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "storage/tile_store.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

// Finest leaf (local linear index) → stats, per chunk.
using FinestMap = absl::flat_hash_map<uint32_t, LeafStats>;

void Expand(const TileData& tile, FinestMap& out) {
  const int k = tile.grid.chunk_depth;
  for (const TileLeaf& leaf : tile.leaves) {
    const int span = 1 << (k - leaf.node.depth);
    const Eigen::Vector3i base = leaf.node.local * span;
    for (int z = 0; z < span; ++z)
      for (int y = 0; y < span; ++y)
        for (int x = 0; x < span; ++x) {
          const Eigen::Vector3i l = base + Eigen::Vector3i(x, y, z);
          out[uint32_t(l.x()) | uint32_t(l.y()) << 10 | uint32_t(l.z()) << 20] = leaf.stats;
        }
  }
}

std::map<std::string, std::string> Tiles(const std::string& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() == ".h5") out[e.path().filename().string()] = e.path().string();
  }
  return out;
}

int Main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: tile_compare DIR_A DIR_B\n");
    return 2;
  }
  const auto a_tiles = Tiles(argv[1]), b_tiles = Tiles(argv[2]);
  uint64_t both = 0, only_a = 0, only_b = 0, label_diff = 0, a_int = 0, b_int = 0;
  uint64_t count_diff = 0, tiles_only = 0, same_nodes = 0, node_count_diff = 0;
  std::vector<double> dp;
  double max_rel_w = 0;
  for (const auto& [name, path_a] : a_tiles) {
    auto it = b_tiles.find(name);
    if (it == b_tiles.end()) {
      ++tiles_only;
      continue;
    }
    absl::StatusOr<TileData> a = ReadTile(path_a), b = ReadTile(it->second);
    if (!a.ok() || !b.ok()) {
      std::fprintf(stderr, "tile_compare: %s\n",
                   std::string((a.ok() ? b : a).status().message()).c_str());
      return 1;
    }
    FinestMap fa, fb;
    Expand(*a, fa);
    Expand(*b, fb);
    absl::flat_hash_map<uint64_t, LeafStats> nodes_b;
    for (const TileLeaf& l : b->leaves) {
      nodes_b[MortonCode(l.node.local) << 4 | uint64_t(l.node.depth)] = l.stats;
    }
    for (const TileLeaf& l : a->leaves) {
      auto jt = nodes_b.find(MortonCode(l.node.local) << 4 | uint64_t(l.node.depth));
      if (jt == nodes_b.end()) continue;
      ++same_nodes;
      node_count_diff += l.stats.count != jt->second.count;
      dp.push_back(std::abs(l.stats.p() - jt->second.p()));
      max_rel_w = std::max(max_rel_w, std::abs(l.stats.sum_w - jt->second.sum_w) /
                                          std::max(l.stats.sum_w, 1e-300));
    }
    for (const auto& [key, sa] : fa) {
      auto jt = fb.find(key);
      if (jt == fb.end()) {
        ++only_a;
        continue;
      }
      const LeafStats& sb = jt->second;
      ++both;
      a_int += sa.interior();
      b_int += sb.interior();
      label_diff += sa.interior() != sb.interior();
      count_diff += sa.count != sb.count;
    }
    for (const auto& [key, sb] : fb) only_b += !fa.contains(key);
  }
  for (const auto& [name, path] : b_tiles) tiles_only += !a_tiles.contains(name);
  std::sort(dp.begin(), dp.end());
  auto q = [&](double f) { return dp.empty() ? 0.0 : dp[size_t(f * (dp.size() - 1))]; };
  double mean = 0;
  for (double d : dp) mean += d;
  mean = dp.empty() ? 0 : mean / dp.size();
  std::printf("tiles: %zu in A, %zu in B, %llu in only one\n", a_tiles.size(), b_tiles.size(),
              static_cast<unsigned long long>(tiles_only));
  std::printf("finest leaves observed in both: %llu; only in A: %llu; only in B: %llu\n",
              static_cast<unsigned long long>(both), static_cast<unsigned long long>(only_a),
              static_cast<unsigned long long>(only_b));
  std::printf("labels differ: %llu (%.4f %%); interior in A %llu, in B %llu; vote counts of "
              "their stored leaves differ: %llu\n",
              static_cast<unsigned long long>(label_diff), both ? 100.0 * label_diff / both : 0.0,
              static_cast<unsigned long long>(a_int), static_cast<unsigned long long>(b_int),
              static_cast<unsigned long long>(count_diff));
  std::printf("stored leaves that are the same node in both: %llu (vote counts differ in %llu); "
              "their |dp|: max %.3g, mean "
              "%.3g, median %.3g, p99 %.3g, p99.9 %.3g; max relative |d sum_w| %.3g\n",
              static_cast<unsigned long long>(same_nodes),
              static_cast<unsigned long long>(node_count_diff), dp.empty() ? 0.0 : dp.back(), mean,
              q(0.5), q(0.99), q(0.999), max_rel_w);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
