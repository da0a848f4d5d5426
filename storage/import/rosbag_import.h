// ROS bags ➜ sensors of scan.h5 (docs/DESIGN.md §3): ROS 1 bags read by rosbag_reader.h,
// ROS 2 bags (MCAP or sqlite3, CDR messages; sensor_msgs/msg/… of the same fields) by
// ros2_bag_reader.h, told apart by their first bytes.
//
// The user names the scan topics and the fixed (world) frame. Each topic is one sensor (named
// after it, in the order given), and its messages give the sensor's frames:
//   - sensor_msgs/LaserScan: a `line` sensor; beam i at angle_min + i·angle_increment in the
//     scan's frame becomes (r cos a, r sin a, 0); a range outside [range_min, range_max] or not
//     finite is a no-return (NaN) ray. Every scan must have the same number of beams.
//   - sensor_msgs/PointCloud2 with float32 x, y, z: organized (height > 1) a `grid` sensor of
//     height × width, unorganized (height 1) a `points` sensor; a point with a non-finite
//     coordinate, or at the sensor's origin, is a no-return ray. Every organized cloud must
//     have the same size.
// A frame's time is its header stamp (the sensor's clock), strictly increasing on each topic.
//
// The frames come from tf2_msgs/TFMessage on /tf and /tf_static: each transform is its child
// frame's pose in its parent frame. The system frame (`base_frame`, by default the highest frame
// above the sensors' that only /tf_static links to them, e.g. base_link, the same for every
// topic) carries each sensor at a fixed pose: that static chain is the sensor's R_s2c, T_s2c.
// /path has one row per distinct frame time of all topics: the system frame's pose in
// `fixed_frame` at that time, the chain of /tf links interpolated there (linear in position,
// SLERP in rotation). Frames whose time lies outside the /tf links' time spans are skipped and
// counted (recording usually starts before the first /tf arrives); a topic where that leaves
// none is an error.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/import/import_writer.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct RosbagOptions {
  std::vector<std::string> topics;  // required: LaserScan or PointCloud2 topics, each once
  std::string fixed_frame = "map";  // the world frame
  std::string base_frame;           // the system frame; empty: see above
  // 0: the LaserScans' largest range_max, or the farthest point of the clouds (rounded up to
  // the next centimetre). Otherwise returns beyond it are no-returns.
  double max_range_m = 0;
  // Range noise, a + b·range (m): a LaserScan carries none; a 2D lidar of the SICK or Hokuyo
  // kind is within about 3 cm.
  std::array<double, 2> range_sigma = {0.03, 0.0};
  double sigma_t_s = 0.0;

  [[nodiscard]] absl::Status Validate() const;
};

struct RosbagTopicReport {
  std::string topic;
  std::string message_type;  // sensor_msgs/LaserScan or sensor_msgs/PointCloud2
  std::string sensor_frame;
  uint64_t messages = 0;            // on the topic
  uint64_t skipped_outside_tf = 0;  // frames outside the /tf links' time spans
  uint64_t no_return_rays = 0;
};

struct RosbagReport {
  std::vector<RosbagTopicReport> topics;  // as RosbagOptions::topics
  std::string base_frame;
  uint64_t transforms = 0;  // read from /tf and /tf_static
};

// A bag read once (connections, /tf, /tf_static, the topics' sizes and ranges) so that the
// sensors are known before their frames are written; Run() reads it again for the frames.
// Errors name the file and say what is wrong: a topic missing (listing the bag's topics) or of
// another type, no /tf chain from a sensor's frame to the fixed frame, topics whose default
// system frames differ, a frame with two parents, frames of different sizes, a stamp not after
// the previous one of its topic (naming the message), every frame of a topic outside the /tf
// spans, and the reader's errors.
class RosbagImport {
 public:
  static absl::StatusOr<RosbagImport> Open(const std::string& file, const RosbagOptions& options);
  RosbagImport(RosbagImport&&) noexcept;
  RosbagImport& operator=(RosbagImport&&) noexcept;
  ~RosbagImport();

  // One per topic, in the order of RosbagOptions::topics.
  [[nodiscard]] const std::vector<SensorInfo>& sensors() const;
  // Each frame to `sink` (by sensor index), each topic's in time order; returns /path.
  absl::StatusOr<std::vector<PathRecord>> Run(const SensorFrameSink& sink,
                                              RosbagReport* report = nullptr) const;

  struct State;

 private:
  explicit RosbagImport(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace carvemap
