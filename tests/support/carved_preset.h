// Test support: a simulated building carved to tiles in this process (simulate → carve by time
// slices → combine, worker/scan_carver.h), for the tests of the merge stages that need a real
// octree with ground truth. Link: carvemap_sim carvemap_worker (which brings the coordinator).
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "services/sim/simulator.h"
#include "worker/scan_carver.h"

namespace carvemap::testing {

struct CarvedPresetOptions {
  std::string preset = "room";
  uint64_t seed = 1;
  double walk_s = 30;          // 0 = the whole walk
  double rate_hz = 10;         // scanner rate
  double beam_step_deg = 1.0;  // beam spacing
  bool drift = false;          // localization drift (§2.2) on /path; range noise + jitter stay on
  double resolution_m = 0.0625;
  int threads = 2;
};

struct CarvedPreset {
  std::string scan_path;   // <root>/sim/scan.h5
  std::string gt_dir;      // <root>/sim/gt (building.json, surfaces.ply, objects.ply)
  std::string tiles_dir;   // <root>/tiles
  OctreeGrid grid;
  SimulationSummary simulation;
  std::vector<std::string> tile_paths;
};

// Simulates into `root`/sim, carves into `root`/tiles (the partial sums are removed afterwards).
inline absl::StatusOr<CarvedPreset> CarvePreset(const CarvedPresetOptions& options,
                                                const std::string& root) {
  namespace fs = std::filesystem;
  CarvedPreset out;
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(options.resolution_m);
  if (!grid.ok()) return grid.status();
  out.grid = *grid;
  fs::remove_all(root);
  SimulateOptions sim;
  sim.preset = options.preset;
  sim.seed = options.seed;
  sim.rig.rate_hz = options.rate_hz;
  sim.rig.beam_step_deg = options.beam_step_deg;
  sim.noise.drift = options.drift;
  sim.threads = options.threads;
  sim.max_duration_s = options.walk_s;
  sim.output_dir = root + "/sim";
  absl::StatusOr<SimulationSummary> summary = Simulate(sim);
  if (!summary.ok()) return summary.status();
  out.simulation = *summary;
  out.scan_path = summary->scan_path;
  out.gt_dir = summary->gt_dir;

  ScanCarveOptions carve;
  carve.grid = out.grid;
  carve.job_id = "carved_preset";
  carve.partials_dir = root + "/partials";
  carve.tiles_dir = out.tiles_dir = root + "/tiles";
  carve.threads = options.threads;
  absl::StatusOr<ScanCarveTotals> carved = CarveScan(out.scan_path, carve);
  if (!carved.ok()) return carved.status();
  out.tile_paths = std::move(carved->tile_paths);
  return out;
}

// MergeOptions::recarve done in this process, as the coordinator's workers would: the scan's
// slices carved again at the finer grid, only in the chunks' regions, into `tiles_dir`
// (replaced).
inline auto InProcessRecarve(std::string scan_path, std::string tiles_dir, int threads) {
  return [=](const std::vector<RecarveChunk>& chunks,
             double resolution_m) -> absl::StatusOr<std::string> {
    absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
    if (!grid.ok()) return grid.status();
    std::filesystem::remove_all(tiles_dir);
    RecarveRegionMap regions;
    for (const RecarveChunk& c : chunks) regions.emplace(c.chunk, c);
    ScanCarveOptions carve;
    carve.grid = *grid;
    carve.job_id = "carved_preset";
    carve.partials_dir = tiles_dir + ".partials";
    carve.tiles_dir = tiles_dir;
    carve.threads = threads;
    carve.regions = &regions;
    absl::StatusOr<ScanCarveTotals> carved = CarveScan(scan_path, carve);
    if (!carved.ok()) return carved.status();
    return tiles_dir;
  };
}

}  // namespace carvemap::testing
