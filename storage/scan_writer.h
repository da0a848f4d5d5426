// Writes scan.h5 (carvemap-scan v1, docs/DESIGN.md §3) as a stream: path, sensors and frames are
// appended in any amount; memory stays bounded by an internal buffer. Equal content gives
// byte-identical files (no HDF5 time stamps).
//
// Thread safety: Debian's libhdf5 is built without thread-safety: serialize every HDF5 call in
// the process (all ScanReader/ScanWriter use included).
#pragma once

#include <memory>
#include <span>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/scan_types.h"

namespace carvemap {

class ScanWriter {
 public:
  // Creates `path`. Data goes to "<path>.partial" and is renamed to `path` by Close(), so a
  // crash never leaves a file that looks complete.
  static absl::StatusOr<std::unique_ptr<ScanWriter>> Create(const std::string& path);
  ~ScanWriter();  // Without Close(), removes the .partial file.
  ScanWriter(const ScanWriter&) = delete;
  ScanWriter& operator=(const ScanWriter&) = delete;

  // Appends rows to /path (and /path_cov). `cov` is empty or has one entry per pose; once
  // poses were written without covariances, later calls must not add them (and vice versa).
  // Times must ascend strictly, across calls too.
  absl::Status AppendPath(std::span<const PathRecord> poses,
                          std::span<const PathCovariance> cov = {});
  // Declares a sensor; returns its index for AppendFrame. Names are unique.
  absl::StatusOr<int> AddSensor(const SensorInfo& info);
  // Appends one frame of `sensor`: a row to its frames table and the points to its /points.
  // REQUIRES: grid frames hold rows·cols points; t is finite and after the sensor's last frame.
  absl::Status AppendFrame(int sensor, double t, std::span<const Eigen::Vector3f> points_sensor);
  absl::Status AppendMagnetometer(std::span<const MagnetometerRecord> records);

  // Flushes, closes and renames the file into place.
  absl::Status Close();

 private:
  struct Impl;
  explicit ScanWriter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace carvemap
