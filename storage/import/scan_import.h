// Plain data shared by the importers (other inputs ➜ carvemap-scan, docs/DESIGN.md §3). An importer
// parses its input into an ImportedScan; import_writer.h writes one through ScanWriter.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/scan_types.h"

namespace carvemap {

// One frame of the imported sensor: its time (s) and ray end points in the sensor frame
// (NaN row = no return).
struct ImportedFrame {
  double t = 0.0;
  std::vector<Eigen::Vector3f> points_sensor;
};

// Receives frames in ascending time while an importer parses; the span is valid only during
// the call. A non-OK status stops the import and is returned by the importer.
using FrameSink = std::function<absl::Status(double t, std::span<const Eigen::Vector3f>)>;

// What an importer produced. `frames` holds the frames only when no FrameSink was given
// (tests); with a sink they went there and only the counts are kept.
struct ImportedScan {
  SensorInfo sensor;             // the one sensor of the import
  std::vector<PathRecord> path;  // strictly ascending t, unit quaternions
  std::vector<ImportedFrame> frames;
  uint64_t frame_count = 0;  // frames produced (kept or streamed)
  uint64_t point_count = 0;  // rays in those frames, NaN rows included
};

// Helper for importers: delivers a frame to `sink`, or keeps it in `scan.frames` when `sink`
// is empty, and updates the counts.
absl::Status EmitFrame(const FrameSink& sink, double t, std::span<const Eigen::Vector3f> points,
                       ImportedScan& scan);

// Checks a quaternion read from a file: finite and of norm 1 ± `tolerance` (files round
// them); returns it normalised, as (w, x, y, z), so /path holds exact unit quaternions.
absl::StatusOr<Eigen::Vector4d> CheckedUnitQuaternion(double qw, double qx, double qy, double qz,
                                                      double tolerance = 1e-3);

// The options the importers of georeferenced point clouds (LAS, E57) share: returns farther
// than `max_range_m` are no returns (0: from the data), the range noise a + b·range, and the
// shift to near the origin. `command` ("import las") begins each error.
absl::Status ValidateCloudOptions(std::string_view command, double max_range_m,
                                  const std::array<double, 2>& range_sigma,
                                  const std::optional<Eigen::Vector3d>& shift);

// Carving works near the origin (float32 rays, the octree's key range): a georeferenced survey
// is shifted by `given`, or by default by its first position rounded down to whole kilometres
// in x and y (0 in z), which keeps the outputs' coordinates readable against the source's.
Eigen::Vector3d CloudShift(const std::optional<Eigen::Vector3d>& given,
                           const Eigen::Vector3d& first_position);

}  // namespace carvemap
