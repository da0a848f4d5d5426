// `carvemap floorplan --gridmap MAP.png --resolution 0.05 --path PATH.csv -o OUT`: the 2D route:
// a SLAM grid map used directly as wall samples (§3.1.2), the walk for the lines
// of sight, then the floor plan with rooms (§3.3) and its 2.5D extrusion.
// `carvemap floorplan --cloud SCAN.h5 -o OUT`: the point-cloud route (§3.1.1): every return of
// the scan as a cloud, its levels from the points' height histograms (§2.5), wall samples per
// level, the scan's path for the lines of sight, a floor plan per level.
// `--floorplan eigencrust` makes the interior by §3.2 instead (floorplan_pipeline.h).
// Writes the same files as the merge (docs/DESIGN.md §7): OUT/level_<k>/floorplan.geojson,
// floorplan.svg, extruded.ply, and OUT/job.json last.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/floorplan/floorplan_export.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/gridmap_wall_samples.h"
#include "services/floorplan/pointcloud_wall_samples.h"
#include "services/floorplan/scan_cloud_stream.h"
#include "services/levels/level_split.h"
#include "storage/atomic_file.h"
#include "storage/path_csv.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

struct FloorplanFlags {
  std::string gridmap;
  std::string path_csv;
  std::string cloud;  // scan.h5: the point-cloud route instead of --gridmap/--path
  std::string output_dir;
  std::string method = "rooms";
  GridMapOptions grid;
  PointCloudWallSampleOptions cloud_options;
  FloorPlanOptions plan;
  bool keep_unentered = false;
};

// The counts of one level's plan for job.json.
nlohmann::json PlanCounts(const LevelFloorPlan& r) {
  const RoomLabelingReport& lr = r.labeling;
  nlohmann::json c = {{"wall_samples", r.wall_samples},
                      {"triangles", lr.triangles},
                      {"interior_triangles", lr.interior_triangles},
                      {"sight_segments", lr.sight_segments},
                      {"truncated_segments", lr.truncated_segments},
                      {"initial_seeds", lr.initial_seeds},
                      {"removed_rooms", lr.removed_rooms},
                      {"rooms", r.plan.rooms.size()},
                      {"extruded_triangles", r.extruded.triangles.size()}};
  if (r.method == FloorPlanMethod::kEigencrust) {
    const EigencrustFloorPlanReport& e = r.eigencrust;
    c["eigencrust_inside_triangles"] = e.labeling.inside;
    c["eigencrust_lines"] = e.curves.lines;
    c["eigencrust_circles"] = e.curves.circles;
  }
  return c;
}

// Writes OUT/level_<k>/{floorplan.geojson, floorplan.svg, extruded.ply}; appends them to
// `outputs`.
absl::Status WriteLevel(const fs::path& out, int level, const LevelFloorPlan& r,
                        nlohmann::json& outputs) {
  const std::string name = absl::StrCat("level_", level);
  const fs::path dir = out / name;
  if (absl::Status s = WriteFloorPlanFiles(dir.string(), r.plan, r.outline); !s.ok()) return s;
  if (absl::Status s = WriteExtrudedPly((dir / "extruded.ply").string(), r.extruded); !s.ok()) {
    return s;
  }
  for (const char* file : {"floorplan.geojson", "floorplan.svg", "extruded.ply"}) {
    outputs.push_back(absl::StrCat(name, "/", file));
  }
  return absl::OkStatus();
}

void AddTimings(nlohmann::json& timings, const LevelFloorPlan& r) {
  for (const auto& [key, seconds] :
       {std::pair{"floorplan.rooms", r.seconds_rooms}, {"floorplan.simplify", r.seconds_simplify},
        {"floorplan.outline", r.seconds_outline}, {"floorplan.extrude", r.seconds_extrude}}) {
    timings[key] = timings.value(key, 0.0) + seconds;
  }
}

absl::Status RunFloorplan(FloorplanFlags& f) {
  const auto t_start = std::chrono::steady_clock::now();
  f.plan.rooms.remove_unentered_rooms = !f.keep_unentered;
  absl::StatusOr<FloorPlanMethod> method = ParseFloorPlanMethod(f.method);
  if (!method.ok()) return method.status();
  f.plan.method = *method;
  const bool from_cloud = !f.cloud.empty();
  if (from_cloud && (!f.gridmap.empty() || !f.path_csv.empty())) {
    return absl::InvalidArgumentError("--cloud replaces --gridmap and --path: give one route");
  }
  if (!from_cloud && f.gridmap.empty() && f.path_csv.empty()) {
    return absl::InvalidArgumentError(
        "no input: give --gridmap MAP.png and --path PATH.csv (the 2D route) or --cloud SCAN.h5");
  }
  if (!from_cloud && (f.gridmap.empty() || f.path_csv.empty())) {
    return absl::InvalidArgumentError("--gridmap needs --path, and --path needs --gridmap");
  }

  const fs::path out(f.output_dir);
  nlohmann::json outputs = nlohmann::json::array();
  nlohmann::json rooms = nlohmann::json::array();
  nlohmann::json counts = nlohmann::json::object();
  nlohmann::json timings = nlohmann::json::object();
  nlohmann::json input, params;
  size_t total_samples = 0, total_rooms = 0, total_removed = 0;
  if (!from_cloud) {
    absl::StatusOr<Image<uint8_t>> map = ReadPngGray8(f.gridmap);
    if (!map.ok()) return map.status();
    absl::StatusOr<std::vector<Eigen::Vector2d>> path = ReadPathCsv(f.path_csv);
    if (!path.ok()) return path.status();
    absl::StatusOr<WallSampleSet> samples = GridMapWallSamples(*map, *path, f.grid);
    if (!samples.ok()) {
      return absl::Status(samples.status().code(),
                          absl::StrCat(f.gridmap, ": ", samples.status().message()));
    }
    absl::StatusOr<LevelFloorPlan> result = BuildLevelFloorPlan(*samples, 0, f.plan);
    if (!result.ok()) return result.status();
    if (absl::Status s = WriteLevel(out, 0, *result, outputs); !s.ok()) return s;
    input = {{"gridmap", f.gridmap}, {"path", f.path_csv}};
    params = {{"resolution_m", f.grid.resolution_m},
              {"origin", {f.grid.origin_x_m, f.grid.origin_y_m}},
              {"occupied_below", f.grid.occupied_below},
              {"floor_z", f.grid.floor_z},
              {"ceiling_z", f.grid.ceiling_z}};
    counts = PlanCounts(*result);
    counts["path_positions"] = path->size();
    AddTimings(timings, *result);
    rooms = RoomsToJson(*result);
    total_samples = result->wall_samples;
    total_rooms = result->plan.rooms.size();
    total_removed = result->labeling.removed_rooms;
  } else {
    // §3.1.1 on the scan's returns: levels (§2.5), then all levels' samples in two passes.
    absl::StatusOr<std::unique_ptr<ScanCloudStream>> scan = ScanCloudStream::Open(f.cloud);
    if (!scan.ok()) return scan.status();
    auto t0 = std::chrono::steady_clock::now();
    absl::StatusOr<HeightHistogram> histogram = PointCloudHeightHistogram((*scan)->Stream());
    if (!histogram.ok()) return histogram.status();
    const uint64_t points = (*scan)->points_streamed();  // one pass so far
    absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromHistogram(*histogram);
    if (!levels.ok()) return levels.status();
    if (levels->empty()) {
      return absl::FailedPreconditionError(
          absl::StrCat(f.cloud, ": no level found (no floor in the points' height histogram)"));
    }
    std::vector<PointCloudWallSampleReport> reports;
    absl::StatusOr<std::vector<WallSampleSet>> sets = PointCloudWallSamples(
        (*scan)->Stream(), *levels, (*scan)->path(), f.cloud_options, &reports);
    if (!sets.ok()) {
      return absl::Status(sets.status().code(),
                          absl::StrCat(f.cloud, ": ", sets.status().message()));
    }
    timings["floorplan.wall_samples"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    input = {{"cloud", f.cloud}};
    params = {{"spacing_m", f.cloud_options.spacing_m},
              {"min_points", f.cloud_options.min_points},
              {"min_wall_height_m", f.cloud_options.min_wall_height_m},
              {"min_normal_confidence", f.cloud_options.min_normal_confidence}};
    counts["points"] = points;
    counts["path_positions"] = (*scan)->path().size();
    counts["levels"] = levels->size();
    for (size_t k = 0; k < sets->size(); ++k) {
      const int level = static_cast<int>(k);
      absl::StatusOr<LevelFloorPlan> result = BuildLevelFloorPlan((*sets)[k], level, f.plan);
      if (!result.ok()) {
        return absl::Status(result.status().code(),
                            absl::StrCat("level ", k, ": ", result.status().message()));
      }
      if (absl::Status s = WriteLevel(out, level, *result, outputs); !s.ok()) return s;
      nlohmann::json lc = PlanCounts(*result);
      lc["floor_z"] = (*levels)[k].floor_z;
      lc["ceiling_z"] = (*levels)[k].ceiling_z;
      lc["samples_with_poses"] = reports[k].samples_with_poses;
      lc["poses"] = reports[k].poses;
      counts["floorplan_levels"][absl::StrCat("level_", k)] = lc;
      AddTimings(timings, *result);
      for (auto& room : RoomsToJson(*result)) rooms.push_back(room);
      total_samples += result->wall_samples;
      total_rooms += result->plan.rooms.size();
      total_removed += result->labeling.removed_rooms;
    }
    counts["wall_samples"] = total_samples;
    counts["rooms"] = total_rooms;
  }
  params["floorplan"] = FloorPlanMethodName(f.plan.method);
  params["max_door_width_m"] = f.plan.rooms.max_door_width_m;
  params["remove_unentered_rooms"] = f.plan.rooms.remove_unentered_rooms;
  params["simplify"] = f.plan.simplify;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  timings["total"] = seconds;
  nlohmann::json job = {{"command", "carvemap floorplan"},
                        {"input", input},
                        {"params", params},
                        {"counts", counts},
                        {"timings_s", timings},
                        {"rooms", rooms},
                        {"outputs", outputs}};
  if (absl::Status s = WriteFileAtomically((out / "job.json").string(),
                                           [&](std::ostream& o) { o << job.dump(2) << "\n"; });
      !s.ok()) {
    return s;
  }
  std::printf("floor plan (%s): %zu wall samples, %zu rooms (%zu removed as never entered) in "
              "%.2f s\n",
              std::string(FloorPlanMethodName(f.plan.method)).c_str(), total_samples, total_rooms,
              total_removed, seconds);
  for (const auto& room : job["rooms"]) {
    std::printf("  level %d room %d: %.1f m²\n", room["level"].get<int>(), room["room"].get<int>(),
                room["area_m2"].get<double>());
  }
  std::printf("wrote %s/level_<k>/{floorplan.geojson, floorplan.svg, extruded.ply} and %s\n",
              out.string().c_str(), (out / "job.json").string().c_str());
  return absl::OkStatus();
}

void RegisterFloorplan(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "floorplan",
      "Floor plan with rooms and a 2.5D model from a 2D occupancy grid map and the walk "
      "(§3.1.2, §3.3), or from a scan.h5's points (--cloud, §3.1.1): writes "
      "OUT/level_<k>/floorplan.geojson, floorplan.svg, extruded.ply and OUT/job.json");
  auto f = std::make_shared<FloorplanFlags>();
  CLI::Option* gridmap =
      cmd->add_option("--gridmap", f->gridmap,
                      "Occupancy grid map PNG (dark = occupied, white = free; any PNG type)")
          ->check(CLI::ExistingFile);
  CLI::Option* path =
      cmd->add_option("--path", f->path_csv,
                      "The walk: one scanner position \"x,y\" in metres per line, in time order")
          ->check(CLI::ExistingFile);
  cmd->add_option("--cloud", f->cloud,
                  "A scan.h5 (docs/DESIGN.md §3): wall samples from its points (§3.1.1), levels "
                  "from their heights (§2.5), lines of sight from its path; instead of "
                  "--gridmap/--path")
      ->check(CLI::ExistingFile)
      ->excludes(gridmap)
      ->excludes(path);
  cmd->add_option("--floorplan", f->method,
                  "Floor-plan method: rooms (§3.3 room partitioning) or eigencrust (§3.2, with "
                  "§3.3's rooms on its interior)")
      ->check(CLI::IsMember({"rooms", "eigencrust"}))
      ->capture_default_str();
  cmd->add_option("-o,--output", f->output_dir, "Output directory")->required();
  cmd->add_option("--resolution", f->grid.resolution_m, "Metres per pixel")
      ->capture_default_str();
  cmd->add_option("--origin-x", f->grid.origin_x_m, "World x of the map's lower-left corner, m")
      ->capture_default_str();
  cmd->add_option("--origin-y", f->grid.origin_y_m, "World y of the map's lower-left corner, m")
      ->capture_default_str();
  cmd->add_option("--occupied-below", f->grid.occupied_below,
                  "Gray values below this are occupied")
      ->capture_default_str();
  cmd->add_option("--floor-z", f->grid.floor_z, "Floor height given to every room, m")
      ->capture_default_str();
  cmd->add_option("--ceiling-z", f->grid.ceiling_z, "Ceiling height given to every room, m")
      ->capture_default_str();
  cmd->add_option("--max-range", f->grid.visibility.max_range_m, "Scanner range, m")
      ->capture_default_str();
  cmd->add_option("--spacing", f->cloud_options.spacing_m,
                  "With --cloud: wall-sample grid d_s, m (§3.1.1)")
      ->capture_default_str();
  cmd->add_option("--min-wall-height", f->cloud_options.min_wall_height_m,
                  "With --cloud: a wall's points span at least this height, m (§3.1.1: H)")
      ->capture_default_str();
  cmd->add_option("--door-width", f->plan.rooms.max_door_width_m,
                  "Rooms sharing a border longer than this are one room, m (§3.3.2: 2.44)")
      ->capture_default_str();
  cmd->add_flag("--keep-unentered", f->keep_unentered,
                "Keep rooms the walk never entered (§3.3.2 removes them)");
  cmd->add_flag("!--no-simplify", f->plan.simplify, "Keep the walls as sampled (§3.3.3 off)");
  cmd->callback([f, &exit_code] { exit_code = ReportStatus("floorplan", RunFloorplan(*f)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(52, RegisterFloorplan);

}  // namespace carvemap
