// `carvemap carve`: the whole carving pipeline in this process (docs/DESIGN.md §5): the scan cut
// into time slices, each carved into partial sums per chunk by a pool of threads, then every
// chunk's sums combined into its tile (worker/scan_carver.h). The baseline the distributed
// coordinator/worker run is compared against.
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
#include <numbers>
#include <string>
#include <system_error>
#include <vector>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "coordinator/scan_north.h"
#include "geometry/octree_keys.h"
#include "services/cli/commands.h"
#include "services/cli/north_flags.h"
#include "services/cli/progress.h"
#include "services/system/usable_cpus.h"
#include "storage/atomic_file.h"
#include "worker/scan_carver.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct CarveFlags {
  std::string scan_path;
  std::string output_dir;
  double resolution_m = 0.0625;
  int threads = 1;
  size_t slice_memory_mb = 256;  // per thread
  double slice_s = 0;               // 0: the scan's length over ~4 M-ray slices
  std::string evaluation = "fast";  // eq 4.7: worker/chunk_octree.h
  bool keep_partials = false;
  bool quiet = false;
  NorthFlags north;  // §2.3
};

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

absl::Status RunCarve(const CarveFlags& flags) {
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(flags.resolution_m);
  if (!grid.ok()) return grid.status();
  if (flags.threads < 1) return absl::InvalidArgumentError("--threads must be >= 1");
  if (!(flags.slice_s >= 0)) return absl::InvalidArgumentError("--slice-s must be >= 0");

  const fs::path out(flags.output_dir);
  const fs::path partials_dir = out / "partials";
  const fs::path tiles_dir = out / "tiles";
  const fs::path partial_dir = out / "tiles.incomplete";
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) return absl::UnavailableError(absl::StrCat("cannot create ", out.string(), ": ", ec.message()));
  // A previous run's files would otherwise mix with this run's (an old tile of a chunk this scan
  // does not touch would survive).
  fs::remove_all(partials_dir, ec);
  fs::remove_all(partial_dir, ec);
  // An older run's tiles must not pass for this run's if this one fails.
  fs::remove_all(tiles_dir, ec);
  const fs::path north_path = out / "north.json";
  fs::remove(north_path, ec);
  absl::StatusOr<ScanNorth> north = NorthOfScanForFlags(flags.scan_path, flags.north);
  if (!north.ok()) return north.status();
  if (north->decision.turned) {
    std::printf("north: turned %.2f° about the vertical to %s north (§2.3)\n",
                north->decision.yaw_rad * 180 / std::numbers::pi,
                north->place ? "true" : "magnetic");
  } else if (north->decision.warn) {
    std::fprintf(stderr, "carve: warning: north: %s\n", north->decision.note.c_str());
  }

  ProgressLine line(!flags.quiet);
  ScanCarveOptions options;
  options.grid = *grid;
  options.job_id = fs::path(flags.scan_path).stem().string();
  options.partials_dir = partials_dir.string();
  options.tiles_dir = partial_dir.string();
  options.threads = flags.threads;
  options.evaluation =
      flags.evaluation == "exact" ? CarveEvaluation::kExact : CarveEvaluation::kFast;
  options.slices.slice_s = flags.slice_s;
  options.memory_budget_bytes = flags.slice_memory_mb << 20;
  options.keep_partials = flags.keep_partials;
  options.world_yaw_rad = north->decision.yaw_rad;
  const Clock::time_point carve_t0 = Clock::now();
  absl::StatusOr<ScanCarveTotals> carved =
      CarveScan(flags.scan_path, options, [&](const ScanCarveProgress& p) {
        const double el = SecondsSince(carve_t0);
        if (p.stage == "slices") {
          const double frac = p.rays_total ? double(p.rays_done) / p.rays_total : 0.0;
          const double eta = frac > 0 ? el * (1 - frac) / frac : 0.0;
          line.Update("carve: %llu/%llu slices, %.1f/%.1f M rays, %.0f rays/s, ETA %.0f s",
                      static_cast<unsigned long long>(p.done),
                      static_cast<unsigned long long>(p.total), p.rays_done * 1e-6,
                      p.rays_total * 1e-6, el > 0 ? p.rays_done / el : 0.0, eta);
        } else {
          line.Update("combine: %llu/%llu chunks", static_cast<unsigned long long>(p.done),
                      static_cast<unsigned long long>(p.total));
        }
      });
  line.Finish();
  if (!carved.ok()) {
    fs::remove_all(partial_dir, ec);
    if (!flags.keep_partials) fs::remove_all(partials_dir, ec);
    return absl::Status(carved.status().code(),
                        absl::StrCat(carved.status().message(), " (no tiles kept: ",
                                     partial_dir.string(), " removed)"));
  }
  // What `carvemap merge OUT/tiles --scan` reads back: the turn the tiles were carved with.
  nlohmann::json north_doc = NorthJson(*north);
  north_doc["yaw_rad"] = north->decision.yaw_rad;
  if (absl::Status s = WriteFileAtomically(
          north_path.string(), [&](std::ostream& o) { o << north_doc.dump(2) << "\n"; });
      !s.ok()) {
    return s;
  }
  // The swap: OUT/tiles/ only ever holds a complete run.
  fs::create_directories(partial_dir, ec);  // a scan without chunks still gives a tiles/ dir
  fs::remove_all(tiles_dir, ec);
  fs::rename(partial_dir, tiles_dir, ec);
  if (ec) {
    return absl::UnavailableError(absl::StrCat("cannot rename ", partial_dir.string(), " to ",
                                               tiles_dir.string(), ": ", ec.message()));
  }
  // Each tile was synced when written; the swap itself must reach the disk too (atomic_file.h).
  if (absl::Status s = SyncFolderOf(tiles_dir.string()); !s.ok()) return s;
  const double total_s = SecondsSince(t0);

  const ScanCarveTotals& t = *carved;
  auto ull = [](uint64_t v) { return static_cast<unsigned long long>(v); };
  std::printf("scan %s: %llu frames, %llu rays, %llu returns%s\n", flags.scan_path.c_str(),
              ull(t.frames), ull(t.rays), ull(t.returns),
              t.default_covariance ? " (no /path_cov: default covariances)" : "");
  std::printf("slices: %llu of %.1f s; wedges: %llu, %llu wedge-chunk pairs, partial sums "
              "%.1f MB (%.1f B/ray)\n",
              ull(t.slices), t.slice_s, ull(t.wedges), ull(t.wedge_chunk_pairs),
              t.partial_bytes * 1e-6, t.rays ? double(t.partial_bytes) / t.rays : 0.0);
  std::printf("tiles: %llu in %s, %llu leaves, %.1f MB (%.1f B/ray), %llu leaf updates\n",
              ull(t.tile_paths.size()), tiles_dir.string().c_str(), ull(t.leaves),
              t.tile_bytes * 1e-6, t.rays ? double(t.tile_bytes) / t.rays : 0.0,
              ull(t.leaf_updates));
  std::printf("resolution %.4f m, %d thread%s, %s evaluation\n", grid->resolution_m(),
              flags.threads, flags.threads == 1 ? "" : "s", flags.evaluation.c_str());
  std::printf("stages: slices %.2f s (%.0f rays/s), combine %.2f s, total %.2f s (%.0f "
              "rays/s)\n",
              t.slices_elapsed_s, t.slices_elapsed_s > 0 ? t.rays / t.slices_elapsed_s : 0.0,
              t.combine_elapsed_s, total_s, total_s > 0 ? t.rays / total_s : 0.0);
  return absl::OkStatus();
}

void RegisterCarve(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "carve",
      "Carve a scan into a probabilistic octree in this process (docs/DESIGN.md §5), by time "
      "slices on --threads threads: OUT/tiles/ gets one HDF5 tile per 2 m chunk");
  auto flags = std::make_shared<CarveFlags>();
  cmd->add_option("scan", flags->scan_path, "scan.h5 (docs/DESIGN.md §3)")->required();
  cmd->add_option("-o,--output", flags->output_dir, "Output directory (created if missing)")
      ->required();
  cmd->add_option("--resolution", flags->resolution_m,
                  "Leaf size, metres: 2 m / 2^k (0.125, 0.0625, 0.03125, 0.015625, ...)")
      ->capture_default_str();
  flags->threads = UsableCpus();
  cmd->add_option("--threads", flags->threads,
                  "Carving threads (tiles are byte-identical for any count)")
      ->capture_default_str();
  cmd->add_option("--slice-memory-mb", flags->slice_memory_mb,
                  "Memory for a slice's chunk sums before they are written out, MB per thread")
      ->check(CLI::Range(16, 1 << 16))
      ->capture_default_str();
  cmd->add_option("--slice-s", flags->slice_s,
                  "Length of a time slice, s (0: slices of ~4 M rays, at least 10 s, but at "
                  "least 8 slices for a short scan, each at least 2 s)")
      ->capture_default_str();
  cmd->add_option("--evaluation", flags->evaluation,
                  "How eq 4.7 is evaluated: fast (single precision, the default) or exact (double "
                  "precision, the reference; the same votes, within the tolerance in "
                  "worker/chunk_octree.h)")
      ->check(CLI::IsMember({"fast", "exact"}))
      ->capture_default_str();
  AddNorthFlags(cmd, flags->north);  // the turn is recorded in OUT/north.json for `merge`
  cmd->add_flag("--keep-partials", flags->keep_partials,
                "Keep OUT/partials/ (each slice's partial sums per chunk)");
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress on stderr");
  cmd->callback([flags, &exit_code] { exit_code = ReportStatus("carve", RunCarve(*flags)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(40, RegisterCarve);

}  // namespace carvemap
