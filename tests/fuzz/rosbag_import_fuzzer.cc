// ROS bags (storage/import/rosbag_import.h, rosbag_reader.h, ros2_bag_reader.h): any bytes
// give a scan or an error naming the file; an accepted bag writes a scan.h5 that validates. The
// topic is /scan, or /cloud when the bag has no /scan messages, as the seeds carry (ROS 1 bags
// written by python3-rosbag; ROS 2 bags, MCAP and sqlite3, from tests/data/ros2/).
#include <cstddef>
#include <cstdint>

#include "storage/import/rosbag_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("input.bag", data, size);
  RosbagOptions options;
  options.topic = "/scan";
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open(path, options);
  if (absl::IsNotFound(bag.status()) &&
      bag.status().message().find("no messages on topic") != std::string::npos) {
    options.topic = "/cloud";
    bag = RosbagImport::Open(path, options);
  }
  if (!bag.ok()) {
    fuzz::RequireNamesFile(bag.status(), path);
    return 0;
  }
  RosbagReport report;
  absl::StatusOr<ImportedScan> scan = bag->Run(nullptr, &report);
  if (!scan.ok()) {
    fuzz::RequireNamesFile(scan.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(scan->frame_count == scan->frames.size() && scan->frame_count > 0,
                "frames kept in the result");
  fuzz::Require(scan->path.size() == scan->frames.size(), "one /path row per frame");
  fuzz::Require(report.messages == scan->frame_count + report.skipped_outside_tf,
                "every message a frame or counted as skipped");
  fuzz::RequireImportWritesValidScan(bag->sensor(), scan->frame_count,
                                     [&](const FrameSink& sink) { return bag->Run(sink); });
  return 0;
}
