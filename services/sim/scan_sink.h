// Where the simulator's records go: a scan.h5 through ScanWriter, or memory (tests). The same
// calls as ScanWriter, so the simulator streams either way.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/scan_types.h"
#include "storage/scan_writer.h"

namespace carvemap {

class ScanSink {
 public:
  virtual ~ScanSink() = default;
  virtual absl::Status AppendPath(std::span<const PathRecord> poses,
                                  std::span<const PathCovariance> cov) = 0;
  virtual absl::StatusOr<int> AddSensor(const SensorInfo& info) = 0;
  virtual absl::Status AppendFrame(int sensor, double t,
                                   std::span<const Eigen::Vector3f> points_sensor) = 0;
  virtual absl::Status AppendMagnetometer(std::span<const MagnetometerRecord> records) = 0;
};

// Forwards to a ScanWriter it borrows (must outlive the sink).
class ScanWriterSink : public ScanSink {
 public:
  explicit ScanWriterSink(ScanWriter& writer) : writer_(writer) {}
  absl::Status AppendPath(std::span<const PathRecord> poses,
                          std::span<const PathCovariance> cov) override {
    return writer_.AppendPath(poses, cov);
  }
  absl::StatusOr<int> AddSensor(const SensorInfo& info) override {
    return writer_.AddSensor(info);
  }
  absl::Status AppendFrame(int sensor, double t,
                           std::span<const Eigen::Vector3f> points_sensor) override {
    return writer_.AppendFrame(sensor, t, points_sensor);
  }
  absl::Status AppendMagnetometer(std::span<const MagnetometerRecord> records) override {
    return writer_.AppendMagnetometer(records);
  }

 private:
  ScanWriter& writer_;
};

// Keeps everything in memory (tests; small simulations only).
class MemoryScanSink : public ScanSink {
 public:
  struct Frame {
    int sensor;
    double t;
    std::vector<Eigen::Vector3f> points_sensor;
  };
  std::vector<PathRecord> path;
  std::vector<PathCovariance> path_cov;
  std::vector<SensorInfo> sensors;
  std::vector<Frame> frames;  // in the order appended
  std::vector<MagnetometerRecord> magnetometer;

  absl::Status AppendPath(std::span<const PathRecord> poses,
                          std::span<const PathCovariance> cov) override {
    path.insert(path.end(), poses.begin(), poses.end());
    path_cov.insert(path_cov.end(), cov.begin(), cov.end());
    return absl::OkStatus();
  }
  absl::StatusOr<int> AddSensor(const SensorInfo& info) override {
    sensors.push_back(info);
    return static_cast<int>(sensors.size()) - 1;
  }
  absl::Status AppendFrame(int sensor, double t,
                           std::span<const Eigen::Vector3f> points_sensor) override {
    frames.push_back(Frame{sensor, t, {points_sensor.begin(), points_sensor.end()}});
    return absl::OkStatus();
  }
  absl::Status AppendMagnetometer(std::span<const MagnetometerRecord> records) override {
    magnetometer.insert(magnetometer.end(), records.begin(), records.end());
    return absl::OkStatus();
  }
};

}  // namespace carvemap
