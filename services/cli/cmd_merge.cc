// `carvemap merge TILES_DIR -o OUT [--scan SCAN.h5] [--resolution R]`: the merge (docs/DESIGN.md
// §6, §7) of a tiles directory: OUT/octree.bt, OUT/levels.json, OUT/level_<k>/topdown.png (+
// topdown.json), with --scan OUT/level_<k>/floorplan.geojson, floorplan.svg and extruded.ply,
// OUT/mesh/dense.ply, OUT/mesh/building.ply and OUT/job.json.
#include <iomanip>
#include <iostream>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/cli/commands.h"
#include "services/cli/progress.h"
#include "services/merge/merge_job.h"

namespace carvemap {
namespace {

struct MergeFlags {
  MergeOptions options;
  double cache_mb = 256;
  bool quiet = false;
};

absl::Status RunMergeCommand(MergeFlags& flags) {
  flags.options.cache_budget_bytes = static_cast<uint64_t>(flags.cache_mb * (1 << 20));
  flags.options.job = {{"command", "carvemap merge"},
                       {"params",
                        {{"floorplan", flags.options.floorplan_method},
                         {"points", flags.options.trimmed_points}}}};
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
            << " s\n"
            << "  interior " << s.interior_volume_m3 << " m3, observed exterior "
            << s.exterior_observed_volume_m3 << " m3\n"
            << "  " << s.octree_bt_path << ": " << s.num_bt_nodes << " nodes (OctoMap .bt)\n";
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
      std::cout << "  level_<k>/floorplan.geojson, floorplan.svg, extruded.ply: " << s.num_rooms
                << " rooms\n";
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
      "merge", "Merge carved tiles into the job's outputs: octree.bt (OctoMap), levels.json, "
               "level_<k>/topdown.png (open height, §5.4), mesh/dense.ply, mesh/building.ply "
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
  cmd->add_option("--resolution", flags->options.resolution_m,
                  "Octree resolution in m (2 m / 2^k); default: the tiles'");
  cmd->add_option("--cache-mb", flags->cache_mb, "Decoded-tile cache budget in MiB")
      ->capture_default_str();
  cmd->add_option("--threads", flags->options.threads,
                  "Threads for the per-chunk stages (boundary faces, dense meshes); 0 = one per "
                  "core. The outputs do not depend on it")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  cmd->add_option("--topdown-max-m", flags->options.topdown_max_height_m,
                  "Open height drawn as white (255) in topdown.png")
      ->capture_default_str();
  cmd->add_flag("!--no-meshes", flags->options.meshes,
                "Skip faces, regions, levels and meshes (octree.bt, level_0 and job.json only)");
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress line");
  cmd->callback([flags, &exit_code] { exit_code = ReportStatus("merge", RunMergeCommand(*flags)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(50, RegisterMerge);

}  // namespace carvemap
