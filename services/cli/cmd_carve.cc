// `carvemap carve`: the whole carving pipeline in this process (DESIGN §5): ingest the scan
// into per-chunk spill files, carve every chunk on N threads, one tile per chunk. This local
// mode is also the baseline the distributed coordinator/worker run is compared against.
//
// Output: OUT/tiles/c_<x>_<y>_<z>.h5. Tiles are carved into OUT/tiles.incomplete/ and that
// directory is renamed to OUT/tiles/ only when every chunk succeeded, so OUT/tiles/ is always a
// complete result of this run; on failure the incomplete directory is removed (and an older
// run's OUT/tiles/ was removed at the start). (Each tile is itself written
// atomically, so no file is ever half-written either way.)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "coordinator/scan_ingest.h"
#include "services/cli/commands.h"
#include "services/cli/progress.h"
#include "services/geometry/octree_keys.h"
#include "worker/spilled_chunk_carver.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct CarveFlags {
  std::string scan_path;
  std::string output_dir;
  double resolution_m = 0.0625;
  int threads = 1;
  size_t memory_mb = 256;
  std::string evaluation = "fast";  // eq 4.7: worker/chunk_octree.h
  bool keep_spill = false;
  bool quiet = false;
};

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Carves every chunk with a progress line; tile names and bytes do not depend on the order or
// the thread count.
absl::StatusOr<SpilledChunkCarveTotals> CarveAll(const std::vector<SpilledChunk>& chunks,
                                                 const OctreeGrid& grid, const std::string& job_id,
                                                 const std::string& tiles_dir, int threads,
                                                 CarveEvaluation evaluation, uint64_t total_rays,
                                                 ProgressLine& line) {
  const Clock::time_point t0 = Clock::now();
  SpilledChunkCarveOptions options;
  options.grid = grid;
  options.job_id = job_id;
  options.tiles_dir = tiles_dir;
  options.threads = threads;
  options.evaluation = evaluation;
  absl::StatusOr<SpilledChunkCarveTotals> totals =
      CarveSpilledChunks(chunks, options, [&](const SpilledChunkCarveProgress& p) {
        // Rays carved so far, estimated from the wedge-chunk pairs done.
        const double frac = p.pairs_total ? double(p.pairs_done) / p.pairs_total : 1.0;
        const double el = SecondsSince(t0);
        const double rays_per_s = el > 0 ? frac * total_rays / el : 0.0;
        const double eta = frac > 0 ? el * (1 - frac) / frac : 0.0;
        line.Update("carve: %zu/%zu chunks, %.0f rays/s, ETA %.0f s", p.chunks_done,
                    p.chunks_total, rays_per_s, eta);
      });
  line.Finish();
  return totals;
}

absl::Status RunCarve(const CarveFlags& flags) {
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(flags.resolution_m);
  if (!grid.ok()) return grid.status();
  if (flags.threads < 1) return absl::InvalidArgumentError("--threads must be >= 1");

  const fs::path out(flags.output_dir);
  const fs::path spill_dir = out / "spill";
  const fs::path tiles_dir = out / "tiles";
  const fs::path partial_dir = out / "tiles.incomplete";
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) return absl::UnavailableError(absl::StrCat("cannot create ", out.string(), ": ", ec.message()));
  // A previous run's chunks would otherwise mix with this run's (the spill appends per chunk,
  // and an old tile of a chunk this scan does not touch would survive).
  fs::remove_all(spill_dir, ec);
  fs::remove_all(partial_dir, ec);
  // An older run's tiles must not pass for this run's if this one fails.
  fs::remove_all(tiles_dir, ec);

  ProgressLine line(!flags.quiet);
  IngestOptions io;
  io.scan_path = flags.scan_path;
  io.spill_dir = spill_dir.string();
  io.memory_budget_bytes = flags.memory_mb << 20;
  absl::StatusOr<IngestResult> ingest = IngestScan(io, [&line](const IngestProgress& p) {
    line.Update("ingest: %llu/%llu frames, %.0f rays/s",
                static_cast<unsigned long long>(p.frames_done),
                static_cast<unsigned long long>(p.frames_total),
                p.elapsed_s > 0 ? p.rays / p.elapsed_s : 0.0);
  });
  line.Finish();
  if (!ingest.ok()) {
    fs::remove_all(spill_dir, ec);
    return ingest.status();
  }
  uint64_t spill_bytes = 0;
  for (const SpilledChunk& c : ingest->chunks) spill_bytes += c.file_bytes;
  const double ingest_s = SecondsSince(t0);

  const Clock::time_point t1 = Clock::now();
  const std::string job_id = fs::path(flags.scan_path).stem().string();
  const CarveEvaluation evaluation =
      flags.evaluation == "exact" ? CarveEvaluation::kExact : CarveEvaluation::kFast;
  absl::StatusOr<SpilledChunkCarveTotals> carved =
      CarveAll(ingest->chunks, *grid, job_id, partial_dir.string(), flags.threads, evaluation,
               ingest->rays, line);
  if (!carved.ok()) {
    fs::remove_all(partial_dir, ec);
    return absl::Status(carved.status().code(),
                        absl::StrCat(carved.status().message(), " (no tiles kept: ",
                                     partial_dir.string(), " removed)"));
  }
  // The swap: OUT/tiles/ only ever holds a complete run.
  fs::create_directories(partial_dir, ec);  // a scan without chunks still gives a tiles/ dir
  fs::remove_all(tiles_dir, ec);
  fs::rename(partial_dir, tiles_dir, ec);
  if (ec) {
    return absl::UnavailableError(absl::StrCat("cannot rename ", partial_dir.string(), " to ",
                                               tiles_dir.string(), ": ", ec.message()));
  }
  const double carve_s = SecondsSince(t1);
  if (!flags.keep_spill) fs::remove_all(spill_dir, ec);
  const double total_s = SecondsSince(t0);

  const IngestResult& r = *ingest;
  const SpilledChunkCarveTotals& t = *carved;
  auto ull = [](uint64_t v) { return static_cast<unsigned long long>(v); };
  std::printf("scan %s: %llu frames, %llu rays, %llu returns%s\n", flags.scan_path.c_str(),
              ull(r.frames), ull(r.rays), ull(r.returns),
              r.default_covariance ? " (no /path_cov: default covariances)" : "");
  std::printf("wedges: %llu (%llu single-ray), %llu chunks, %llu wedge-chunk pairs, "
              "spill %.1f MB (%.1f B/ray)\n",
              ull(r.wedges), ull(r.single_ray_wedges), ull(r.chunks.size()),
              ull(r.wedge_chunk_pairs), spill_bytes * 1e-6,
              r.rays ? double(spill_bytes) / r.rays : 0.0);
  std::printf("tiles: %llu in %s, %llu leaves, %.1f MB (%.1f B/ray), %llu leaf updates\n",
              ull(t.tile_paths.size()), tiles_dir.string().c_str(), ull(t.leaves), t.tile_bytes * 1e-6,
              r.rays ? double(t.tile_bytes) / r.rays : 0.0, ull(t.leaf_updates));
  std::printf("resolution %.4f m, %d thread%s\n", grid->resolution_m(), flags.threads,
              flags.threads == 1 ? "" : "s");
  std::printf("stages: ingest %.2f s (%.0f rays/s), carve %.2f s (%.0f rays/s), "
              "total %.2f s (%.0f rays/s)\n",
              ingest_s, ingest_s > 0 ? r.rays / ingest_s : 0.0, carve_s,
              carve_s > 0 ? r.rays / carve_s : 0.0, total_s, total_s > 0 ? r.rays / total_s : 0.0);
  return absl::OkStatus();
}

void RegisterCarve(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "carve",
      "Carve a scan into a probabilistic octree in this process (DESIGN §5): OUT/tiles/ gets "
      "one HDF5 tile per 2 m chunk");
  auto flags = std::make_shared<CarveFlags>();
  cmd->add_option("scan", flags->scan_path, "scan.h5 (DESIGN §3)")->required();
  cmd->add_option("-o,--output", flags->output_dir, "Output directory (created if missing)")
      ->required();
  cmd->add_option("--resolution", flags->resolution_m,
                  "Leaf size, metres: 2 m / 2^k (0.125, 0.0625, 0.03125, 0.015625, ...)")
      ->capture_default_str();
  flags->threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  cmd->add_option("--threads", flags->threads,
                  "Carving threads (tiles are byte-identical for any count)")
      ->capture_default_str();
  cmd->add_option("--memory-mb", flags->memory_mb, "Spill buffer budget of the ingest, MB")
      ->capture_default_str();
  cmd->add_option("--evaluation", flags->evaluation,
                  "How the workers evaluate eq 4.7: fast (single precision, the default) or exact (double "
                  "precision, the reference; the same votes, within the tolerance in "
                  "worker/chunk_octree.h)")
      ->check(CLI::IsMember({"fast", "exact"}))
      ->capture_default_str();
  cmd->add_flag("--keep-spill", flags->keep_spill, "Keep OUT/spill/ (per-chunk wedge files)");
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress on stderr");
  cmd->callback([flags, &exit_code] { exit_code = ReportStatus("carve", RunCarve(*flags)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(40, RegisterCarve);

}  // namespace carvemap
