// `carvemap demo`: the main job on a built-in example. Simulates the demo building (by default
// the furnished `room` preset; `office` and `office2` are larger and take minutes to carve),
// checks its scan, then runs it through the real pipeline exactly as a user would: `carvemap
// run` with a local coordinator, two workers and the merge, as separate processes. Later stages
// (floor plans, meshes) join here as they land.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <sys/wait.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/cli/progress.h"
#include "services/rpc/process_util.h"
#include "services/sim/simulator.h"
#include "services/system/usable_cpus.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

// The short summary of a finished job: levels, rooms with areas, objects, triangle
// counts and time per stage, from its levels.json and job.json. A file that cannot be read is
// skipped: the outputs list below still says where everything is.
void PrintJobSummary(const std::string& out_dir) {
  namespace fs = std::filesystem;
  auto read = [](const fs::path& p) -> nlohmann::json {
    std::ifstream in(p);
    if (!in) return nullptr;
    return nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  };
  const nlohmann::json levels = read(fs::path(out_dir) / "levels.json");
  const nlohmann::json job = read(fs::path(out_dir) / "job.json");
  if (!job.is_object()) return;
  std::printf("\nsummary:\n");
  if (levels.is_array()) {
    std::printf("  levels: %zu\n", levels.size());
    for (const auto& l : levels) {
      std::printf("    level %d: floor %.2f m, ceiling %.2f m\n", l.value("index", 0),
                  l.value("floor_z", 0.0), l.value("ceiling_z", 0.0));
    }
  }
  const nlohmann::json rooms = job.value("rooms", nlohmann::json::array());
  std::printf("  rooms: %zu\n", rooms.size());
  for (const auto& r : rooms) {
    std::printf("    level %d room %d: %.1f m², floor %.2f m, ceiling %.2f m\n",
                r.value("level", 0), r.value("room", 0), r.value("area_m2", 0.0),
                r.value("floor_z", 0.0), r.value("ceiling_z", 0.0));
  }
  const nlohmann::json counts = job.value("counts", nlohmann::json::object());
  std::printf("  objects: %zu", job.value("objects", nlohmann::json::array()).size());
  if (counts.contains("recarved_chunks")) {
    std::printf(" (meshed at %g cm: %llu chunks carved again around them, §5.6.1)",
                100 * counts.value("object_resolution_m", 0.0),
                (unsigned long long)counts.value("recarved_chunks", uint64_t{0}));
  }
  std::printf("\n");
  std::printf("  triangles: dense %llu, building %llu, objects %llu\n",
              (unsigned long long)counts.value("dense_triangles", uint64_t{0}),
              (unsigned long long)counts.value("building_triangles", uint64_t{0}),
              (unsigned long long)counts.value("object_triangles", uint64_t{0}));
  std::vector<std::pair<double, std::string>> times;
  const nlohmann::json timings = job.value("timings_s", nlohmann::json::object());
  for (const auto& [stage, seconds] : timings.items()) {
    if (seconds.is_number() && seconds.get<double>() >= 0.01) {
      times.emplace_back(seconds.get<double>(), stage);
    }
  }
  std::sort(times.rbegin(), times.rend());
  std::printf("  seconds per stage (≥ 0.01 s):");
  for (const auto& [seconds, stage] : times) std::printf(" %s %.2f;", stage.c_str(), seconds);
  std::printf("\n");
  const nlohmann::json warnings = job.value("warnings", nlohmann::json::array());
  for (const auto& w : warnings) {
    if (w.is_string()) std::printf("  warning: %s\n", w.get<std::string>().c_str());
  }
}

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
  options.threads = UsableCpus();

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

  std::printf("carvemap demo: carving with a local coordinator, %d workers and a merge service\n",
              flags.workers);
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

  const std::string out_dir =
      std::filesystem::absolute(flags.output_dir).lexically_normal().string();
  PrintJobSummary(out_dir);
  std::printf(
      "\noutputs in %s:\n"
      "  input/scan.h5           the scans and the localizer's (drifted) path, docs/DESIGN.md §3\n"
      "  input/gt/               the truth: building.json, surfaces.ply, objects.ply\n"
      "                          (docs/DESIGN.md §4)\n"
      "  octree.bt               the carved occupancy octree (OctoMap binary; opens in octovis)\n"
      "  octree.ot               the same with each node's log-odds (OctoMap's library reads it)\n"
      "  levels.json             floor and ceiling heights of each level (§5.2)\n"
      "  level_<k>/              topdown.png open-height map (§5.4); occupancy.pgm + .yaml, the\n"
      "                          level as a ROS map_server map; floorplan.geojson, .svg, .dxf,\n"
      "                          the rooms (§3.3); extruded.ply, the 2.5D model\n"
      "  mesh/dense.ply          dual-contouring mesh of the whole octree (§4.3.3), watertight\n"
      "  mesh/building.ply       planar mesh of the building without furniture (§5.6)\n"
      "  mesh/objects.ply        the furniture; mesh/objects/<id>.ply one watertight mesh each\n"
      "  mesh/combined.ply       building + objects\n"
      "  mesh/model.glb          building, rooms and objects as one glTF scene (any viewer)\n"
      "  index.html, report/     the report: numbers, time per stage, plans, 3D (a browser)\n"
      "  job.json                parameters, counts, rooms, objects, timings and any warnings\n"
      "  tiles/                  one HDF5 tile per 2 m chunk (storage/TILE_FORMAT.md)\n"
      "  object_tiles/           the chunks holding objects, carved again finer (§5.6.1)\n"
      "\nthe report: %s/index.html; for its 3D view run\n"
      "  carvemap serve %s\nand open http://127.0.0.1:8080/index.html\n",
      out_dir.c_str(), out_dir.c_str(), out_dir.c_str());
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
