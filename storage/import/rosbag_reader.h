// ROS 1 bags (format 2.0) and the three message types carvemap imports from ROS bags, in
// ROS 1's serialization and in ROS 2's CDR (ROS 2's containers: ros2_bag_reader.h).
//
// A bag is "#ROSBAG V2.0\n" then records: header length (u32), header (fields: u32 length,
// "name=value"), data length (u32), data; all little-endian. The record's `op` field says its
// kind: 0x03 bag header, 0x05 chunk (its data is more records, compressed as its
// `compression` field says: none, bz2 or lz4 (LZ4 frames)), 0x07 connection (topic, message
// type and MD5 of its definition), 0x02 message data (connection id, receive time, the
// serialized message), 0x04 index and 0x06 chunk info (skipped: the file is read in order).
// Messages are ROS 1 serialization: little-endian numbers, strings and arrays as a u32
// count then their elements. CDR (ROS 2) differs in three ways: a 4-byte encapsulation first,
// each number aligned to its size from the payload's start, strings ending in a NUL that their
// length counts; and a header has no seq.
//
// Our own reader: Debian's librosbag-dev is the C++ half of ROS (roscpp, boost), far more than
// reading three message types needs. Tests read bags written by Debian's python3-rosbag.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace carvemap {

// How a connection's messages are serialized: ROS 1's own serialization, ROS 2's CDR, or
// another encoding an MCAP file may hold (JSON, Protobuf, …), which is not read.
enum class RosEncoding { kRos1, kCdr, kUnknown };

struct BagConnection {
  uint32_t id = 0;
  std::string topic, type, md5sum;  // md5sum: ROS 1 only
  RosEncoding encoding = RosEncoding::kRos1;
};

// One message as the reader meets it; `data` is valid only during the call.
struct BagMessage {
  const BagConnection* connection = nullptr;
  double receive_time = 0;        // s, the record's time (the recorder's clock)
  std::span<const uint8_t> data;  // the serialized message
  uint64_t index = 0;             // 0-based, in file order, over all topics
};

using BagMessageFn = std::function<absl::Status(const BagMessage&)>;

// Calls `fn` for every message of `path` in file order (its connection is always known by
// then); a non-OK status from `fn` stops the read and is returned. Errors name the file and the
// byte offset of the record: not a bag, a record running past the end of the file (a bag cut
// short), a chunk that does not decompress to its stated size, a message of an unknown
// connection. `connections`, if given, receives every connection of the file.
absl::Status ReadBag(const std::string& path, const BagMessageFn& fn,
                     std::vector<BagConnection>* connections = nullptr);

// The message types, with the MD5 sums of their definitions that a bag's connections carry.
inline constexpr char kLaserScanType[] = "sensor_msgs/LaserScan";
inline constexpr char kLaserScanMd5[] = "90c7ef2dc6895d81024acba2ac42f369";
inline constexpr char kPointCloud2Type[] = "sensor_msgs/PointCloud2";
inline constexpr char kPointCloud2Md5[] = "1158d486dd51d683ce2f1be655c3c181";
inline constexpr char kTfMessageType[] = "tf2_msgs/TFMessage";
inline constexpr char kTfMessageMd5[] = "94810edda583a504dfda3829e70d7eec";

struct RosHeader {
  uint32_t seq = 0;
  double stamp = 0;  // s
  std::string frame_id;
};

struct RosLaserScan {
  RosHeader header;
  float angle_min = 0, angle_max = 0, angle_increment = 0;
  float time_increment = 0, scan_time = 0;
  float range_min = 0, range_max = 0;
  std::vector<float> ranges;  // intensities are not kept
};

// A cloud whose x, y and z are float32 fields, read into points: height × width of them,
// row-major. A point with any non-finite coordinate, or exactly at the sensor's origin (how
// many drivers mark a beam without return, against REP 117's NaN), is NaN in all three.
struct RosPointCloud {
  RosHeader header;
  uint32_t height = 0, width = 0;
  std::vector<Eigen::Vector3f> points;
};

struct RosTransform {
  RosHeader header;  // frame_id: the parent frame
  std::string child_frame_id;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // child ➜ parent
};

// InvalidArgument saying what is wrong (an array running past the message's end, a cloud
// without float32 x, y, z, a big-endian cloud, bytes left over); the caller names the file
// and the message.
// ROS 2's messages of the same names are read with `encoding` kCdr (sensor_msgs/msg/…,
// tf2_msgs/msg/TFMessage: the same fields, a header without seq).
absl::StatusOr<RosLaserScan> DecodeLaserScan(std::span<const uint8_t> data,
                                             RosEncoding encoding = RosEncoding::kRos1);
// With `points` false the cloud's layout is checked but its points are not read.
absl::StatusOr<RosPointCloud> DecodePointCloud2(std::span<const uint8_t> data,
                                                RosEncoding encoding = RosEncoding::kRos1,
                                                bool points = true);
absl::StatusOr<std::vector<RosTransform>> DecodeTfMessage(
    std::span<const uint8_t> data, RosEncoding encoding = RosEncoding::kRos1);

}  // namespace carvemap
