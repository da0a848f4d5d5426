// `carvemap merge TILES_DIR -o OUT [--scan SCAN.h5] [--resolution R]`: the merge (docs/DESIGN.md
// §6, §7) of a tiles directory: OUT/octree.bt, OUT/octree.ot, OUT/levels.json,
// OUT/level_<k>/topdown.png (+ topdown.json), with --scan OUT/level_<k>/floorplan.geojson,
// floorplan.svg, floorplan.dxf and extruded.ply, OUT/mesh/dense.ply, OUT/mesh/building.ply and
// OUT/job.json.
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "coordinator/scan_north.h"
#include "services/cli/north_flags.h"
#include "services/cli/commands.h"
#include "services/cli/progress.h"
#include "services/merge/merge_job.h"
#include "services/system/process_memory.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

struct MergeFlags {
  MergeOptions options;
  double cache_mb = 256;
  double memory_mb = 0;  // MemoryBudgetBytes
  bool quiet = false;
  NorthFlags north;  // mode "" = what the carve recorded (TILES/../north.json), else auto
};

// §2.3: the turn the scan is read with, which must be the one the tiles were carved with.
// `carvemap carve` records it in OUT/north.json beside OUT/tiles/.
absl::Status ResolveNorth(MergeFlags& flags) {
  fs::path tiles = fs::path(flags.options.tiles_dir).lexically_normal();
  if (!tiles.has_filename()) tiles = tiles.parent_path();  // "OUT/tiles/"
  const fs::path recorded_path = tiles.parent_path() / "north.json";
  std::optional<nlohmann::json> recorded;
  if (std::ifstream in(recorded_path); in) {
    nlohmann::json j = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (!j.is_object() || !j.contains("yaw_rad") || !j["yaw_rad"].is_number()) {
      return absl::InvalidArgumentError(
          absl::StrCat(recorded_path.string(), ": not a north record (no number 'yaw_rad')"));
    }
    recorded = std::move(j);
  }
  if (flags.options.scan_path.empty()) {
    if (recorded) flags.options.job["north"] = *recorded;
    return absl::OkStatus();  // no path or points are read: the turn does not matter
  }
  if (recorded && flags.north.mode.empty() && flags.north.location.empty()) {
    flags.options.world_yaw_rad = (*recorded)["yaw_rad"].get<double>();
    flags.options.job["north"] = *recorded;
    return absl::OkStatus();
  }
  absl::StatusOr<ScanNorth> north = NorthOfScanForFlags(flags.options.scan_path, flags.north);
  if (!north.ok()) return north.status();
  if (recorded && (*recorded)["yaw_rad"].get<double>() != north->decision.yaw_rad) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "--north %s%s turns the scan by %.4f°, but the tiles were carved turned by %.4f° (%s): "
        "leave --north and --location out to use the carve's",
        flags.north.mode.empty() ? "auto" : flags.north.mode,
        flags.north.location.empty() ? "" : " --location " + flags.north.location,
        north->decision.yaw_rad * 180 / std::numbers::pi,
        (*recorded)["yaw_rad"].get<double>() * 180 / std::numbers::pi, recorded_path.string()));
  }
  flags.options.world_yaw_rad = north->decision.yaw_rad;
  nlohmann::json doc = NorthJson(*north);
  doc["yaw_rad"] = north->decision.yaw_rad;
  flags.options.job["north"] = doc;
  return absl::OkStatus();
}

absl::Status RunMergeCommand(MergeFlags& flags) {
  // The merge's stages run one after another: what one frees goes back to the system.
  MapLargeBuffersAlone();
  flags.options.cache_budget_bytes = static_cast<uint64_t>(flags.cache_mb * (1 << 20));
  flags.options.memory_budget_bytes = MemoryBudgetBytes(flags.memory_mb);
  flags.options.job = {{"command", "carvemap merge"},
                       {"params",
                        {{"floorplan", flags.options.floorplan_method},
                         {"points", flags.options.trimmed_points}}}};
  if (absl::Status s = ResolveNorth(flags); !s.ok()) return s;
  ProgressLine line(!flags.quiet);
  auto progress = [&line](const MergeProgress& p) {
    line.Update("merge: %s %llu/%llu", p.stage.c_str(),
                static_cast<unsigned long long>(p.done), static_cast<unsigned long long>(p.total));
    return true;
  };
  absl::StatusOr<MergeSummary> summary = carvemap::RunMerge(flags.options, progress);
  line.Finish();
  if (!summary.ok()) return summary.status();
  const MergeSummary& s = *summary;
  std::cout << std::fixed << std::setprecision(3) << "merged " << s.num_tiles << " tiles, "
            << s.num_leaves << " leaves at " << s.resolution_m << " m in " << s.seconds_total
            << " s, peak memory " << std::setprecision(0)
            << double(ReadProcessStatus().peak_resident_bytes) / (1 << 20) << " MiB\n"
            << std::setprecision(3) << "  interior " << s.interior_volume_m3
            << " m3, observed exterior " << s.exterior_observed_volume_m3 << " m3\n"
            << "  " << s.octree_bt_path << ": " << s.num_bt_nodes << " nodes (OctoMap .bt)\n"
            << "  " << s.octree_ot_path << ": " << s.num_ot_nodes
            << " nodes (OctoMap .ot, log-odds)\n";
  if (s.topdown_width > 0) {
    std::cout << "  " << s.topdown_png_path << ": " << s.topdown_width << "x" << s.topdown_height
              << " px, origin (" << s.topdown_origin_x_m << ", " << s.topdown_origin_y_m
              << ") m, max open height " << s.max_open_height_m << " m\n";
  }
  std::cout << "  " << s.topdown_json_path << "\n";
  if (flags.options.meshes) {
    std::cout << "  " << s.num_boundary_faces << " boundary faces, " << s.num_planar_regions
              << " planar regions, " << s.num_levels << " level(s) (levels.json)\n"
              << "  mesh/dense.ply: " << s.dense_triangles << " triangles\n";
    if (s.num_rooms > 0) {
      std::cout << "  level_<k>/floorplan.geojson, floorplan.svg, floorplan.dxf, extruded.ply: "
                << s.num_rooms << " rooms\n";
    }
    if (s.building_triangles > 0) {
      std::cout << "  mesh/building.ply: " << s.building_triangles << " triangles\n";
    }
    const nlohmann::json counts = s.job.value("counts", nlohmann::json::object());
    if (counts.contains("points_kept")) {
      std::cout << "  points.ply: " << counts.value("points_kept", uint64_t{0}) << " points ("
                << counts.value("points_trimmed", uint64_t{0}) << " trimmed, §5.5)\n";
    }
    for (const std::string& w : s.warnings) std::cout << "  warning: " << w << "\n";
  }
  std::cout << "  " << s.job_json_path << "\n";
  return absl::OkStatus();
}

void RegisterMerge(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "merge",
      "Merge carved tiles into the job's outputs: octree.bt and octree.ot (OctoMap), levels.json, "
      "level_<k>/topdown.png (open height, §5.4) and occupancy.pgm/.yaml (a ROS map_server "
      "map), mesh/dense.ply, mesh/building.ply "
      "and job.json");
  auto flags = std::make_shared<MergeFlags>();
  cmd->add_option("tiles", flags->options.tiles_dir, "Directory of c_<x>_<y>_<z>.h5 tiles")
      ->required();
  cmd->add_option("-o,--output", flags->options.output_dir, "Output directory")->required();
  cmd->add_option("--scan", flags->options.scan_path,
                  "The job's scan.h5: its path gives the floor plans their lines of sight "
                  "(without it: no floor plans)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--floorplan", flags->options.floorplan_method,
                  "Floor-plan method with --scan: rooms (§3.3 room partitioning) or eigencrust "
                  "(§3.2, with §3.3's rooms on its interior)")
      ->check(CLI::IsMember({"rooms", "eigencrust"}))
      ->capture_default_str();
  cmd->add_flag("--points", flags->options.trimmed_points,
                "Also write points.ply: the scan's points in the world frame without those "
                "farther than 1 m from the floor plans (§5.5: seen through windows and doors); "
                "needs --scan")
      ->needs("--scan");
  cmd->add_option("--min-object-volume", flags->options.min_object_volume_m3,
                  "With --scan: objects with less volume than this, m³, are specks and dropped "
                  "(§5.6); 0 = the default, 0.005 (5 litres)")
      ->check(CLI::Range(0.0, 1000.0));
  // With --scan: the turn the tiles were carved with; by default what the carve recorded in
  // TILES/../north.json, else auto.
  AddNorthFlags(cmd, flags->north, /*optional_mode=*/true);
  cmd->add_option("--resolution", flags->options.resolution_m,
                  "Octree resolution in m (2 m / 2^k); default: the tiles'");
  cmd->add_option("--cache-mb", flags->cache_mb, "Decoded-tile cache budget in MiB")
      ->capture_default_str();
  cmd->add_option("--memory-mb", flags->memory_mb, kMergeMemoryBudgetHelp)
      ->capture_default_str();
  cmd->add_option("--threads", flags->options.threads,
                  "Threads for the per-chunk stages (boundary faces, dense meshes); 0 = one per "
                  "core. The outputs do not depend on it")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  cmd->add_option("--topdown-max-m", flags->options.topdown_max_height_m,
                  "Open height drawn as white (255) in topdown.png")
      ->capture_default_str();
  cmd->add_flag(
      "!--no-meshes", flags->options.meshes,
      "Skip faces, regions, levels and meshes (octree.bt, octree.ot, level_0 and job.json only)");
  cmd->add_flag("!--no-fill-pockets", flags->options.fill_pockets,
                "Mesh and segment the tiles as carved, without filling thin unobserved pockets "
                "enclosed by free space as free (docs/DESIGN.md §6 stage 0)");
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress line");
  cmd->callback([flags, &exit_code] { exit_code = ReportStatus("merge", RunMergeCommand(*flags)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(50, RegisterMerge);

}  // namespace carvemap
