// `carvemap floorplan --gridmap MAP.png --resolution 0.05 --path PATH.csv -o OUT`: the 2D route:
// a SLAM grid map used directly as wall samples (§3.1.2), the walk for the lines
// of sight, then the floor plan with rooms (§3.3) and its 2.5D extrusion.
// `carvemap floorplan --cloud SCAN.h5 -o OUT`: the point-cloud route (§3.1.1): every return of
// the scan as a cloud, its levels from the points' height histograms (§2.5), wall samples per
// level, the scan's path for the lines of sight, a floor plan per level.
// `carvemap floorplan --scan SCAN.h5 -o OUT`: the 2D route from a 2D laser log: an occupancy
// grid from the rays of its horizontal line scanners (scan_occupancy_grid.h), then the grid map
// route on it (§3.1.2 wall samples, the scan's path for the lines of sight, §3.3's rooms);
// the grid is also written as OUT/occupancy.png.
// `--floorplan eigencrust` makes the interior by §3.2 instead (floorplan_pipeline.h).
// Writes the same files as the merge (docs/DESIGN.md §7): OUT/level_<k>/floorplan.geojson,
// floorplan.svg, floorplan.dxf, extruded.ply, and OUT/job.json last.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "coordinator/scan_north.h"
#include "services/cli/commands.h"
#include "services/cli/north_flags.h"
#include "services/floorplan/export/floorplan_export.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/samples/gridmap_wall_samples.h"
#include "services/floorplan/samples/pointcloud_wall_samples.h"
#include "services/floorplan/samples/scan_cloud_stream.h"
#include "services/floorplan/samples/scan_occupancy_grid.h"
#include "services/levels/level_split.h"
#include "storage/atomic_file.h"
#include "storage/path_csv.h"
#include "storage/png_io.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

struct FloorplanFlags {
  std::string gridmap;
  std::string path_csv;
  std::string cloud;  // scan.h5: the point-cloud route instead of --gridmap/--path
  std::string scan;   // scan.h5 of horizontal line scanners: the grid built from its rays
  NorthFlags north;  // §2.3 for --scan and --cloud
  ScanOccupancyOptions occupancy;
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
                      {"open_sides_split", lr.open_sides_split},
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

// Writes OUT/level_<k>/{floorplan.geojson, floorplan.svg, floorplan.dxf, extruded.ply}; appends
// them to `outputs`.
absl::Status WriteLevel(const fs::path& out, int level, const LevelFloorPlan& r,
                        nlohmann::json& outputs) {
  const std::string name = absl::StrCat("level_", level);
  const fs::path dir = out / name;
  if (absl::Status s = WriteFloorPlanFiles(dir.string(), r.plan, r.outline); !s.ok()) return s;
  if (absl::Status s = WriteExtrudedPly((dir / "extruded.ply").string(), r.extruded); !s.ok()) {
    return s;
  }
  for (const char* file : {"floorplan.geojson", "floorplan.svg", "floorplan.dxf", "extruded.ply"}) {
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

// A line scanner's scan plane is its x-y plane (docs/DESIGN.md §3, backpack_rig.h); it is
// horizontal when the sensor's z axis is vertical (either way up). The mounting is checked, not
// the path's roll and pitch: a 2D log's path has none.
constexpr double kMaxTiltDeg = 2.0;

// Every sensor must be a horizontal line scanner; the error names the first that is not and
// the route that takes it.
absl::Status CheckHorizontalLineSensors(const std::string& file,
                                        const std::vector<SensorInfo>& sensors) {
  if (sensors.empty()) {
    return absl::FailedPreconditionError(absl::StrCat(file, ": no sensors, so no rays to map"));
  }
  for (const SensorInfo& s : sensors) {
    if (s.kind != SensorKind::kLine) {
      return absl::InvalidArgumentError(
          absl::StrCat(file, ": sensor \"", s.name, "\" is a ", std::string(SensorKindName(s.kind)),
                       " sensor; --scan maps horizontal 2D line scanners only: use --cloud ", file,
                       " (wall samples from the points, §3.1.1) or `carvemap run` for 3D scans"));
    }
    const double tilt_deg =
        std::acos(std::min(1.0, std::abs((s.R_s2c * Eigen::Vector3d::UnitZ()).z()))) * 180 / M_PI;
    if (tilt_deg > kMaxTiltDeg) {
      return absl::InvalidArgumentError(absl::StrCat(
          file, ": sensor \"", s.name, "\" is a line scanner whose scan plane is tilted ",
          absl::SixDigits(tilt_deg), "° from horizontal (at most ", kMaxTiltDeg,
          "° here); --scan maps horizontal 2D line scanners only: use --cloud ", file,
          " (wall samples from the points, §3.1.1) or `carvemap run`"));
    }
  }
  return absl::OkStatus();
}

// What the --scan route read, for job.json.
struct ScanGridCounts {
  uint64_t frames = 0, rays = 0, returns = 0;
};

// The occupancy grid of a scan's rays (two passes: its extent, then the rays) and the path's
// x-y positions. The scan's frames in world x-y: the path at the frame's time composed with
// the sensor's mounting (docs/DESIGN.md §3).
absl::StatusOr<ScanOccupancyGrid> ScanGrid(ScanReader& reader, const ScanOccupancyOptions& options,
                                           std::vector<Eigen::Vector2d>& path,
                                           ScanGridCounts& counts) {
  path.clear();
  for (const PathRecord& p : reader.path()) path.emplace_back(p.x, p.y);
  const std::vector<SensorInfo>& sensors = reader.sensors();
  auto to_scan = [&](const ScanFrame& frame, LineScan2D& scan) {
    const SensorInfo& info = sensors[frame.sensor];
    const Pose pose = reader.PoseAt(frame.t) * Pose{Eigen::Quaterniond(info.R_s2c), info.T_s2c};
    scan.origin = pose.translation.head<2>();
    scan.hits.clear();
    for (const Eigen::Vector3f& p : frame.points_sensor) {
      if (!p.allFinite()) continue;  // no return: carves nothing (scan_occupancy_grid.h)
      scan.hits.push_back((pose * p.cast<double>()).head<2>());
    }
  };
  // Every frame as a 2D scan, through `each` (a first pass for the extent, a second for the
  // rays: the grid's size must be known before the first ray is drawn).
  auto each_scan = [&](auto&& each) -> absl::Status {
    ScanFrame frame;
    LineScan2D scan;
    std::unique_ptr<ScanReader::FrameStream> stream = reader.StreamFrames();
    for (;;) {
      absl::StatusOr<bool> more = stream->Next(frame);
      if (!more.ok()) return more.status();
      if (!*more) return absl::OkStatus();
      to_scan(frame, scan);
      if (absl::Status s = each(frame, scan); !s.ok()) return s;
    }
  };
  Eigen::AlignedBox2d box;
  for (const Eigen::Vector2d& p : path) box.extend(p);
  if (absl::Status s = each_scan([&](const ScanFrame&, const LineScan2D& scan) {
        ExtendScanBounds(scan, options, box);
        return absl::OkStatus();
      });
      !s.ok()) {
    return s;
  }
  absl::StatusOr<ScanOccupancyGrid> grid = EmptyScanOccupancyGrid(box, options);
  if (!grid.ok()) return grid.status();
  if (absl::Status s = each_scan([&](const ScanFrame& frame, const LineScan2D& scan) {
        if (absl::Status s = IntegrateLineScan(scan, options, *grid); !s.ok()) {
          return absl::Status(s.code(),
                              absl::StrCat(reader.file(), ": sensor ", sensors[frame.sensor].name,
                                           " frame ", frame.row, ": ", s.message()));
        }
        ++counts.frames;
        counts.rays += frame.points_sensor.size();
        counts.returns += scan.hits.size();
        return absl::OkStatus();
      });
      !s.ok()) {
    return s;
  }
  if (counts.returns == 0) {
    return absl::FailedPreconditionError(
        absl::StrCat(reader.file(), ": no ray has a return, so nothing is occupied"));
  }
  return grid;
}

absl::Status RunFloorplan(FloorplanFlags& f) {
  const auto t_start = std::chrono::steady_clock::now();
  f.plan.rooms.remove_unentered_rooms = !f.keep_unentered;
  absl::StatusOr<FloorPlanMethod> method = ParseFloorPlanMethod(f.method);
  if (!method.ok()) return method.status();
  f.plan.method = *method;
  const bool from_cloud = !f.cloud.empty();
  const bool from_scan = !f.scan.empty();
  if (from_cloud && from_scan) {
    return absl::InvalidArgumentError("--cloud and --scan are two routes: give one");
  }
  if ((from_cloud || from_scan) && (!f.gridmap.empty() || !f.path_csv.empty())) {
    return absl::InvalidArgumentError(absl::StrCat(
        from_cloud ? "--cloud" : "--scan", " replaces --gridmap and --path: give one route"));
  }
  if (!from_cloud && !from_scan && f.gridmap.empty() && f.path_csv.empty()) {
    return absl::InvalidArgumentError(
        "no input: give --gridmap MAP.png and --path PATH.csv (the 2D route), --scan SCAN.h5 "
        "(a 2D laser scan) or --cloud SCAN.h5");
  }
  if (!from_cloud && !from_scan && (f.gridmap.empty() || f.path_csv.empty())) {
    return absl::InvalidArgumentError("--gridmap needs --path, and --path needs --gridmap");
  }

  const fs::path out(f.output_dir);
  nlohmann::json outputs = nlohmann::json::array();
  nlohmann::json rooms = nlohmann::json::array();
  nlohmann::json counts = nlohmann::json::object();
  nlohmann::json timings = nlohmann::json::object();
  nlohmann::json input, params;
  size_t total_samples = 0, total_rooms = 0, total_removed = 0;
  // §2.3 for the routes from a scan.h5: the turn to north it is read with.
  nlohmann::json north_doc;
  double world_yaw_rad = 0;
  if (from_cloud || from_scan) {
    absl::StatusOr<ScanNorth> north = NorthOfScanForFlags(from_cloud ? f.cloud : f.scan, f.north);
    if (!north.ok()) return north.status();
    if (north->decision.warn) {
      std::fprintf(stderr, "floorplan: warning: north: %s\n", north->decision.note.c_str());
    }
    world_yaw_rad = north->decision.yaw_rad;
    north_doc = NorthJson(*north);
  }
  if (!from_cloud) {
    absl::StatusOr<Image<uint8_t>> map;
    absl::StatusOr<std::vector<Eigen::Vector2d>> path;
    ScanGridCounts scan_counts;
    auto t0 = std::chrono::steady_clock::now();
    if (from_scan) {
      // The grid from the scan's rays, then the grid-map route on it (§3.1.2).
      ScanReader::OpenOptions open;
      open.world_yaw_rad = world_yaw_rad;
      absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(f.scan, open);
      if (!reader.ok()) return reader.status();
      if (absl::Status s = CheckHorizontalLineSensors(f.scan, (*reader)->sensors()); !s.ok()) {
        return s;
      }
      f.occupancy.resolution_m = f.grid.resolution_m;
      path = std::vector<Eigen::Vector2d>();
      absl::StatusOr<ScanOccupancyGrid> grid = ScanGrid(**reader, f.occupancy, *path, scan_counts);
      if (!grid.ok()) return grid.status();
      map = OccupancyGridImage(*grid, f.occupancy);
      f.grid.origin_x_m = grid->origin_x_m;
      f.grid.origin_y_m = grid->origin_y_m;
      std::error_code ec;
      fs::create_directories(out, ec);
      if (ec) return absl::InternalError(absl::StrCat(out.string(), ": ", ec.message()));
      if (absl::Status s = WritePngGray8((out / "occupancy.png").string(), *map); !s.ok()) {
        return s;
      }
      outputs.push_back("occupancy.png");
      timings["floorplan.occupancy_grid"] =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    } else {
      map = ReadPngGray8(f.gridmap);
      if (!map.ok()) return map.status();
      path = ReadPathCsv(f.path_csv);
      if (!path.ok()) return path.status();
    }
    const std::string& source = from_scan ? f.scan : f.gridmap;
    absl::StatusOr<WallSampleSet> samples = GridMapWallSamples(*map, *path, f.grid);
    if (!samples.ok()) {
      return absl::Status(samples.status().code(),
                          absl::StrCat(source, ": ", samples.status().message()));
    }
    absl::StatusOr<LevelFloorPlan> result = BuildLevelFloorPlan(*samples, 0, f.plan);
    if (!result.ok()) return result.status();
    if (absl::Status s = WriteLevel(out, 0, *result, outputs); !s.ok()) return s;
    params = {{"resolution_m", f.grid.resolution_m},
              {"origin", {f.grid.origin_x_m, f.grid.origin_y_m}},
              {"occupied_below", f.grid.occupied_below},
              {"floor_z", f.grid.floor_z},
              {"ceiling_z", f.grid.ceiling_z}};
    counts = PlanCounts(*result);
    if (from_scan) {
      input = {{"scan", f.scan}};
      params["occupancy"] = {{"hit_log_odds", f.occupancy.hit_log_odds},
                             {"miss_log_odds", f.occupancy.miss_log_odds},
                             {"min_log_odds", f.occupancy.min_log_odds},
                             {"max_log_odds", f.occupancy.max_log_odds},
                             {"occupied_log_odds", f.occupancy.occupied_log_odds},
                             {"max_range_m", f.occupancy.max_range_m},
                             {"grid_size", {map->width, map->height}}};
      counts["frames"] = scan_counts.frames;
      counts["rays"] = scan_counts.rays;
      counts["returns"] = scan_counts.returns;
    } else {
      input = {{"gridmap", f.gridmap}, {"path", f.path_csv}};
    }
    counts["path_positions"] = path->size();
    AddTimings(timings, *result);
    rooms = RoomsToJson(*result);
    total_samples = result->wall_samples;
    total_rooms = result->plan.rooms.size();
    total_removed = result->labeling.removed_rooms;
  } else {
    // §3.1.1 on the scan's returns: levels (§2.5), then all levels' samples in two passes.
    absl::StatusOr<std::unique_ptr<ScanCloudStream>> scan =
        ScanCloudStream::Open(f.cloud, /*validate=*/true, world_yaw_rad);
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
  params["open_side_max_m"] = f.plan.rooms.open_side_max_m;
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
  if (!north_doc.is_null()) job["north"] = north_doc;
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
  std::printf(
      "wrote %s/level_<k>/{floorplan.geojson, floorplan.svg, floorplan.dxf, extruded.ply} and %s\n",
      out.string().c_str(), (out / "job.json").string().c_str());
  return absl::OkStatus();
}

void RegisterFloorplan(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "floorplan",
      "Floor plan with rooms and a 2.5D model from a 2D occupancy grid map and the walk "
      "(§3.1.2, §3.3), from a 2D laser scan's rays (--scan), or from a scan.h5's points "
      "(--cloud, §3.1.1): writes "
      "OUT/level_<k>/floorplan.geojson, floorplan.svg, floorplan.dxf, extruded.ply and "
      "OUT/job.json");
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
  cmd->add_option("--scan", f->scan,
                  "A scan.h5 of horizontal 2D line scanners (e.g. `import carmen`): an occupancy "
                  "grid from its rays at --resolution (written as OUT/occupancy.png), then the "
                  "grid-map route on it with the scan's path; instead of --gridmap/--path")
      ->check(CLI::ExistingFile)
      ->excludes(gridmap)
      ->excludes(path);
  AddNorthFlags(cmd, f->north);  // with --scan or --cloud
  cmd->add_option("--ray-max-range", f->occupancy.max_range_m,
                  "With --scan: returns further than this carve free space up to it and mark "
                  "no wall, m (0 = no limit)")
      ->capture_default_str();
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
  cmd->add_option("--open-side-width", f->plan.rooms.open_side_max_m,
                  "Once the rooms are found, a dead-end part of a room (a bay, a room open to a "
                  "corridor over its width) that opens between two wall ends at most this far "
                  "apart becomes a room of its own, m (0: off, §3.3.2's rooms alone)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  cmd->add_flag("--keep-unentered", f->keep_unentered,
                "Keep rooms the walk never entered (§3.3.2 removes them)");
  cmd->add_flag("!--no-simplify", f->plan.simplify, "Keep the walls as sampled (§3.3.3 off)");
  cmd->callback([f, &exit_code] { exit_code = ReportStatus("floorplan", RunFloorplan(*f)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(52, RegisterFloorplan);

}  // namespace carvemap
