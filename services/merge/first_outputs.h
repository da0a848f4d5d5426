// The first merge outputs of a job (docs/DESIGN.md §6, §7): from the carved tiles, out of core,
//   <output_dir>/octree.bt              OctoMap binary tree (occupancy from p) — opens in octovis
//   <output_dir>/level_0/topdown.png    open-height map (§5.4); level_0 covers the whole
//                                       height until levels (§5.2, docs/DESIGN.md §6.3) exist
//   <output_dir>/level_0/topdown.json   its georeference (origin, resolution) and gray scale
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
#include "services/geometry/chunk_region.h"
#include "services/merge/topdown_map.h"

namespace carvemap {

struct MergeOptions {
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
  // RunMerge only: threads for the per-chunk stages (boundary faces, dense meshes); ≤ 0: the
  // CPUs the process may use (UsableCpus: affinity and cgroup quota). The outputs do not
  // depend on it.
  int threads = 0;
  // RunMerge only: the most memory the merge process may hold, bytes; 0 = no bound. The planar
  // regions and the planar mesh are made for the whole building at once (every level
  // together), and their memory grows with its boundary faces: before each, RunMerge
  // estimates it (kPlanarBytesPerFace) and fails with ResourceExhausted, naming the faces per
  // level, the estimate and this budget, rather than be killed for memory later.
  uint64_t memory_budget_bytes = 0;
  // Gray scale of topdown.png: 0 = no open height, 255 = ≥ this many metres (linear).
  double topdown_max_height_m = 3.0;
  // The elevations of each level (§5.2, services/levels): level_<k>/topdown.png integrates
  // levels[k]. Empty: one level_0 over the whole height.
  std::vector<TopdownZRange> levels;
  // RunMerge only (services/merge/merge_job.h): false skips the meshing stages (faces, regions,
  // levels, dense and planar meshes), leaving the first outputs.
  bool meshes = true;
  // RunMerge only: the job's scan.h5 (docs/DESIGN.md §3), whose /path (poses, small) gives the
  // floor plans their scanner positions (§3.3.1 lines of sight, §3.3.2 unentered rooms). Empty: no
  // floor plans (job.json says why under "warnings").
  std::string scan_path;
  // RunMerge only: the §2.3 turn to north the tiles were carved with
  // (ScanReader::OpenOptions::world_yaw_rad): the scan's path and points are read turned by
  // it, so that they lie where the tiles do.
  double world_yaw_rad = 0;
  // RunMerge only, §5.5 on request: OUT/points.ply, the scan's returns in the world frame
  // without those the floor plans trim (services/merge/trimmed_points.h). Needs scan_path
  // and floor plans: without either, job.json warns and there is no file (the other outputs
  // do not depend on it, so the job goes on).
  bool trimmed_points = false;
  // RunMerge only: objects with less volume than this are specks, dropped (§5.6;
  // ObjectSplitOptions::min_volume_m3), m³. ≤ 0: that default (5 litres). Pieces under its
  // speck_volume_m3 (1 litre) go whatever this says.
  double min_object_volume_m3 = 0;
  // RunMerge only: the floor-plan method, "rooms" (§3.3) or "eigencrust" (§3.2); another name
  // is InvalidArgument before any work.
  std::string floorplan_method = "rooms";
  // RunMerge only, §5.6.1 (Fig 5.17): the chunks that hold objects are carved again at this
  // finer resolution (2 m / 2^k, below resolution_m), so that the furniture's boards, legs and
  // rods, thinner than a cell, survive; the objects are then segmented and meshed from those
  // tiles. Carving needs the job's wedges, which the merge does not have: `recarve` does it
  // (the coordinator leases the chunks to its workers; tests carve in process). 0 or no
  // `recarve`: the objects come from the job's tiles.
  double object_resolution_m = 0;
  // Carves each of `chunks`, inside its region only, at `resolution_m` into one tile each and
  // returns the directory that holds them (storage/TILE_FORMAT.md names). Errors fail the merge.
  std::function<absl::StatusOr<std::string>(const std::vector<RecarveChunk>& chunks,
                                            double resolution_m)>
      recarve;

  // InvalidArgument for empty dirs, a resolution that is not 2 m / 2^k, a non-object job or a
  // non-positive topdown_max_height_m.
  [[nodiscard]] absl::Status Validate() const;
};

// Progress of a running merge: `stage` is "index", "octree_bt", "topdown_png" or "job_json";
// `done`/`total` count tiles (or 0/1 for single-step stages).
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
  std::string topdown_png_path;
  std::string topdown_json_path;
  std::string job_json_path;

  int chunk_depth = 0;
  double resolution_m = 0;
  uint64_t num_tiles = 0;
  uint64_t num_leaves = 0;           // rows over all tiles
  uint64_t num_observed_leaves = 0;  // count > 0
  uint64_t num_bt_nodes = 0;         // nodes of octree.bt (its "size" line)
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
// counts and the topdown sums share that read). Memory: the tile cache plus the topdown image
// (5 bytes per pixel at the octree resolution over the chunks' xy bounding box).
// Errors name the file: NotFound for a missing tiles dir; DataLoss for a corrupt tile or one
// whose content disagrees with its name; InvalidArgument for bad options or tiles of mixed or
// unexpected resolution; OutOfRange for chunks beyond OctoMap's 16-level key space; Cancelled
// when `progress` returns false; Unavailable for I/O errors on the outputs.
// Not thread-safe with other HDF5 use in the process (storage/tile_store.h).
absl::StatusOr<MergeSummary> MergeFirstOutputs(const MergeOptions& options,
                                               const MergeProgressCallback& progress = nullptr);

}  // namespace carvemap
