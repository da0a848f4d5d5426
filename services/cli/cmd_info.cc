// `carvemap info SCAN.h5`: what a scan.h5 holds (docs/DESIGN.md §3): each sensor's kind, mounting,
// noise and frames, and the path's span and extent. Reads the frame tables and the path only, not
// the points, so it is quick on any size of scan; `validate` is the full check.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/cli/commands.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

// R_s2c as yaw, pitch, roll (z-y'-x'', degrees): readable for the usual mountings.
Eigen::Vector3d YawPitchRollDeg(const Eigen::Matrix3d& r) {
  const double pitch = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  // + 0.0 turns −0 (asin(−0.0) of a level mounting) into 0 for printing.
  return Eigen::Vector3d(yaw, pitch, roll) * (180.0 / std::numbers::pi) + Eigen::Vector3d::Zero();
}

absl::Status RunInfo(const std::string& scan_path) {
  absl::StatusOr<std::unique_ptr<ScanReader>> opened = ScanReader::Open(scan_path);
  if (!opened.ok()) return opened.status();
  ScanReader& reader = **opened;
  std::cout << std::fixed << std::setprecision(3) << reader.file() << "\n";

  const std::vector<PathRecord>& path = reader.path();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  double length_m = 0;
  for (size_t i = 0; i < path.size(); ++i) {
    const Eigen::Vector3d p(path[i].x, path[i].y, path[i].z);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
    if (i > 0)
      length_m += (p - Eigen::Vector3d(path[i - 1].x, path[i - 1].y, path[i - 1].z)).norm();
  }
  if (!path.empty()) {
    std::cout << "  path: " << path.size() << " poses, t " << path.front().t << " … "
              << path.back().t << " s (" << path.back().t - path.front().t << " s), " << length_m
              << " m travelled\n"
              << "        x " << lo.x() << " … " << hi.x() << ", y " << lo.y() << " … " << hi.y()
              << ", z " << lo.z() << " … " << hi.z() << " m\n";
  }
  std::cout << "  path_cov: " << (reader.path_covariance() ? "yes" : "no") << ", magnetometer: ";
  if (reader.magnetometer()) {
    std::cout << reader.magnetometer()->size() << " rows\n";
  } else {
    std::cout << "no\n";
  }

  for (size_t i = 0; i < reader.sensors().size(); ++i) {
    const SensorInfo& s = reader.sensors()[i];
    const int index = static_cast<int>(i);
    absl::StatusOr<std::vector<FrameRecord>> frames = reader.FrameRecords(index);
    if (!frames.ok()) return frames.status();
    const uint64_t frame_count = reader.frame_count(index);
    const uint64_t points = reader.point_count(index);
    std::cout << "  sensor " << s.name << ": " << SensorKindName(s.kind);
    if (s.kind == SensorKind::kGrid) std::cout << " " << s.rows << "×" << s.cols;
    std::cout << ", " << frame_count << " frames, " << points << " rays";
    if (frame_count > 0) {
      std::cout << " (" << double(points) / double(frame_count) << " per frame)";
    }
    std::cout << "\n";
    if (!frames->empty()) {
      const double span = frames->back().t - frames->front().t;
      std::cout << "    frames: t " << frames->front().t << " … " << frames->back().t << " s";
      if (frames->size() > 1 && span > 0) {
        std::cout << ", " << double(frames->size() - 1) / span << " Hz";
      }
      std::cout << "\n";
    }
    const Eigen::Vector3d ypr = YawPitchRollDeg(s.R_s2c);
    std::cout << "    mounting (sensor ➜ system): T_s2c (" << s.T_s2c.x() << ", " << s.T_s2c.y()
              << ", " << s.T_s2c.z() << ") m, R_s2c yaw " << ypr.x() << "°, pitch " << ypr.y()
              << "°, roll " << ypr.z() << "°\n";
    std::cout << "    noise: range " << s.range_sigma[0] << " + " << s.range_sigma[1]
              << "·range m, time " << s.sigma_t_s << " s; max range " << s.max_range_m << " m\n";
  }
  std::cout << "(structure only: `carvemap validate` checks every row)\n";
  return absl::OkStatus();
}

void RegisterInfo(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "info",
      "Summarize a scan.h5: each sensor's kind, mounting, noise, frames and rate, and the path's "
      "time span, length and extent (reads no points; `validate` checks every row)");
  auto scan_path = std::make_shared<std::string>();
  cmd->add_option("scan", *scan_path, "The scan.h5 file")->required();
  cmd->callback([scan_path, &exit_code] { exit_code = ReportStatus("info", RunInfo(*scan_path)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(21, RegisterInfo);

}  // namespace carvemap
