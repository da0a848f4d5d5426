// How much a hierarchical evaluation of eq 4.8 could save: one vote per coarse node instead of
// one per finest leaf, where a ray's votes over the node are all there and flat.
//   vote_blocks [walk seconds = 3] [rate Hz = 40] [beam step deg = 0.25] [preset = office2]
//               [sampled rays = 4000]
// 1. simulates the preset (seed 1, noise on, as carve_bench) and builds every wedge
//    (coordinator/wedge_builder.h), binned into chunks (ChunksOfWedge);
// 2. for a sample of rays (fixed seed), carves each ray alone: its wedges (S(L) is the set of
//    rays of the wedges touching L, §4.3.2) in each chunk they touch, only that ray voting
//    (IndexedWedges::votes), with the default evaluation. A finest leaf then holds exactly
//    the ray's own vote (w, p);
// 3. groups each ray's voted leaves into aligned nodes of 2³, 4³ and 8³ leaves and counts, from
//    the coarsest down, the nodes a hierarchical scheme could vote in once: every leaf of the
//    node voted by the ray ("full"), and the ray's w and p flat over it within a tolerance
//    ("flat": |w − mean w| ≤ tol_w·mean w and |p − mean p| ≤ tol_p on every leaf). The votes left
//    (leaves outside such nodes, plus one per node) are the hierarchy's best case: what it must
//    still evaluate with the same S(L).
// Prints votes per ray and what is left for each tolerance, and how the votes' weights spread.
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "coordinator/chunk_binning.h"
#include "coordinator/wedge_builder.h"
#include "services/sim/simulator.h"
#include "storage/scan_reader.h"
#include "worker/chunk_octree.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

int Fail(const absl::Status& s) {
  std::fprintf(stderr, "vote_blocks: %s\n", std::string(s.message()).c_str());
  return 1;
}

struct RayKey {
  uint32_t sensor;
  uint64_t frame;
  uint32_t index;
  bool operator==(const RayKey&) const = default;
  template <typename H>
  friend H AbslHashValue(H h, const RayKey& k) {
    return H::combine(std::move(h), k.sensor, k.frame, k.index);
  }
};

struct Tolerance {
  const char* name;
  double w, p;  // relative on w, absolute on p
};
constexpr Tolerance kTolerances[] = {
    {"full nodes, any values (geometric bound)", 1e300, 1e300},
    {"p within 0.01, w free", 1e300, 0.01},
    {"flat: w within 10 %, p within 0.01", 0.10, 0.01},
    {"flat: w within 1 %, p within 0.001", 0.01, 0.001},
};
constexpr int kLevels = 3;  // nodes of 2³, 4³, 8³ leaves

struct Vote {
  uint64_t code;  // Morton code of the finest leaf in its chunk
  double w, p;
};

// The votes left when every node that is full and flat at `tol` (coarsest first, not inside a
// node taken already) votes once. `votes` sorted by code.
uint64_t VotesLeft(const std::vector<Vote>& votes, const Tolerance& tol,
                   std::array<uint64_t, kLevels + 1>& nodes_taken) {
  std::vector<uint8_t> covered(votes.size(), 0);
  uint64_t left = votes.size();
  for (int level = kLevels; level >= 1; --level) {
    const int shift = 3 * level;
    const size_t per_node = size_t{1} << shift;
    for (size_t i = 0; i < votes.size();) {
      const uint64_t node = votes[i].code >> shift;
      size_t j = i;
      while (j < votes.size() && votes[j].code >> shift == node) ++j;
      bool take = j - i == per_node;
      for (size_t k = i; take && k < j; ++k) take = !covered[k];
      if (take) {
        double mw = 0, mp = 0;
        for (size_t k = i; k < j; ++k) {
          mw += votes[k].w;
          mp += votes[k].p;
        }
        mw /= double(j - i);
        mp /= double(j - i);
        for (size_t k = i; take && k < j; ++k) {
          take = std::abs(votes[k].w - mw) <= tol.w * mw && std::abs(votes[k].p - mp) <= tol.p;
        }
      }
      if (take) {
        for (size_t k = i; k < j; ++k) covered[k] = 1;
        left -= per_node - 1;
        ++nodes_taken[level];
      }
      i = j;
    }
  }
  return left;
}

int Main(int argc, char** argv) {
  const double walk_s = argc > 1 ? std::atof(argv[1]) : 3.0;
  const double rate_hz = argc > 2 ? std::atof(argv[2]) : 40.0;
  const double beam_deg = argc > 3 ? std::atof(argv[3]) : 0.25;
  const std::string preset = argc > 4 ? argv[4] : "office2";
  const int samples = argc > 5 ? std::atoi(argv[5]) : 4000;
  const double resolution_m = 0.0625;
  const std::string root = (fs::temp_directory_path() / "vote_blocks").string();
  fs::remove_all(root);

  SimulateOptions so;
  so.preset = preset;
  so.seed = 1;
  so.rig.rate_hz = rate_hz;
  so.rig.beam_step_deg = beam_deg;
  so.max_duration_s = walk_s;
  so.output_dir = root + "/sim";
  absl::StatusOr<SimulationSummary> sim = Simulate(so);
  if (!sim.ok()) return Fail(sim.status());
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
  if (!grid.ok()) return Fail(grid.status());
  absl::StatusOr<std::unique_ptr<ScanReader>> scan = ScanReader::Open(sim->scan_path);
  if (!scan.ok()) return Fail(scan.status());
  ScanReader& reader = **scan;

  // Every wedge, with its rays' ids and its chunks.
  struct StoredWedge {
    Wedge wedge;
    std::array<RayKey, 4> ids;
    std::vector<ChunkKey> chunks;
  };
  std::vector<StoredWedge> wedges;
  absl::flat_hash_map<RayKey, std::vector<uint32_t>> wedges_of_ray;
  absl::StatusOr<WedgeBuilderStats> built =
      BuildWedges(reader, WedgeBuilderOptions{}, [&](const Wedge& w, std::span<const RayId> ids) {
        StoredWedge s;
        s.wedge = w;
        for (int r = 0; r < w.num_rays; ++r) {
          s.ids[r] = RayKey{ids[r].sensor, ids[r].frame, ids[r].index};
          wedges_of_ray[s.ids[r]].push_back(uint32_t(wedges.size()));
        }
        s.chunks = ChunksOfWedge(w, kWedgeHullSigmas);
        wedges.push_back(std::move(s));
        return absl::OkStatus();
      });
  if (!built.ok()) return Fail(built.status());

  // The sample: rays in a fixed order (the map's order is not), drawn with a fixed seed.
  std::vector<RayKey> rays;
  rays.reserve(wedges_of_ray.size());
  for (const auto& [key, list] : wedges_of_ray) rays.push_back(key);
  std::sort(rays.begin(), rays.end(), [](const RayKey& a, const RayKey& b) {
    return std::tie(a.sensor, a.frame, a.index) < std::tie(b.sensor, b.frame, b.index);
  });
  std::mt19937_64 rng(7);
  std::shuffle(rays.begin(), rays.end(), rng);
  rays.resize(std::min(rays.size(), size_t(std::max(samples, 1))));

  uint64_t total_votes = 0, sampled = 0, chunk_carves = 0;
  std::array<uint64_t, std::size(kTolerances)> left{};
  std::array<std::array<uint64_t, kLevels + 1>, std::size(kTolerances)> nodes{};
  // Weights of the votes: how many would matter beside a ray at w ≈ 1.
  uint64_t below_1e3 = 0, below_1e6 = 0;
  for (const RayKey& key : rays) {
    const std::vector<uint32_t>& list = wedges_of_ray.at(key);
    std::vector<ChunkKey> chunks;
    for (uint32_t w : list) {
      chunks.insert(chunks.end(), wedges[w].chunks.begin(), wedges[w].chunks.end());
    }
    std::sort(chunks.begin(), chunks.end(), ChunkKeyLess());
    chunks.erase(std::unique(chunks.begin(), chunks.end()), chunks.end());
    // The ray's wedges, each ray once; only the sampled one votes.
    IndexedWedges in;
    absl::flat_hash_map<RayKey, uint32_t> index;
    for (uint32_t w : list) {
      const StoredWedge& s = wedges[w];
      WedgeRef ref;
      ref.num_rays = uint8_t(s.wedge.num_rays);
      for (int r = 0; r < s.wedge.num_rays; ++r) {
        auto [it, inserted] = index.try_emplace(s.ids[r], uint32_t(in.rays.size()));
        if (inserted) {
          in.rays.push_back(s.wedge.rays[r]);
          in.votes.push_back(s.ids[r] == key ? 1 : 0);
        }
        ref.ray[r] = it->second;
      }
      in.wedges.push_back(ref);
    }
    ++sampled;
    for (const ChunkKey& c : chunks) {
      ChunkOctree tree(*grid, c);
      if (absl::Status s = tree.CarveIndexed(in); !s.ok()) return Fail(s);
      ++chunk_carves;
      std::vector<Vote> votes;
      for (const TileLeaf& leaf : tree.FinestLeaves()) {
        if (leaf.stats.count == 0) continue;
        votes.push_back({MortonCode(leaf.node.local), leaf.stats.sum_w, leaf.stats.p()});
        below_1e3 += leaf.stats.sum_w < 1e-3;
        below_1e6 += leaf.stats.sum_w < 1e-6;
      }
      std::sort(votes.begin(), votes.end(),
                [](const Vote& a, const Vote& b) { return a.code < b.code; });
      total_votes += votes.size();
      for (size_t t = 0; t < std::size(kTolerances); ++t) {
        left[t] += VotesLeft(votes, kTolerances[t], nodes[t]);
      }
    }
  }

  const double n = double(sampled);
  std::printf(
      "%s seed 1, %.0f s walk, %.1f Hz, %.2f deg beams, %.4f m: %zu wedges, %zu rays "
      "in wedges, %llu sampled (%llu ray-chunk carves)\n",
      preset.c_str(), walk_s, rate_hz, beam_deg, resolution_m, wedges.size(), wedges_of_ray.size(),
      static_cast<unsigned long long>(sampled), static_cast<unsigned long long>(chunk_carves));
  std::printf("votes per ray: %.1f; with w < 1e-3: %.1f %%, w < 1e-6: %.1f %%\n", total_votes / n,
              100.0 * below_1e3 / double(total_votes), 100.0 * below_1e6 / double(total_votes));
  for (size_t t = 0; t < std::size(kTolerances); ++t) {
    std::printf(
        "%s: %.1f votes per ray left (%.1f %% of the votes), nodes taken per ray: "
        "8^3 %.2f, 4^3 %.2f, 2^3 %.2f\n",
        kTolerances[t].name, left[t] / n, 100.0 * left[t] / double(total_votes), nodes[t][3] / n,
        nodes[t][2] / n, nodes[t][1] / n);
  }
  fs::remove_all(root);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
