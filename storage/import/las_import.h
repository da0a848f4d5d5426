// LAS point clouds with the scanner's trajectory ➜ one `points` sensor of scan.h5 (docs/DESIGN.md
// §3), as mobile mappers deliver them: every point carries its GPS time, and the trajectory
// gives the scanner's pose at any time, so each point's ray starts where the scanner was when
// it measured the point.
//
// The trajectory is a text file, one pose per line: time x y z qx qy qz qw (the scanner ➜ the
// LAS frame; separated by spaces, tabs or commas; '#' lines and a first line that is not
// numbers are skipped; times strictly increasing, in the points' GPS time base).
//
// Frames: consecutive points (in file order, which must be time order) within
// `frame_seconds` of the frame's first point share one frame at that point's time, and one
// origin, the trajectory's pose there: a point's origin is off by at most the scanner's speed ×
// frame_seconds (1.5 cm at 1.5 m/s and the default 10 ms). /path has one row per frame.
//
// Coordinates are shifted so that carving works near the origin: by default the trajectory's
// first position rounded down to whole kilometres in x and y (0 in z); the report says the
// shift, which added to the outputs' coordinates gives the LAS frame's again.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/pose.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct LasImportOptions {
  std::string trajectory;  // required
  double frame_seconds = 0.01;
  // 0: the farthest point from its origin, rounded up to the next centimetre.
  double max_range_m = 0;
  std::array<double, 2> range_sigma = {0.02, 0.0};  // a survey scanner's few centimetres
  double sigma_t_s = 0.0;
  // Points whose time lies outside the trajectory: an error naming the first, or (true)
  // skipped and counted.
  bool skip_outside_trajectory = false;
  std::optional<Eigen::Vector3d> shift;  // none: see above

  [[nodiscard]] absl::Status Validate() const;
};

struct LasReport {
  uint8_t version_minor = 0, point_format = 0;
  uint64_t points = 0;  // in the file
  uint64_t skipped_outside_trajectory = 0;
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
};

// The trajectory file as poses; errors name the file and the line.
absl::StatusOr<std::vector<TimedPose>> ReadTrajectoryText(const std::string& path);

// A LAS file read once (the header, the trajectory, the time order, the ranges) so that the
// sensor is known before its frames are written; Run() reads it again for the frames. Errors
// name the file and say what is wrong: no GPS time in the point format, points out of time
// order or outside the trajectory (naming the point), and the readers' errors.
class LasImport {
 public:
  static absl::StatusOr<LasImport> Open(const std::string& file, const LasImportOptions& options);
  LasImport(LasImport&&) noexcept;
  LasImport& operator=(LasImport&&) noexcept;
  ~LasImport();

  [[nodiscard]] const SensorInfo& sensor() const;
  absl::StatusOr<ImportedScan> Run(const FrameSink& sink = nullptr,
                                   LasReport* report = nullptr) const;

  struct State;

 private:
  explicit LasImport(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace carvemap
