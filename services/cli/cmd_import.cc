// `carvemap import graph|tum|ply|carmen|rosbag|las|e57 INPUT -o scan.h5`: turns other inputs into
// scan.h5 (docs/DESIGN.md §3) through the importers in storage/import/, then re-opens and
// validates what it wrote.
#include <array>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "storage/import/carmen_import.h"
#include "storage/import/e57_import.h"
#include "storage/import/import_writer.h"
#include "storage/import/las_import.h"
#include "storage/import/octomap_graph_import.h"
#include "storage/import/ply_import.h"
#include "storage/import/rosbag_import.h"
#include "storage/import/tum_import.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

// Re-opens the written file so the summary reports what is on disk, and so a writer bug
// cannot go unnoticed.
absl::Status ValidateAndSummarize(const std::string& out_path) {
  auto reader = ScanReader::Open(out_path);
  if (!reader.ok()) return reader.status();
  if (absl::Status s = (*reader)->Validate(); !s.ok()) return s;
  const ScanReader& r = **reader;
  uint64_t frames = 0, points = 0;
  for (size_t i = 0; i < r.sensors().size(); ++i) {
    frames += r.frame_count(static_cast<int>(i));
    points += r.point_count(static_cast<int>(i));
  }
  const double duration_s = r.path().back().t - r.path().front().t;
  std::cout << std::fixed << std::setprecision(3) << out_path << ": " << frames << " frames, "
            << points << " points, " << r.path().size() << " poses, " << duration_s << " s\n";
  return absl::OkStatus();
}

// As `simulate -o DIR`: the folder the scan goes into is made if missing.
absl::Status MakeFolderOf(const std::string& out_path) {
  const std::filesystem::path folder = std::filesystem::path(out_path).parent_path();
  std::error_code ec;
  if (!folder.empty() && !std::filesystem::is_directory(folder, ec)) {
    std::filesystem::create_directories(folder, ec);
    if (ec) {
      return absl::UnavailableError(absl::StrCat(out_path, ": cannot create its folder ",
                                                 folder.string(), ": ", ec.message()));
    }
  }
  return absl::OkStatus();
}

absl::Status Run(const std::string& out_path, const SensorInfo& sensor,
                 absl::FunctionRef<absl::StatusOr<ImportedScan>(const FrameSink&)> import) {
  if (absl::Status s = MakeFolderOf(out_path); !s.ok()) return s;
  if (auto summary = WriteImport(out_path, sensor, import); !summary.ok()) {
    return summary.status();
  }
  return ValidateAndSummarize(out_path);
}

absl::Status Run(
    const std::string& out_path, std::span<const SensorInfo> sensors,
    absl::FunctionRef<absl::StatusOr<std::vector<PathRecord>>(const SensorFrameSink&)> import) {
  if (absl::Status s = MakeFolderOf(out_path); !s.ok()) return s;
  if (auto summary = WriteImportSensors(out_path, sensors, import); !summary.ok()) {
    return summary.status();
  }
  return ValidateAndSummarize(out_path);
}

// --max-range, --range-sigma and --shift, as the point-cloud importers (LAS, E57) share them
// (storage/import/scan_import.h ValidateCloudOptions, CloudShift).
void AddCloudOptions(CLI::App* cmd, const std::string& format, double& max_range_m,
                     std::array<double, 2>& range_sigma, std::vector<double>& shift) {
  cmd->add_option("--max-range", max_range_m,
                  "Returns farther from their origin are no return, m; 0: the farthest return")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--range-sigma", range_sigma,
                  "Range noise a + b·range, m: A B (" + format + " does not carry it)")
      ->capture_default_str()
      ->expected(2);
  cmd->add_option("--shift", shift, "The shift X Y Z, m (default: see above)")->expected(3);
}

std::optional<Eigen::Vector3d> ShiftFlag(const std::vector<double>& xyz) {
  if (xyz.size() != 3) return std::nullopt;
  return Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
}

void PrintShift(const Eigen::Vector3d& shift, const std::string& format) {
  std::cout << "; coordinates shifted by (" << shift.x() << ", " << shift.y() << ", " << shift.z()
            << ") m: add it to the outputs' to return to the " << format << " frame";
}

struct ImportFlags {
  std::string input, output;
  OctomapGraphOptions graph;
  TumOptions tum;
  PlyImportOptions ply;
  CarmenOptions carmen;
  RosbagOptions rosbag;
  LasImportOptions las;
  std::vector<double> las_shift;  // empty: automatic
  E57ImportOptions e57;
  std::vector<double> e57_shift;  // empty: automatic
};

void RegisterImport(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "import",
      "Turn an OctoMap scan graph, TUM depth images, a PLY with sensor origins, a CARMEN "
      "laser log,\na ROS 1 or ROS 2 bag, a LAS point cloud with its trajectory or an E57 survey "
      "into scan.h5\n(validated after writing)");
  cmd->require_subcommand(1);
  auto flags = std::make_shared<ImportFlags>();

  CLI::App* graph = cmd->add_subcommand(
      "graph",
      "OctoMap scan graph (.graph) ➜ scan.h5.\n"
      "Assumes: one `points` sensor \"graph\" with identity extrinsics (node pose = sensor "
      "pose);\none frame and one path pose per node; SYNTHETIC times: node k at t = k s "
      "(graphs have none);\npoints kept in the sensor frame; edges are checked, not stored.");
  graph->add_option("input", flags->input, "The .graph file")->required();
  graph->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  graph->callback([flags, &exit_code] {
    exit_code = ReportStatus(
        "import graph",
        Run(flags->output, OctomapGraphSensor(flags->graph), [&](const FrameSink& sink) {
          return ImportOctomapGraph(flags->input, flags->graph, sink);
        }));
  });

  TumOptions& tum = flags->tum;
  CLI::App* tum_cmd = cmd->add_subcommand(
      "tum",
      "TUM RGB-D style directory (depth/<t>.png + association file) ➜ scan.h5.\n"
      "Assumes: depth PNGs are 16-bit, metres = value/5000, 0 = no return, registered to the "
      "colour camera;\nassociation lines 'rgb/<t>.png depth/<t>.png tx ty tz qx qy qz qw' give "
      "the colour camera pose\n(mocap world) at the rgb time; path = all those poses sorted "
      "(verbatim duplicates dropped);\none frame per existing depth image at its depth time; "
      "one `grid` sensor \"depth\" with identity\nextrinsics (system frame = camera optical "
      "frame: x right, y down, z forward);\nrange noise 2 mm + 0.008·range, sigma_t 0.01 s, "
      "pixels beyond --max-range become no-return.");
  tum_cmd->add_option("input", flags->input, "The directory holding depth/")->required();
  tum_cmd->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  tum_cmd->add_option("--association", tum.association_file,
                      "Association file (default: DIR/my_association.txt)");
  tum_cmd->add_option("--stride", tum.stride, "Keep every N-th pixel in both directions")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  tum_cmd->add_option("--fx", tum.fx, "Focal length x, px")->capture_default_str();
  tum_cmd->add_option("--fy", tum.fy, "Focal length y, px")->capture_default_str();
  tum_cmd->add_option("--cx", tum.cx, "Principal point x, px")->capture_default_str();
  tum_cmd->add_option("--cy", tum.cy, "Principal point y, px")->capture_default_str();
  tum_cmd->add_option("--depth-scale", tum.depth_scale, "Stored depth units per metre")
      ->capture_default_str();
  tum_cmd->add_option("--max-range", tum.max_range_m, "Max range, m; farther = no return")
      ->capture_default_str();
  tum_cmd->callback([flags, &exit_code] {
    exit_code = ReportStatus("import tum",
                             Run(flags->output, TumSensor(flags->tum), [&](const FrameSink& sink) {
                               return ImportTum(flags->input, flags->tum, sink);
                             }));
  });

  CLI::App* ply = cmd->add_subcommand(
      "ply",
      "PLY point cloud with per-vertex sensor origin ➜ scan.h5 (ascii or binary).\n"
      "Needs vertex x y z and an origin named sensor_x/y/z, sx/sy/sz, origin_x/y/z or "
      "vp_x/y/z;\noptional time t, time or timestamp (s). Assumes: each run of consecutive "
      "vertices with one origin\n(and time) is one frame of a `points` sensor \"ply\" with "
      "identity extrinsics; its path pose has\nidentity rotation at the origin; frame time = "
      "the vertex time, else the frame index (synthetic,\n1 s apart); times must increase.");
  ply->add_option("input", flags->input, "The .ply file")->required();
  ply->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  ply->callback([flags, &exit_code] {
    exit_code = ReportStatus("import ply",
                             Run(flags->output, PlySensor(flags->ply), [&](const FrameSink& sink) {
                               return ImportPly(flags->input, flags->ply, sink);
                             }));
  });

  CarmenOptions& carmen = flags->carmen;
  CLI::App* carmen_cmd = cmd->add_subcommand(
      "carmen",
      "CARMEN robot log (plain or .gz) ➜ scan.h5: one 2D laser as a `line` sensor.\n"
      "Reads FLASER/RLASER (old format), ROBOTLASER<k> and RAWLASER<k> (with or without "
      "remission_mode) and ODOM.\nAssumes: the laser is horizontal, --height above the floor; "
      "the system frame is the laser's pose on\nthe floor (path z = 0, yaw = theta). Lines "
      "that carry a pose (FLASER/RLASER: x y theta,\nthe corrected pose in a corrected log; "
      "ROBOTLASER: the laser pose) give one frame and one path\npose each; RAWLASER lines "
      "(no pose) take the ODOM odometry interpolated at their time, and\nthose outside the "
      "odometry's span are skipped. Old-format beams span 180° from theta − 90°,\nπ/n apart "
      "for 180 or 360 readings, π/(n−1) for 181 or 361. Readings ≥ --max-range (and the\n"
      "line's own max range) or 0 are no return. Times must increase (--skip-backward-times).");
  carmen_cmd->add_option("input", flags->input, "The log file (.log or .log.gz)")->required();
  carmen_cmd->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  carmen_cmd
      ->add_option("--laser", carmen.laser,
                   "Which laser: 1 front (FLASER, ROBOTLASER1, RAWLASER1), 2 rear (RLASER, "
                   "ROBOTLASER2, RAWLASER2), 3, 4")
      ->capture_default_str()
      ->check(CLI::Range(1, 4));
  carmen_cmd->add_option("--height", carmen.height_m, "Height of the laser above the floor, m")
      ->capture_default_str();
  carmen_cmd
      ->add_option("--max-range", carmen.max_range_m, "Readings at or beyond this are no return, m")
      ->capture_default_str();
  carmen_cmd->add_flag("--skip-backward-times", carmen.skip_backward_times,
                       "Skip a line whose time is not after the previous one's (counted) "
                       "instead of failing");
  carmen_cmd->callback([flags, &exit_code] {
    CarmenReport report;
    absl::Status status =
        Run(flags->output, CarmenSensor(flags->carmen), [&](const FrameSink& sink) {
          return ImportCarmen(flags->input, flags->carmen, sink, &report);
        });
    if (status.ok()) {
      std::cout << "frames from " << report.laser_message << " lines, path from "
                << report.pose_message << "; " << report.no_return_rays << " no-return rays";
      if (report.skipped_backward > 0) {
        std::cout << "; skipped " << report.skipped_backward
                  << " lines whose time went backwards (the first at line "
                  << report.first_skipped_line << ")";
      }
      if (report.skipped_outside_poses > 0) {
        std::cout << "; skipped " << report.skipped_outside_poses
                  << " scans outside the odometry's time span";
      }
      if (report.ignored_laser_lines > 0) {
        std::cout << "; ignored " << report.ignored_laser_lines
                  << " lines of the same laser in other message types";
      }
      std::cout << "\n";
    }
    exit_code = ReportStatus("import carmen", status);
  });

  RosbagOptions& bag = flags->rosbag;
  CLI::App* bag_cmd = cmd->add_subcommand(
      "rosbag",
      "ROS bag ➜ scan.h5: each topic given (--topic, repeated or comma-separated) as one\n"
      "sensor. ROS 1 bags (format 2.0; chunks uncompressed, bz2 or lz4) and ROS 2 bags (CDR\n"
      "messages; MCAP with chunks uncompressed, zstd or lz4, or the sqlite3 .db3; a file, or the\n"
      "bag's directory with its metadata.yaml) are told apart by their bytes.\n"
      "sensor_msgs/LaserScan ➜ a `line` sensor (ranges outside [range_min, range_max] are no\n"
      "return); sensor_msgs/PointCloud2 (float32 x, y, z) ➜ a `grid` sensor when organized\n"
      "(height > 1), else `points` (non-finite points, and points at the origin, are no return).\n"
      "Frame times are the header stamps. A sensor's mounting is the /tf_static chain from its\n"
      "frame up to --base-frame (default: the highest frame joined to it by /tf_static only,\n"
      "e.g. base_link; the same for every topic); /path is that frame's pose in --fixed-frame,\n"
      "the /tf chain interpolated at each frame's stamp. Frames outside the /tf links' time\n"
      "spans are skipped and counted.");
  bag_cmd->add_option("input", flags->input, "The bag (.bag, .mcap, .db3 or a ROS 2 bag directory)")
      ->required();
  bag_cmd->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  bag_cmd
      ->add_option("--topic", bag.topics,
                   "A LaserScan or PointCloud2 topic, e.g. /scan; repeat for several sensors")
      ->required()
      ->delimiter(',');
  bag_cmd->add_option("--fixed-frame", bag.fixed_frame, "The world frame of /tf")
      ->capture_default_str();
  bag_cmd->add_option("--base-frame", bag.base_frame,
                      "The system frame (the path's); default: see above");
  bag_cmd
      ->add_option("--max-range", bag.max_range_m,
                   "Returns beyond this are no return, m; 0: the scans' range_max, or the "
                   "clouds' farthest point")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  bag_cmd
      ->add_option("--range-sigma", bag.range_sigma,
                   "Range noise a + b·range, m: A B (a bag does not carry it)")
      ->capture_default_str()
      ->expected(2);
  bag_cmd->callback([flags, &exit_code] {
    RosbagReport report;
    absl::StatusOr<RosbagImport> bag = RosbagImport::Open(flags->input, flags->rosbag);
    absl::Status status = bag.status();
    if (bag.ok()) {
      status = Run(flags->output, bag->sensors(),
                   [&](const SensorFrameSink& sink) { return bag->Run(sink, &report); });
    }
    if (status.ok()) {
      for (const RosbagTopicReport& t : report.topics) {
        std::cout << t.topic << ": " << t.messages << " " << t.message_type
                  << " messages in frame \"" << t.sensor_frame << "\", mounted on \""
                  << report.base_frame << "\"; " << t.no_return_rays << " no-return rays";
        if (t.skipped_outside_tf > 0) {
          std::cout << "; skipped " << t.skipped_outside_tf
                    << " frames outside the /tf links' time spans";
        }
        std::cout << "\n";
      }
      std::cout << report.transforms << " transforms\n";
    }
    exit_code = ReportStatus("import rosbag", status);
  });

  LasImportOptions& las = flags->las;
  CLI::App* las_cmd = cmd->add_subcommand(
      "las",
      "LAS 1.0–1.4 (uncompressed; point formats with GPS time: 1, 3–10) + the scanner's "
      "trajectory ➜\nscan.h5: one `points` sensor, as mobile mappers deliver. The trajectory is "
      "a text file, a pose\nper line: time x y z qx qy qz qw (the scanner in the LAS frame, times "
      "in the points' GPS time\nbase). Each point's origin is the trajectory at its time: points "
      "within --frame-seconds of a\nframe's first point share that point's pose (an origin off by "
      "at most speed × frame-seconds).\nPoints must be in time order. Coordinates are shifted to "
      "near the origin (default: the\ntrajectory's first x, y rounded down to whole km); the "
      "shift is printed: add it to the\noutputs' coordinates to return to the LAS frame.");
  las_cmd->add_option("input", flags->input, "The LAS file (.las)")->required();
  las_cmd->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  las_cmd->add_option("--trajectory", las.trajectory, "The trajectory text file")->required();
  las_cmd
      ->add_option("--frame-seconds", las.frame_seconds,
                   "Points within this of a frame's first share its pose, s")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  AddCloudOptions(las_cmd, "LAS", las.max_range_m, las.range_sigma, flags->las_shift);
  las_cmd->add_flag("--skip-outside-trajectory", las.skip_outside_trajectory,
                    "Drop points whose time lies outside the trajectory (else an error)");
  las_cmd->callback([flags, &exit_code] {
    flags->las.shift = ShiftFlag(flags->las_shift);
    LasReport report;
    absl::StatusOr<LasImport> las = LasImport::Open(flags->input, flags->las);
    absl::Status status = las.status();
    if (las.ok()) {
      status = Run(flags->output, las->sensor(),
                   [&](const FrameSink& sink) { return las->Run(sink, &report); });
    }
    if (status.ok()) {
      std::cout << std::fixed << std::setprecision(3) << report.points << " points of LAS 1."
                << int(report.version_minor) << " format " << int(report.point_format);
      PrintShift(report.shift, "LAS");
      if (report.skipped_outside_trajectory > 0) {
        std::cout << "; skipped " << report.skipped_outside_trajectory
                  << " points outside the trajectory";
      }
      std::cout << "\n";
    }
    exit_code = ReportStatus("import las", status);
  });

  E57ImportOptions& e57 = flags->e57;
  CLI::App* e57_cmd = cmd->add_subcommand(
      "e57",
      "E57 (ASTM E2807), as survey scanners export ➜ scan.h5: each scan of the file is one "
      "frame from\nits setup's pose. Structured scans (rowIndex, columnIndex) are frames of a "
      "`grid` sensor per\ngrid size (\"grid_<rows>x<cols>\"), so wedges join neighbouring "
      "pixels; pixels without a\nreturn are rays with no return. Unstructured scans are frames "
      "of one `points` sensor. The\npath has one pose per scan, at t = the scan's index (s). "
      "Coordinates are shifted to near the\norigin (default: the first scan's x, y rounded "
      "down to whole km); the shift is printed: add\nit to the outputs' coordinates to return "
      "to the E57 frame.");
  e57_cmd->add_option("input", flags->input, "The E57 file (.e57)")->required();
  e57_cmd->add_option("-o,--output", flags->output, "The scan.h5 to write")->required();
  AddCloudOptions(e57_cmd, "E57", e57.max_range_m, e57.range_sigma, flags->e57_shift);
  e57_cmd->callback([flags, &exit_code] {
    flags->e57.shift = ShiftFlag(flags->e57_shift);
    E57Report report;
    absl::StatusOr<E57Import> e57 = E57Import::Open(flags->input, flags->e57);
    absl::Status status = e57.status();
    if (e57.ok()) {
      status = Run(flags->output, e57->sensors(),
                   [&](const SensorFrameSink& sink) { return e57->Run(sink, &report); });
    }
    if (status.ok()) {
      std::cout << std::fixed << std::setprecision(3) << report.scans << " scans ("
                << report.structured_scans << " structured), " << report.records << " records; "
                << report.no_return << " of " << report.rays << " rays with no return";
      if (report.later_returns > 0) {
        std::cout << "; " << report.later_returns << " second or later returns left out";
      }
      PrintShift(report.shift, "E57");
      std::cout << "\n";
    }
    exit_code = ReportStatus("import e57", status);
  });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(30, RegisterImport);

}  // namespace carvemap
