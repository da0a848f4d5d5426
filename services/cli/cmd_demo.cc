// `carvemap demo`: the main job on a built-in example. Simulates the demo building (by default
// the furnished `room` preset; `office` and `office2` are larger and take minutes to carve),
// checks its scan, then runs it through the real pipeline exactly as a user would: `carvemap
// run` with a local coordinator, two workers and the merge, as separate processes. Later stages
// (floor plans, meshes) join here as they land.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <sys/wait.h>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/cli/progress.h"
#include "services/rpc/process_util.h"
#include "services/sim/simulator.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

struct DemoFlags {
  std::string output_dir = "out/demo";
  std::string preset = "room";
  int workers = 2;
  uint64_t seed = 1;
  // The demo thins the scanners to half rate and half the beams: a quarter of the rays of a
  // real survey, so the demo finishes in well under a minute.
  double rate_hz = 20.0;
  double beam_step_deg = 0.5;
  bool quiet = false;
};

absl::Status RunDemo(const DemoFlags& flags) {
  SimulateOptions options;
  options.preset = flags.preset;
  options.seed = flags.seed;
  options.output_dir = (std::filesystem::path(flags.output_dir) / "input").string();
  options.rig.rate_hz = flags.rate_hz;
  options.rig.beam_step_deg = flags.beam_step_deg;
  options.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));

  std::printf("carvemap demo: simulating the '%s' building (seed %llu)\n", flags.preset.c_str(),
              static_cast<unsigned long long>(flags.seed));
  ProgressLine line(!flags.quiet);
  absl::StatusOr<SimulationSummary> sim = Simulate(options, SimulationProgressPrinter(line));
  line.Finish();
  if (!sim.ok()) return sim.status();
  std::printf("  walk %.0f s, %.0f m, %d rooms entered; %.1f M rays in %.1f s\n", sim->duration_s,
              sim->path_length_m, sim->rooms_entered, sim->rays * 1e-6, sim->elapsed_s);

  std::printf("carvemap demo: validating %s\n", sim->scan_path.c_str());
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(sim->scan_path);
  if (!reader.ok()) return reader.status();
  if (absl::Status s = (*reader)->Validate(); !s.ok()) return s;
  std::printf("  valid: %zu sensors, %zu poses\n", (*reader)->sensors().size(),
              (*reader)->path().size());

  std::printf("carvemap demo: carving with a local coordinator and %d workers\n", flags.workers);
  std::vector<std::string> run_args = {
      "run", sim->scan_path, "-o", flags.output_dir, "--workers", std::to_string(flags.workers)};
  if (flags.quiet) run_args.push_back("--quiet");
  absl::StatusOr<pid_t> child = SpawnSelf(run_args, /*log_path=*/"");
  if (!child.ok()) return child.status();
  int wait_status = 0;
  if (waitpid(*child, &wait_status, 0) < 0 || !WIFEXITED(wait_status) ||
      WEXITSTATUS(wait_status) != 0) {
    return absl::AbortedError("carvemap run failed (its message is above)");
  }

  std::printf(
      "\noutputs in %s:\n"
      "  input/scan.h5           the scans and the localizer's (drifted) path, DESIGN §3\n"
      "  input/gt/               the truth: building.json, surfaces.ply, objects.ply (DESIGN §4)\n"
      "  octree.bt               the carved occupancy octree (OctoMap binary; opens in octovis)\n"
      "  levels.json             floor and ceiling heights of each level (§5.2)\n"
      "  level_<k>/topdown.png   open-height map of each level (§5.4), with topdown.json\n"
      "  mesh/dense.ply          dual-contouring mesh of the octree (§4.3.3), watertight\n"
      "  mesh/building.ply       planar mesh (§4.3.3; faces carry their planar region)\n"
      "  job.json                parameters, counts, timings and any warnings\n"
      "  tiles/                  one HDF5 tile per 2 m chunk (storage/TILE_FORMAT.md)\n"
      "floor plans, rooms, furniture segmentation and the combined model are not in carvemap "
      "yet.\n",
      std::filesystem::absolute(flags.output_dir).lexically_normal().c_str());
  return absl::OkStatus();
}

void RegisterDemo(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "demo", "Run carvemap end to end on a simulated building and say where the outputs are");
  auto flags = std::make_shared<DemoFlags>();
  cmd->add_option("-o,--output", flags->output_dir, "Output directory")->capture_default_str();
  cmd->add_option("--preset", flags->preset,
                  "Demo building: room (under a minute), office or office2 (minutes to carve)")
      ->capture_default_str();
  cmd->add_option("--workers", flags->workers, "Worker processes")->capture_default_str();
  cmd->add_option("--seed", flags->seed, "Seed of the simulation")->capture_default_str();
  cmd->add_option("--rate-hz", flags->rate_hz, "Scanner frame rate, Hz (a real one: 40)")
      ->capture_default_str();
  cmd->add_option("--beam-step-deg", flags->beam_step_deg,
                  "Angle between beams, degrees (a real one: 0.25)")
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress on stderr");
  cmd->callback([flags, &exit_code] { exit_code = ReportStatus("demo", RunDemo(*flags)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(1, RegisterDemo);

}  // namespace carvemap
