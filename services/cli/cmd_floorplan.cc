// `carvemap floorplan --gridmap MAP.png --resolution 0.05 --path PATH.csv -o OUT`: the 2D route
// of issue 5: a SLAM grid map used directly as wall samples (seed §3.1.2), the walk for the lines
// of sight, then the floor plan with rooms (§3.3) and its 2.5D extrusion. Writes the same files
// as the merge (DESIGN §7): OUT/level_0/floorplan.geojson, floorplan.svg, extruded.ply, and
// OUT/job.json last.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/floorplan/floorplan_export.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/gridmap_wall_samples.h"
#include "storage/atomic_file.h"
#include "storage/path_csv.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

struct FloorplanFlags {
  std::string gridmap;
  std::string path_csv;
  std::string output_dir;
  GridMapOptions grid;
  FloorPlanOptions plan;
  bool keep_unentered = false;
};

absl::Status RunFloorplan(FloorplanFlags& f) {
  const auto t_start = std::chrono::steady_clock::now();
  f.plan.rooms.remove_unentered_rooms = !f.keep_unentered;
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

  const fs::path out(f.output_dir);
  const fs::path level_dir = out / "level_0";
  if (absl::Status s = WriteFloorPlanFiles(level_dir.string(), result->plan, result->outline);
      !s.ok()) {
    return s;
  }
  if (absl::Status s = WriteExtrudedPly((level_dir / "extruded.ply").string(), result->extruded);
      !s.ok()) {
    return s;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  const RoomLabelingReport& lr = result->labeling;
  nlohmann::json job = {
      {"command", "carvemap floorplan"},
      {"input", {{"gridmap", f.gridmap}, {"path", f.path_csv}}},
      {"params",
       {{"resolution_m", f.grid.resolution_m},
        {"origin", {f.grid.origin_x_m, f.grid.origin_y_m}},
        {"occupied_below", f.grid.occupied_below},
        {"floor_z", f.grid.floor_z},
        {"ceiling_z", f.grid.ceiling_z},
        {"max_door_width_m", f.plan.rooms.max_door_width_m},
        {"remove_unentered_rooms", f.plan.rooms.remove_unentered_rooms},
        {"simplify", f.plan.simplify}}},
      {"counts",
       {{"path_positions", path->size()},
        {"wall_samples", result->wall_samples},
        {"triangles", lr.triangles},
        {"interior_triangles", lr.interior_triangles},
        {"sight_segments", lr.sight_segments},
        {"truncated_segments", lr.truncated_segments},
        {"initial_seeds", lr.initial_seeds},
        {"removed_rooms", lr.removed_rooms},
        {"rooms", result->plan.rooms.size()},
        {"extruded_triangles", result->extruded.triangles.size()}}},
      {"timings_s",
       {{"total", seconds},
        {"floorplan.rooms", result->seconds_rooms},
        {"floorplan.simplify", result->seconds_simplify},
        {"floorplan.outline", result->seconds_outline},
        {"floorplan.extrude", result->seconds_extrude}}},
      {"rooms", RoomsToJson(*result)},
      {"outputs",
       {"level_0/floorplan.geojson", "level_0/floorplan.svg", "level_0/extruded.ply"}}};
  if (absl::Status s = WriteFileAtomically((out / "job.json").string(),
                                           [&](std::ostream& o) { o << job.dump(2) << "\n"; });
      !s.ok()) {
    return s;
  }
  std::printf("floor plan: %zu wall samples, %zu rooms (%zu removed as never entered) in %.2f s\n",
              result->wall_samples, result->plan.rooms.size(), lr.removed_rooms, seconds);
  for (const auto& room : job["rooms"]) {
    std::printf("  room %d: %.1f m²\n", room["room"].get<int>(), room["area_m2"].get<double>());
  }
  std::printf("wrote %s/{floorplan.geojson, floorplan.svg, extruded.ply} and %s\n",
              level_dir.string().c_str(), (out / "job.json").string().c_str());
  return absl::OkStatus();
}

void RegisterFloorplan(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "floorplan",
      "Floor plan with rooms and a 2.5D model from a 2D occupancy grid map and the walk "
      "(seed §3.1.2, §3.3): writes OUT/level_0/floorplan.geojson, floorplan.svg, extruded.ply "
      "and OUT/job.json");
  auto f = std::make_shared<FloorplanFlags>();
  cmd->add_option("--gridmap", f->gridmap,
                  "Occupancy grid map PNG (dark = occupied, white = free; any PNG type)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--path", f->path_csv,
                  "The walk: one scanner position \"x,y\" in metres per line, in time order")
      ->required()
      ->check(CLI::ExistingFile);
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
