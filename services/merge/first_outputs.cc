#include "services/merge/first_outputs.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "geometry/octree_keys.h"
#include "services/merge/octomap_writer.h"
#include "services/merge/tile_set.h"
#include "services/merge/topdown_map.h"
#include "services/report/job_report.h"
#include "storage/atomic_file.h"
#include "storage/tile_store.h"

#ifndef CARVEMAP_VERSION
#define CARVEMAP_VERSION "unknown"
#endif

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}


// Sets job[a][b] = value, keeping whatever else the caller put under job[a].
void Put(nlohmann::json& job, const char* a, const char* b, nlohmann::json value) {
  if (!job.contains(a) || !job[a].is_object()) job[a] = nlohmann::json::object();
  job[a][b] = std::move(value);
}

}  // namespace

absl::Status ReportMergeProgress(const MergeProgressCallback& progress, const char* stage,
                                 uint64_t done, uint64_t total) {
  if (progress && !progress(MergeProgress{stage, done, total})) {
    return absl::CancelledError(absl::StrCat("merge cancelled during ", stage));
  }
  return absl::OkStatus();
}

absl::Status FirstOutputsOptions::Validate() const {
  if (tiles_dir.empty()) return absl::InvalidArgumentError("merge: tiles_dir is empty");
  if (output_dir.empty()) return absl::InvalidArgumentError("merge: output_dir is empty");
  if (resolution_m != 0) {
    absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
    if (!grid.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("merge: ", grid.status().message()));
    }
  }
  if (!job.is_object() && !job.is_null()) {
    return absl::InvalidArgumentError("merge: job must be a JSON object");
  }
  if (!(topdown_max_height_m > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("merge: topdown_max_height_m must be > 0, got ", topdown_max_height_m));
  }
  if (!level_floors_z.empty() && level_floors_z.size() != levels.size()) {
    return absl::InvalidArgumentError(absl::StrCat("merge: ", level_floors_z.size(),
                                                   " level floors for ", levels.size(), " levels"));
  }
  if (!(occupancy_band_low_m < occupancy_band_high_m) || !std::isfinite(occupancy_band_low_m) ||
      !std::isfinite(occupancy_band_high_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat("merge: the occupancy band [", occupancy_band_low_m, ", ",
                     occupancy_band_high_m, ") m above the floor is empty"));
  }
  return absl::OkStatus();
}

absl::StatusOr<MergeSummary> MergeFirstOutputs(const FirstOutputsOptions& options,
                                               const MergeProgressCallback& progress) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const Clock::time_point t_start = Clock::now();
  MergeSummary summary;
  nlohmann::json timings = nlohmann::json::object();

  // index
  Clock::time_point t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "index", 0, 1); !s.ok()) return s;
  absl::StatusOr<std::unique_ptr<TileSet>> opened =
      TileSet::Open(options.tiles_dir, options.resolution_m, options.cache_budget_bytes);
  if (!opened.ok()) return opened.status();
  TileSet& tiles = **opened;
  summary.chunk_depth = tiles.grid().chunk_depth;
  summary.resolution_m = tiles.grid().resolution_m();
  const uint64_t num_tiles = tiles.chunks().size();
  std::error_code ec;
  const fs::path out(options.output_dir);
  const std::vector<TopdownZRange> level_ranges =
      options.levels.empty() ? std::vector<TopdownZRange>{TopdownZRange{}} : options.levels;
  for (size_t k = 0; k < level_ranges.size(); ++k) {
    const fs::path dir = out / absl::StrCat("level_", k);
    fs::create_directories(dir, ec);
    if (ec) {
      return absl::UnavailableError(absl::StrCat(dir.string(), ": cannot create: ", ec.message()));
    }
  }
  timings["merge.index"] = SecondsSince(t0);

  // octree.bt and octree.ot, with the per-tile counts and the topdown sums gathered on the
  // same single read of each tile.
  t0 = Clock::now();
  std::vector<TopdownMap> topdowns;
  for (const TopdownZRange& range : level_ranges) topdowns.emplace_back(tiles.grid(), tiles.chunks(), range);
  std::vector<TopdownMap> occupancy;  // per level, over its band above the floor
  for (double floor_z : options.level_floors_z) {
    occupancy.emplace_back(tiles.grid(), tiles.chunks(),
                           TopdownZRange{floor_z + options.occupancy_band_low_m,
                                         floor_z + options.occupancy_band_high_m},
                           /*occupancy=*/true);
  }
  uint64_t visited = 0;
  auto visit = [&](const TileData& tile) -> absl::Status {
    if (absl::Status s = ReportMergeProgress(progress, "octree_bt", visited, num_tiles); !s.ok()) return s;
    ++visited;
    for (const TileLeaf& leaf : tile.leaves) {
      ++summary.num_leaves;
      if (!leaf.stats.observed()) continue;
      ++summary.num_observed_leaves;
      const double side = kChunkSizeM / (1 << leaf.node.depth);
      const double volume = side * side * side;
      summary.observed_volume_m3 += volume;
      if (leaf.stats.interior()) {
        summary.interior_volume_m3 += volume;
      } else {
        summary.exterior_observed_volume_m3 += volume;
      }
    }
    for (TopdownMap& topdown : topdowns) {
      if (absl::Status s = topdown.AddTile(tile); !s.ok()) return s;
    }
    for (TopdownMap& band : occupancy) {
      if (absl::Status s = band.AddTile(tile); !s.ok()) return s;
    }
    return absl::OkStatus();
  };
  summary.octree_bt_path = (out / "octree.bt").string();
  summary.octree_ot_path = (out / "octree.ot").string();
  absl::StatusOr<OctomapFilesStats> octrees =
      WriteOctomapFiles(tiles, summary.octree_bt_path, summary.octree_ot_path, visit);
  if (!octrees.ok()) return octrees.status();
  summary.num_tiles = octrees->num_tiles;
  summary.num_bt_nodes = octrees->bt.num_nodes;
  summary.num_ot_nodes = octrees->ot.num_nodes;
  timings["merge.octree_bt"] = SecondsSince(t0);
  if (absl::Status s = ReportMergeProgress(progress, "octree_bt", num_tiles, num_tiles); !s.ok()) return s;

  // level_<k>/topdown.png (§5.4), one per level
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "topdown_png", 0, topdowns.size()); !s.ok()) return s;
  std::vector<std::string> topdown_outputs;
  for (size_t k = 0; k < topdowns.size(); ++k) {
    const std::string level = absl::StrCat("level_", k);
    const std::string png = (out / level / "topdown.png").string();
    const std::string json = (out / level / "topdown.json").string();
    if (absl::Status s = topdowns[k].Write(png, json, options.topdown_max_height_m, int(k));
        !s.ok()) {
      return s;
    }
    topdown_outputs.push_back(level + "/topdown.json");
    if (topdowns[k].geometry().width > 0 && topdowns[k].geometry().height > 0) {
      topdown_outputs.push_back(level + "/topdown.png");
    }
    if (k < occupancy.size() && occupancy[k].geometry().width > 0 &&
        occupancy[k].geometry().height > 0) {
      const TopdownZRange& band = occupancy[k].z_range();
      const std::string about = absl::StrCat(
          "carvemap ", level, ": a 2D occupancy grid for ROS map_server, from the octree's\n",
          "observed leaves in [", band.z_lo_m, ", ", band.z_hi_m, ") m (the level's floor + [",
          options.occupancy_band_low_m, ", ", options.occupancy_band_high_m, ") m).\n",
          "0 = occupied (solid space in the band), 254 = free, 205 = unknown.");
      if (absl::Status s = occupancy[k].WriteRosMap((out / level / "occupancy.pgm").string(),
                                                    (out / level / "occupancy.yaml").string(),
                                                    OccupancyThresholds{}, about);
          !s.ok()) {
        return s;
      }
      topdown_outputs.push_back(level + "/occupancy.pgm");
      topdown_outputs.push_back(level + "/occupancy.yaml");
    }
    if (k == 0) {
      summary.topdown_png_path = png;
      summary.topdown_json_path = json;
    }
  }
  const TopdownGeometry& geo = topdowns[0].geometry();
  summary.topdown_origin_x_m = geo.origin_x_m;
  summary.topdown_origin_y_m = geo.origin_y_m;
  summary.topdown_width = geo.width;
  summary.topdown_height = geo.height;
  for (const TopdownMap& topdown : topdowns) {
    summary.max_open_height_m = std::max<double>(summary.max_open_height_m, topdown.max_open_height_m());
  }
  timings["merge.topdown_png"] = SecondsSince(t0);

  // job.json
  if (absl::Status s = ReportMergeProgress(progress, "job_json", 0, 1); !s.ok()) return s;
  nlohmann::json job = options.job.is_null() ? nlohmann::json::object() : options.job;
  Put(job, "versions", "carvemap", CARVEMAP_VERSION);
  Put(job, "versions", "tile_format", absl::StrCat(kTileFormat, "/", kTileVersion));
  Put(job, "versions", "octree_bt", "OctoMap OcTree binary (id OcTree)");
  Put(job, "versions", "octree_ot", "OctoMap OcTree file (id OcTree, float log-odds)");
  Put(job, "versions", "topdown", "carvemap-topdown/1");
  Put(job, "parameters", "merge",
      {{"tiles_dir", options.tiles_dir},
       {"resolution_m", summary.resolution_m},
       {"chunk_depth", summary.chunk_depth},
       {"cache_budget_bytes", options.cache_budget_bytes},
       {"topdown_max_height_m", options.topdown_max_height_m},
       {"bt_occupancy",
        "free = observed with p > 0.5 (interior), occupied = observed with "
        "p <= 0.5, unknown = unobserved"},
       {"ot_log_odds", absl::StrCat("log(q / (1 - q)), q = 1 - p clamped to [", kOtMinProbability,
                                    ", 1 - ", kOtMinProbability, "]; unobserved: no node")},
       {"occupancy_band_m", {options.occupancy_band_low_m, options.occupancy_band_high_m}},
       {"topdown_levels", options.levels.empty()
                              ? "level_0 covers the whole height (no levels found)"
                              : "level_<k> covers levels.json's [split_z_low, split_z_high)"}});
  const uint64_t total_leaves = summary.num_leaves;
  Put(job, "counts", "tiles", summary.num_tiles);
  Put(job, "counts", "leaves", total_leaves);
  Put(job, "counts", "observed_leaves", summary.num_observed_leaves);
  Put(job, "counts", "octree_bt_nodes", summary.num_bt_nodes);
  Put(job, "counts", "octree_ot_nodes", summary.num_ot_nodes);
  Put(job, "counts", "interior_volume_m3", summary.interior_volume_m3);
  Put(job, "counts", "exterior_observed_volume_m3", summary.exterior_observed_volume_m3);
  Put(job, "counts", "observed_volume_m3", summary.observed_volume_m3);
  Put(job, "counts", "topdown_max_open_height_m", summary.max_open_height_m);
  summary.seconds_total = SecondsSince(t_start);
  timings["merge.first_outputs"] = summary.seconds_total;
  timings["merge.total"] = options.seconds_before + summary.seconds_total;
  // The caller wrote its stage table before the merge ran; the merge's entry is filled here.
  if (job.contains("stage_seconds") && job["stage_seconds"].is_object() &&
      job["stage_seconds"].contains("merge")) {
    job["stage_seconds"]["merge"] = options.seconds_before + summary.seconds_total;
  }
  for (auto& [key, value] : timings.items()) Put(job, "timings_s", key.c_str(), value);

  nlohmann::json outputs = job.contains("outputs") && job["outputs"].is_array()
                               ? job["outputs"]
                               : nlohmann::json::array();
  std::vector<std::string> mine = {"octree.bt", "octree.ot", "job.json"};
  mine.insert(mine.end(), topdown_outputs.begin(), topdown_outputs.end());
  for (const std::string& name : mine) {
    if (std::find(outputs.begin(), outputs.end(), name) == outputs.end()) outputs.push_back(name);
  }
  job["outputs"] = outputs;

  // index.html, the report in the browser, from the job document as it will be written; a job
  // whose report cannot be made (the viewers' libraries missing) says why in its warnings.
  if (absl::Status s = WriteJobReport(out.string(), job); s.ok()) {
    job["outputs"].push_back("index.html");
  } else {
    job["warnings"].push_back(std::string(s.message()));
  }

  summary.job_json_path = (out / "job.json").string();
  if (absl::Status s = WriteFileAtomically(
          summary.job_json_path, [&](std::ostream& o) { o << job.dump(2) << "\n"; });
      !s.ok()) {
    return s;
  }
  summary.job = std::move(job);
  return summary;
}

}  // namespace carvemap
