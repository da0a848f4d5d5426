// `carvemap validate SCAN.h5`: checks a scan.h5 against docs/DESIGN.md §3 (structure and every row)
// and prints a short summary.
#include <CLI/CLI.hpp>
#include <iomanip>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/cli/commands.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

// Rays with no return (all-NaN rows) per sensor, counted over the frames in one stream.
absl::StatusOr<std::vector<uint64_t>> CountNoReturns(ScanReader& reader) {
  std::vector<uint64_t> counts(reader.sensors().size(), 0);
  auto stream = reader.StreamFrames();
  ScanFrame frame;
  while (true) {
    absl::StatusOr<bool> more = stream->Next(frame);
    if (!more.ok()) return more.status();
    if (!*more) break;
    for (const Eigen::Vector3f& p : frame.points_sensor) {
      if (p.array().isNaN().all()) ++counts[frame.sensor];
    }
  }
  return counts;
}

void PrintSummary(const ScanReader& reader, const std::vector<uint64_t>& no_returns) {
  std::cout << reader.file() << "\n";
  for (size_t i = 0; i < reader.sensors().size(); ++i) {
    const SensorInfo& s = reader.sensors()[i];
    std::cout << "  sensor " << s.name << ": " << SensorKindName(s.kind);
    if (s.kind == SensorKind::kGrid) std::cout << " " << s.rows << "x" << s.cols;
    std::cout << ", " << reader.frame_count(static_cast<int>(i)) << " frames, "
              << reader.point_count(static_cast<int>(i)) << " points, " << no_returns[i]
              << " rays with no return\n";
  }
  const auto& path = reader.path();
  double length_m = 0;
  for (size_t i = 1; i < path.size(); ++i) {
    length_m += Eigen::Vector3d(path[i].x - path[i - 1].x, path[i].y - path[i - 1].y,
                                path[i].z - path[i - 1].z)
                    .norm();
  }
  const double duration_s = path.empty() ? 0.0 : path.back().t - path.front().t;
  std::cout << std::fixed << std::setprecision(3) << "  path: " << path.size() << " poses, "
            << duration_s << " s, " << length_m << " m travelled\n";
  std::cout << "  path_cov: " << (reader.path_covariance() ? "yes" : "no")
            << ", magnetometer: " << (reader.magnetometer() ? "yes" : "no") << "\n";
  std::cout << "valid\n";
}

absl::Status RunValidate(const std::string& scan_path) {
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path);
  if (!reader.ok()) return reader.status();
  if (absl::Status s = (*reader)->Validate(); !s.ok()) return s;
  absl::StatusOr<std::vector<uint64_t>> no_returns = CountNoReturns(**reader);
  if (!no_returns.ok()) return no_returns.status();
  PrintSummary(**reader, *no_returns);
  return absl::OkStatus();
}

void RegisterValidate(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "validate", "Check a scan.h5 (docs/DESIGN.md §3: structure and every row) and summarize it");
  auto scan_path = std::make_shared<std::string>();
  cmd->add_option("scan", *scan_path, "The scan.h5 file")->required();
  cmd->callback(
      [scan_path, &exit_code] { exit_code = ReportStatus("validate", RunValidate(*scan_path)); });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(20, RegisterValidate);

}  // namespace carvemap
