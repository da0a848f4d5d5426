// ROS bags (storage/import/rosbag_import.h, rosbag_reader.h, ros2_bag_reader.h): any bytes
// give a scan or an error naming the file; an accepted bag writes a scan.h5 that validates. The
// topics are /scan and /cloud, as the seeds carry (ROS 1 bags written by python3-rosbag; ROS 2
// bags, MCAP and sqlite3, from tests/data/ros2/), or the one of them a bag has messages on.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "storage/import/rosbag_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("input.bag", data, size);
  RosbagOptions options;
  options.topics = {"/scan", "/cloud"};
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open(path, options);
  for (const char* one : {"/scan", "/cloud"}) {
    if (absl::IsNotFound(bag.status()) &&
        bag.status().message().find("no messages on topic") != std::string::npos) {
      options.topics = {one};
      bag = RosbagImport::Open(path, options);
    }
  }
  if (!bag.ok()) {
    fuzz::RequireNamesFile(bag.status(), path);
    return 0;
  }
  RosbagReport report;
  std::vector<uint64_t> frames(bag->sensors().size(), 0);
  std::vector<double> times;
  absl::StatusOr<std::vector<PathRecord>> path_records = bag->Run(
      [&](int sensor, double t, std::span<const Eigen::Vector3f>) {
        ++frames[static_cast<size_t>(sensor)];
        times.push_back(t);
        return absl::OkStatus();
      },
      &report);
  if (!path_records.ok()) {
    fuzz::RequireNamesFile(path_records.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  fuzz::Require(path_records->size() == times.size(), "one /path row per distinct frame time");
  uint64_t total = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    fuzz::Require(frames[k] > 0, "every topic has frames");
    fuzz::Require(report.topics[k].messages == frames[k] + report.topics[k].skipped_outside_tf,
                  "every message a frame or counted as skipped");
    total += frames[k];
  }
  fuzz::RequireSensorsImportWritesValidScan(
      bag->sensors(), total, [&](const SensorFrameSink& sink) { return bag->Run(sink); });
  return 0;
}
