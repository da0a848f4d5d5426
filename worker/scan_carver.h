// A whole scan carved into tiles in this process (docs/DESIGN.md §5), as the coordinator and its
// workers do it across processes: the scan cut into time slices (coordinator/scan_slices.h), each
// slice carved into partial sums (worker/slice_carver.h) by a pool of threads, then every chunk's
// sums added up in slice order and simplified into its tile (worker/chunk_combiner.h) by the
// same pool. What `carvemap carve`, the tests and the benchmarks run; the distributed run's
// baseline. Tiles are the same bytes whatever the thread count.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/statusor.h"
#include "coordinator/scan_slices.h"
#include "coordinator/wedge_builder.h"
#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "worker/chunk_octree.h"

namespace carvemap {

struct ScanCarveOptions {
  OctreeGrid grid;
  std::string job_id;        // recorded in every tile
  std::string partials_dir;  // the slices' partial sums (created; removed at the end unless kept)
  std::string tiles_dir;     // created
  int threads = 1;
  CarveEvaluation evaluation = CarveEvaluation::kFast;
  SlicePlanOptions slices;
  WedgeBuilderOptions wedges;
  // §5.6.1's second pass: only these chunks, each only inside its region (null: all, whole).
  const RecarveRegionMap* regions = nullptr;
  size_t memory_budget_bytes = 256u << 20;  // per slice being carved
  bool keep_partials = false;
  // §2.3's turn to north, applied to every pose read (ScanReader::OpenOptions).
  double world_yaw_rad = 0;
};

struct ScanCarveProgress {
  std::string stage;  // "slices", then "combine"
  uint64_t done = 0, total = 0;  // slices, or chunks
  uint64_t rays_done = 0, rays_total = 0;  // of the slices' own rays
};

struct ScanCarveTotals {
  uint64_t slices = 0;
  double slice_s = 0;
  uint64_t frames = 0, rays = 0, returns = 0, wedges = 0, wedge_chunk_pairs = 0, leaf_updates = 0;
  uint64_t partial_bytes = 0;
  bool default_covariance = false;
  Eigen::AlignedBox3d bounds;
  std::vector<ChunkKey> chunks;          // ChunkKeyLess order
  std::vector<std::string> tile_paths;   // the same order
  uint64_t tile_bytes = 0, leaves = 0;
  double slices_elapsed_s = 0, combine_elapsed_s = 0;
};

// Validates the scan (ScanReader::Validate: a bad row is named before anything is carved),
// plans, carves, combines. `progress` is called from this thread about every 250 ms and at each
// stage's end. On error nothing under tiles_dir is complete-looking beyond the tiles already
// written (each atomic); callers discard the directory.
absl::StatusOr<ScanCarveTotals> CarveScan(
    const std::string& scan_path, const ScanCarveOptions& options,
    const std::function<void(const ScanCarveProgress&)>& progress = {});

}  // namespace carvemap
