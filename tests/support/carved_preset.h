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
  // Keep the ingest's spill (<root>/spill) so the chunks can be carved again (§5.6.1).
  bool keep_spill = false;
};

struct CarvedPreset {
  std::string scan_path;   // <root>/sim/scan.h5
  std::string gt_dir;      // <root>/sim/gt (building.json, surfaces.ply, objects.ply)
  std::string tiles_dir;   // <root>/tiles
  std::string spill_dir;   // <root>/spill, when kept
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
  if (options.keep_spill) {
    out.spill_dir = root + "/spill";
  } else {
    fs::remove_all(root + "/spill");
  }
  return out;
}

// MergeOptions::recarve done in this process, as the coordinator's workers would: the chunks
// from the spill in `spill_dir`, carved into `tiles_dir` (replaced).
inline auto InProcessRecarve(std::string spill_dir, std::string tiles_dir, int threads) {
  return [=](const std::vector<RecarveChunk>& chunks,
             double resolution_m) -> absl::StatusOr<std::string> {
    absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
    if (!grid.ok()) return grid.status();
    std::vector<ChunkKey> keys;
    for (const RecarveChunk& c : chunks) keys.push_back(c.chunk);
    absl::StatusOr<std::vector<SpilledChunk>> spilled = FindSpilledChunks(spill_dir, keys);
    if (!spilled.ok()) return spilled.status();
    std::filesystem::remove_all(tiles_dir);
    std::filesystem::create_directories(tiles_dir);
    SpilledChunkCarveOptions carve;
    carve.grid = *grid;
    carve.job_id = "carved_preset";
    carve.tiles_dir = tiles_dir;
    carve.threads = threads;
    for (const RecarveChunk& c : chunks) carve.regions.emplace(c.chunk, c.region);
    absl::StatusOr<SpilledChunkCarveTotals> carved = CarveSpilledChunks(*spilled, carve);
    if (!carved.ok()) return carved.status();
    return tiles_dir;
  };
}

}  // namespace carvemap::testing
