#include "storage/import/ros2_bag_reader.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

// Bags written by @mcap/core and Python's sqlite3 with @foxglove/cdr's messages
// (tests/tools/ros2bag/): the robot of make_rosbag.py, ROS 2 style.
const std::string kDir = std::string(CARVEMAP_TEST_DATA_DIR) + "/ros2";

struct Read {
  absl::Status status;
  std::map<std::string, int> per_topic;
  std::map<std::string, std::vector<std::vector<uint8_t>>> data;  // per topic
  std::vector<BagConnection> connections;
  std::vector<double> times;
};

Read ReadAll(const std::string& path) {
  Read r;
  r.status = ReadRos2Bag(
      path,
      [&](const BagMessage& m) {
        ++r.per_topic[m.connection->topic];
        r.data[m.connection->topic].emplace_back(m.data.begin(), m.data.end());
        r.times.push_back(m.receive_time);
        EXPECT_EQ(m.connection->encoding, RosEncoding::kCdr) << m.connection->topic;
        return absl::OkStatus();
      },
      &r.connections);
  return r;
}

std::vector<uint8_t> Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

std::string WriteBytes(const std::vector<uint8_t>& bytes, const std::string& name) {
  std::ofstream(name, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  return name;
}

TEST(Ros2BagReaderTest, EveryStorageGivesTheSameMessages) {
  const Read plain = ReadAll(kDir + "/robot.mcap");
  ASSERT_TRUE(plain.status.ok()) << plain.status;
  EXPECT_EQ(plain.per_topic, (std::map<std::string, int>{
                                 {"/cloud", 19}, {"/scan", 39}, {"/tf", 201}, {"/tf_static", 1}}));
  ASSERT_EQ(plain.connections.size(), 4u);
  std::map<std::string, std::string> types;
  for (const BagConnection& c : plain.connections) types[c.topic] = c.type;
  EXPECT_EQ(types, (std::map<std::string, std::string>{{"/cloud", "sensor_msgs/msg/PointCloud2"},
                                                       {"/scan", "sensor_msgs/msg/LaserScan"},
                                                       {"/tf", "tf2_msgs/msg/TFMessage"},
                                                       {"/tf_static", "tf2_msgs/msg/TFMessage"}}));
  EXPECT_TRUE(std::is_sorted(plain.times.begin(), plain.times.end()));
  EXPECT_NEAR(plain.times.front(), 1700000000.0, 1e-6);
  for (const char* other : {"robot_zstd.mcap", "robot_lz4.mcap", "robot.db3", "robot_db3"}) {
    const Read r = ReadAll(kDir + "/" + other);
    ASSERT_TRUE(r.status.ok()) << other << ": " << r.status;
    EXPECT_EQ(r.per_topic, plain.per_topic) << other;
    EXPECT_EQ(r.data, plain.data) << other << ": the same bytes of every message";
    EXPECT_EQ(r.times, plain.times) << other;
  }
  EXPECT_TRUE(IsRos2Bag(kDir + "/robot.mcap"));
  EXPECT_TRUE(IsRos2Bag(kDir + "/robot.db3"));
  EXPECT_TRUE(IsRos2Bag(kDir + "/robot_db3"));
  EXPECT_FALSE(IsRos2Bag(kDir + "/robot_db3/metadata.yaml"));
}

TEST(Ros2BagReaderTest, DecodesTheCdrMessages) {
  const Read r = ReadAll(kDir + "/robot.mcap");
  ASSERT_TRUE(r.status.ok()) << r.status;
  absl::StatusOr<RosLaserScan> scan = DecodeLaserScan(r.data.at("/scan")[0], RosEncoding::kCdr);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->header.frame_id, "laser");
  EXPECT_NEAR(scan->header.stamp, 1700000000.103, 1e-6);
  EXPECT_EQ(scan->ranges.size(), 181u);
  EXPECT_FLOAT_EQ(scan->range_max, 5.0f);
  EXPECT_NEAR(scan->angle_min, -M_PI / 2, 1e-6);

  absl::StatusOr<RosPointCloud> cloud =
      DecodePointCloud2(r.data.at("/cloud")[0], RosEncoding::kCdr);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->header.frame_id, "camera");
  EXPECT_EQ(cloud->height, 3u);
  EXPECT_EQ(cloud->width, 5u);
  ASSERT_EQ(cloud->points.size(), 15u);
  EXPECT_TRUE(std::isnan(cloud->points[7].x())) << "pixel (1, 2) is NaN";
  EXPECT_GT(cloud->points[0].x(), 0.0f) << "the camera looks along its +x";

  absl::StatusOr<std::vector<RosTransform>> statics =
      DecodeTfMessage(r.data.at("/tf_static")[0], RosEncoding::kCdr);
  ASSERT_TRUE(statics.ok()) << statics.status();
  ASSERT_EQ(statics->size(), 3u);
  EXPECT_EQ((*statics)[1].header.frame_id, "base_link");
  EXPECT_EQ((*statics)[1].child_frame_id, "laser");
  EXPECT_TRUE((*statics)[1].translation.isApprox(Eigen::Vector3d(0.2, 0, 0.3)));

  // The same bytes read as ROS 1 serialization are not a LaserScan.
  EXPECT_FALSE(DecodeLaserScan(r.data.at("/scan")[0], RosEncoding::kRos1).ok());
  // Nor is a big-endian CDR payload read.
  std::vector<uint8_t> big = r.data.at("/scan")[0];
  big[1] = 0x00;
  EXPECT_NE(DecodeLaserScan(big, RosEncoding::kCdr).status().message().find("little-endian CDR"),
            std::string::npos);
}

TEST(Ros2BagReaderTest, BadFilesAreErrorsNamingTheFileAndTheRecord) {
  const std::vector<uint8_t> mcap = Bytes(kDir + "/robot.mcap");
  ASSERT_GT(mcap.size(), 1000u);
  // Cut short.
  const std::string cut =
      WriteBytes({mcap.begin(), mcap.begin() + static_cast<long>(mcap.size() * 3 / 5)}, "cut.mcap");
  absl::Status s = ReadRos2Bag(cut, [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_NE(s.message().find("cut.mcap: record at byte"), std::string::npos) << s;
  EXPECT_NE(s.message().find("cut short"), std::string::npos) << s;

  // A byte of a message changed: the chunk's CRC says so.
  const std::vector<uint8_t> scan0 = ReadAll(kDir + "/robot.mcap").data.at("/scan")[0];
  auto at = std::search(mcap.begin(), mcap.end(), scan0.begin(), scan0.end());
  ASSERT_NE(at, mcap.end());
  std::vector<uint8_t> flipped = mcap;
  flipped[(at - mcap.begin()) + 40] ^= 0x10;
  s = ReadRos2Bag(WriteBytes(flipped, "flipped.mcap"),
                  [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_NE(s.message().find("flipped.mcap: record at byte"), std::string::npos) << s;
  EXPECT_NE(s.message().find("CRC-32"), std::string::npos) << s;

  // Compressed data changed: the decompressor or the CRC says so.
  std::vector<uint8_t> zstd = Bytes(kDir + "/robot_zstd.mcap");
  zstd[zstd.size() / 3] ^= 0x5a;
  s = ReadRos2Bag(WriteBytes(zstd, "bad_zstd.mcap"),
                  [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("bad_zstd.mcap"), std::string::npos) << s;

  // Not a bag at all, and a database that is not a bag.
  s = ReadRos2Bag(WriteBytes({'h', 'e', 'l', 'l', 'o'}, "hello.db3"),
                  [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_NE(s.message().find("hello.db3: neither an MCAP file nor"), std::string::npos) << s;
  std::vector<uint8_t> db = Bytes(kDir + "/robot.db3");
  db.resize(db.size() / 2);
  s = ReadRos2Bag(WriteBytes(db, "half.db3"), [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("half.db3"), std::string::npos) << s;

  // A directory whose metadata.yaml lists no files.
  std::filesystem::create_directory("emptybag");
  std::ofstream("emptybag/metadata.yaml") << "rosbag2_bagfile_information:\n  version: 5\n";
  s = ReadRos2Bag("emptybag", [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_NE(s.message().find("no relative_file_paths"), std::string::npos) << s;
  // And one that lists a file that is not there.
  std::ofstream("emptybag/metadata.yaml")
      << "rosbag2_bagfile_information:\n  relative_file_paths:\n    - gone_0.db3\n";
  s = ReadRos2Bag("emptybag", [](const BagMessage&) { return absl::OkStatus(); });
  EXPECT_EQ(s.code(), absl::StatusCode::kNotFound) << s;
  EXPECT_NE(s.message().find("emptybag/gone_0.db3: cannot open"), std::string::npos) << s;
}

}  // namespace
}  // namespace carvemap
