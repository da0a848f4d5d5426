// The first merge outputs of a job (docs/DESIGN.md §6, §7): from the carved tiles, out of core,
//   <output_dir>/octree.bt              OctoMap binary tree (occupancy from p) — opens in octovis
//   <output_dir>/octree.ot              OctoMap tree with each node's log-odds (from p)
//   <output_dir>/level_0/topdown.png    open-height map (§5.4); level_0 covers the whole
//                                       height until levels (§5.2, docs/DESIGN.md §6.3) exist
//   <output_dir>/level_0/topdown.json   its georeference (origin, resolution) and gray scale
//   <output_dir>/level_<k>/occupancy.pgm + .yaml   with levels: a 2D occupancy grid per level
//                                       for ROS map_server (TopdownMap::WriteRosMap)
//   <output_dir>/index.html + report/   the job report in the browser (services/report)
//   <output_dir>/job.json               the caller's job document plus the merge's parameters,
//                                       versions, timings and counts
// Every file is written through "<name>.partial" and a rename, so a failed merge leaves no
// half-written output that looks complete.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/merge/topdown_map.h"

namespace carvemap {

// What the first outputs are made from and where they go. RunMerge (services/merge/merge_job.h)
// fills it from its MergeOptions once the levels are known.
struct FirstOutputsOptions {
  std::string tiles_dir;   // holds c_<x>_<y>_<z>.h5 tiles (storage/TILE_FORMAT.md)
  std::string output_dir;  // created if missing; existing outputs are replaced
  // 2 m / 2^k; 0 = take it from the tiles. When set, every tile must have it (else
  // InvalidArgument naming the tile).
  double resolution_m = 0;
  // The caller's job document (an object, or null): job id, parameters, versions, ingest and
  // carve timings/counts. MergeFirstOutputs adds its own entries (see MergeSummary::job) and
  // writes the result as job.json; keys it does not own are kept as given.
  nlohmann::json job = nlohmann::json::object();
  // Seconds the caller's merge spent before these outputs (RunMerge's stages): job.json's
  // "merge.total" and, when the caller's document has one, "stage_seconds"."merge" count them.
  double seconds_before = 0;
  // Bound on the decoded tiles held in memory at once (TileSet's LRU cache). At least one
  // chunk is always held, whatever the budget.
  uint64_t cache_budget_bytes = uint64_t{256} << 20;
  // Gray scale of topdown.png: 0 = no open height, 255 = ≥ this many metres (linear).
  double topdown_max_height_m = 3.0;
  // The elevations of each level (§5.2, services/levels): level_<k>/topdown.png integrates
  // levels[k]. Empty: one level_0 over the whole height.
  std::vector<TopdownZRange> levels;
  // Each level's floor height, m (one per level, or none): with them, level_<k>/occupancy.pgm
  // and .yaml, the ROS map_server pair, over [floor + occupancy_band_low_m, floor +
  // occupancy_band_high_m) (TopdownMap::ToOccupancy): from just above the floor (its
  // unevenness) to a standing person's height.
  std::vector<double> level_floors_z;
  double occupancy_band_low_m = 0.1;
  double occupancy_band_high_m = 1.8;

  // InvalidArgument for empty dirs, a resolution that is not 2 m / 2^k, a non-object job, a
  // non-positive topdown_max_height_m, floors not one per level or an empty occupancy band.
  [[nodiscard]] absl::Status Validate() const;
};

// Progress of a running merge: `stage` is "index", "octree_bt" (both octrees), "topdown_png" or
// "job_json"; `done`/`total` count tiles (or 0/1 for single-step stages).
struct MergeProgress {
  std::string stage;
  uint64_t done = 0;
  uint64_t total = 0;
};
// Return false to cancel: MergeFirstOutputs then stops at the next tile and returns Cancelled
// (the outputs of the stage that was running are not written).
using MergeProgressCallback = std::function<bool(const MergeProgress&)>;
// Calls `progress` (when set); Cancelled ("merge cancelled during <stage>") when it says stop.
absl::Status ReportMergeProgress(const MergeProgressCallback& progress, const char* stage,
                                 uint64_t done, uint64_t total);

struct MergeSummary {
  // Absolute-or-as-given paths of what was written.
  std::string octree_bt_path;
  std::string octree_ot_path;
  std::string topdown_png_path;
  std::string topdown_json_path;
  std::string job_json_path;

  int chunk_depth = 0;
  double resolution_m = 0;
  uint64_t num_tiles = 0;
  uint64_t num_leaves = 0;           // rows over all tiles
  uint64_t num_observed_leaves = 0;  // count > 0
  uint64_t num_bt_nodes = 0;         // nodes of octree.bt (its "size" line)
  uint64_t num_ot_nodes = 0;         // nodes of octree.ot
  double interior_volume_m3 = 0;           // observed with p > 0.5 (open space)
  double exterior_observed_volume_m3 = 0;  // observed with p ≤ 0.5 (solid)
  double observed_volume_m3 = 0;           // both
  // Topdown map: pixel (row, col) of the H-row image is the column at
  // x = origin_x + (col + 0.5)·res, y = origin_y + (H − 1 − row + 0.5)·res (lower-left origin,
  // as docs/DESIGN.md §4 floor maps).
  double topdown_origin_x_m = 0, topdown_origin_y_m = 0;
  int topdown_width = 0, topdown_height = 0;
  double max_open_height_m = 0;

  // RunMerge's stages (0 when skipped).
  uint64_t num_boundary_faces = 0;
  uint64_t num_planar_regions = 0;
  uint64_t num_levels = 0;
  uint64_t dense_triangles = 0;
  uint64_t building_triangles = 0;
  uint64_t num_rooms = 0;  // over all levels' floor plans
  uint64_t num_objects = 0;  // segmented objects (§5.6)
  std::vector<std::string> warnings;  // stages that could not produce their output, and why

  double seconds_total = 0;
  nlohmann::json job;  // exactly what was written to job.json
};

// Runs the merge's first outputs over `options.tiles_dir`, reading each tile once (octree.bt,
// octree.ot, counts and the topdown sums share that read). Memory: the tile cache plus the topdown
// image (5 bytes per pixel at the octree resolution over the chunks' xy bounding box). Errors name
// the file: NotFound for a missing tiles dir; DataLoss for a corrupt tile or one whose content
// disagrees with its name; InvalidArgument for bad options or tiles of mixed or unexpected
// resolution; OutOfRange for chunks beyond OctoMap's 16-level key space; Cancelled when `progress`
// returns false; Unavailable for I/O errors on the outputs. Not thread-safe with other HDF5 use in
// the process (storage/tile_store.h).
absl::StatusOr<MergeSummary> MergeFirstOutputs(const FirstOutputsOptions& options,
                                               const MergeProgressCallback& progress = nullptr);

}  // namespace carvemap
