// Test support: a simulated building carved to tiles in this process (simulate → ingest →
// carve every chunk), for the tests of the merge stages that need a real octree with ground
// truth. Link: carvemap_sim carvemap_worker (which brings the coordinator).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "coordinator/scan_ingest.h"
#include "services/geometry/octree_keys.h"
#include "services/sim/simulator.h"
#include "worker/spilled_chunk_carver.h"

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

// Simulates into `root`/sim, carves into `root`/tiles (the spill is removed afterwards).
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

  IngestOptions ingest;
  ingest.scan_path = out.scan_path;
  ingest.spill_dir = root + "/spill";
  absl::StatusOr<IngestResult> spilled = IngestScan(ingest);
  if (!spilled.ok()) return spilled.status();

  SpilledChunkCarveOptions carve;
  carve.grid = out.grid;
  carve.job_id = "carved_preset";
  carve.tiles_dir = out.tiles_dir = root + "/tiles";
  carve.threads = options.threads;
  fs::create_directories(carve.tiles_dir);
  absl::StatusOr<SpilledChunkCarveTotals> carved = CarveSpilledChunks(spilled->chunks, carve);
  if (!carved.ok()) return carved.status();
  out.tile_paths = std::move(carved->tile_paths);
  fs::remove_all(root + "/spill");
  return out;
}

}  // namespace carvemap::testing
