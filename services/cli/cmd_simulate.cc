// `carvemap simulate`: a backpack walks through a known building (a preset or a 2D floor map)
// and records line scans with realistic noise (docs/DESIGN.md §4): writes OUT/scan.h5 and OUT/gt/.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "services/cli/commands.h"
#include "services/cli/progress.h"
#include "services/sim/simulator.h"
#include "services/system/usable_cpus.h"

namespace carvemap {

ProgressCallback SimulationProgressPrinter(ProgressLine& line) {
  return [&line](const SimulationProgress& p) {
    line.Update("simulate: %5.1f%% of %.0f s walk, %.2f M rays/s",
                100.0 * p.sim_time_s / std::max(p.duration_s, 1e-9), p.duration_s,
                p.elapsed_s > 0 ? p.rays / p.elapsed_s * 1e-6 : 0.0);
  };
}

namespace {

struct SimulateFlags {
  SimulateOptions options;
  std::string noise = "on";
  double drift_m = -1;
  bool no_drift = false;
  double range_sigma_m = -1;
  bool quiet = false;
};

absl::Status RunSimulate(SimulateFlags& flags) {
  SimulateOptions& o = flags.options;
  if (flags.noise != "on" && flags.noise != "off") {
    return absl::InvalidArgumentError("--noise must be 'on' or 'off'");
  }
  o.noise.enabled = flags.noise == "on";
  if (flags.no_drift && flags.drift_m >= 0) {
    return absl::InvalidArgumentError("--no-drift and --drift-m cannot both be given");
  }
  o.noise.drift = !flags.no_drift;
  if (flags.drift_m >= 0) {
    o.noise.drift_options.sigma_xy_m = flags.drift_m;
    o.noise.drift_options.sigma_z_m = 0.3 * flags.drift_m;
  }
  if (flags.range_sigma_m >= 0) o.noise.range_a_m = flags.range_sigma_m;
  const bool from_map = !o.floormap_png.empty();
  ProgressLine line(!flags.quiet);
  absl::StatusOr<SimulationSummary> summary = Simulate(o, SimulationProgressPrinter(line));
  line.Finish();
  if (!summary.ok()) return summary.status();
  const SimulationSummary& s = *summary;
  std::printf("building %s (%s), seed %llu, noise %s\n", s.building.c_str(),
              from_map ? o.floormap_png.c_str() : "preset",
              static_cast<unsigned long long>(o.seed), flags.noise.c_str());
  std::printf("walk: %.1f s, %.1f m, %d rooms entered\n", s.duration_s, s.path_length_m,
              s.rooms_entered);
  std::printf("scans: %llu frames, %llu rays, %llu hits, %.2f M rays/s (%.1f s)\n",
              static_cast<unsigned long long>(s.frames), static_cast<unsigned long long>(s.rays),
              static_cast<unsigned long long>(s.hits), s.rays_per_s * 1e-6, s.elapsed_s);
  std::printf("wrote %s\nwrote %s/ (building.json, surfaces.ply, objects.ply)\n",
              s.scan_path.c_str(), s.gt_dir.c_str());
  return absl::OkStatus();
}

void RegisterSimulate(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "simulate",
      "Simulate a backpack scanning a known building: writes OUT/scan.h5 (docs/DESIGN.md §3) and "
      "OUT/gt/ (building.json, surfaces.ply, objects.ply)");
  auto flags = std::make_shared<SimulateFlags>();
  SimulateOptions& o = flags->options;
  cmd->add_option("-o,--output", o.output_dir, "Output directory (created if missing)")
      ->required();
  auto* preset = cmd->add_option("--preset", o.preset,
                                 "Preset building: room, office (16 rooms), office2 (2 levels), office4 (4 levels "
                                 "of 3 wings, 180 rooms)")
                     ->capture_default_str();
  auto* floormap = cmd->add_option("--floormap", o.floormap_png,
                                   "2D floor map PNG to extrude instead of a preset")
                       ->check(CLI::ExistingFile);
  preset->excludes(floormap);
  cmd->add_option("--furniture", o.furniture_png,
                  "Furniture map PNG of the same size (with --floormap)")
      ->check(CLI::ExistingFile)
      ->needs(floormap);
  cmd->add_option("--rooms", o.rooms_png,
                  "Ground-truth room segmentation PNG of the same size (with --floormap)")
      ->check(CLI::ExistingFile)
      ->needs(floormap);
  cmd->add_option("--resolution", o.resolution_m, "Floor map resolution, metres per pixel")
      ->capture_default_str();
  cmd->add_option("--seed", o.seed, "Seed of furniture, walk and noise (same seed, same bytes)")
      ->capture_default_str();
  cmd->add_option("--rate-hz", o.rig.rate_hz, "Frames per second of each line scanner, Hz")
      ->capture_default_str();
  cmd->add_option("--beam-step-deg", o.rig.beam_step_deg,
                  "Angle between beams, degrees (0.25 = 1081 beams over 270°)")
      ->capture_default_str();
  cmd->add_option("--noise", flags->noise,
                  "on: drift, clock jitter, range noise; off: exact data for tests")
      ->capture_default_str();
  cmd->add_option("--drift-m", flags->drift_m,
                  "Localization drift std-dev in x and y, metres (z: 0.3 of it; default 0.1); "
                  "the rotation drift (yaw 0.5°, roll and pitch 0.2°) stays");
  cmd->add_flag("--no-drift", flags->no_drift,
                "No localization drift at all, the path exact (range noise and clock jitter "
                "stay; --noise off removes them too)");
  cmd->add_option("--range-sigma", flags->range_sigma_m,
                  "Constant part a of the range noise std-dev a + b·range, metres (default 0.01)");
  cmd->add_option("--laps", o.walk.laps,
                  "Walk the tour this many times in a row (a longer survey of the same "
                  "building: each lap with fresh noise, the drift going on)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--max-duration", o.max_duration_s,
                  "Stop the walk after this many seconds (0 = the whole walk)")
      ->capture_default_str();
  cmd->add_option("--frame-yaw-deg", o.frame_yaw_deg,
                  "Record the path in a frame turned this many degrees about the vertical, as a "
                  "localizer that starts from its first heading does (§2.3); gt/ stays north-up")
      ->check(CLI::Range(-360.0, 360.0))
      ->capture_default_str();
  o.threads = UsableCpus();
  cmd->add_option("--threads", o.threads, "Ray-casting threads (output is the same for any)")
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress on stderr");
  cmd->callback([flags, &exit_code] {
    exit_code = ReportStatus("simulate", RunSimulate(*flags));
  });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(10, RegisterSimulate);

}  // namespace carvemap
