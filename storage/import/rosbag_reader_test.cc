#include "storage/import/rosbag_reader.h"

#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "storage/import/rosbag_test_util.h"

namespace carvemap {
namespace {

using testing::BagWriter;
using testing::Bytes;

RosLaserScan Scan(double stamp, std::vector<float> ranges) {
  RosLaserScan s;
  s.header = {7, stamp, "laser"};
  s.angle_min = -1.5f;
  s.angle_max = 1.5f;
  s.angle_increment = 0.5f;
  s.range_min = 0.1f;
  s.range_max = 10.f;
  s.ranges = std::move(ranges);
  return s;
}

struct Read {
  absl::Status status;
  std::vector<std::string> topics;
  std::vector<double> times;
  std::vector<Bytes> data;
  std::vector<BagConnection> connections;
};

Read ReadAll(const std::string& path) {
  Read r;
  r.status = ReadBag(
      path,
      [&](const BagMessage& m) {
        r.topics.push_back(m.connection->topic);
        r.times.push_back(m.receive_time);
        r.data.emplace_back(m.data.begin(), m.data.end());
        EXPECT_EQ(m.index, r.data.size() - 1);
        return absl::OkStatus();
      },
      &r.connections);
  return r;
}

// Connections and messages inside chunks of each compression and outside any chunk, with the
// connections repeated at the end as rosbag writes them after its index.
BagWriter ThreeChunks() {
  BagWriter w;
  w.BeginChunk();
  w.Connection(0, "/scan", kLaserScanType, kLaserScanMd5);
  w.Message(0, 100.25, testing::SerializeLaserScan(Scan(100.2, {1, 2, 3})));
  w.EndChunk("none");
  w.BeginChunk();
  w.Connection(1, "/tf", kTfMessageType, kTfMessageMd5);
  w.Message(1, 100.5, testing::SerializeTf({}));
  w.Message(0, 100.75, testing::SerializeLaserScan(Scan(100.7, {4, 5, 6})));
  w.EndChunk("bz2");
  w.Message(0, 101.0, testing::SerializeLaserScan(Scan(100.9, {7, 8, 9})));
  w.Connection(0, "/scan", kLaserScanType, kLaserScanMd5);
  w.Connection(1, "/tf", kTfMessageType, kTfMessageMd5);
  return w;
}

TEST(RosbagReaderTest, ReadsMessagesInFileOrderFromEveryKindOfChunk) {
  const std::string path = "three_chunks.bag";
  ThreeChunks().Write(path);
  const Read r = ReadAll(path);
  ASSERT_TRUE(r.status.ok()) << r.status;
  EXPECT_EQ(r.topics, (std::vector<std::string>{"/scan", "/tf", "/scan", "/scan"}));
  ASSERT_EQ(r.times.size(), 4u);
  EXPECT_NEAR(r.times[1], 100.5, 1e-9);
  ASSERT_EQ(r.connections.size(), 2u);
  EXPECT_EQ(r.connections[0].type, kLaserScanType);
  EXPECT_EQ(r.connections[1].md5sum, kTfMessageMd5);
  absl::StatusOr<RosLaserScan> s = DecodeLaserScan(r.data[2]);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->ranges, (std::vector<float>{4, 5, 6}));
  EXPECT_NEAR(s->header.stamp, 100.7, 1e-6);
  EXPECT_EQ(s->header.frame_id, "laser");
}

// A bag cut anywhere inside its records is an error naming the file and a record, never a
// shorter bag read as if whole.
TEST(RosbagReaderTest, ABagCutShortIsAnError) {
  const BagWriter w = ThreeChunks();
  const size_t size = w.Serialized().size();
  for (size_t keep : {size_t{20}, size_t{4200}, size / 2, size - 3}) {
    const std::string path = "cut.bag";
    w.Write(path, keep);
    const Read r = ReadAll(path);
    EXPECT_FALSE(r.status.ok()) << "kept " << keep;
    EXPECT_NE(r.status.message().find(path), std::string::npos) << r.status;
    EXPECT_NE(r.status.message().find("record at byte"), std::string::npos) << r.status;
  }
}

TEST(RosbagReaderTest, RefusesWhatItCannotRead) {
  {
    std::ofstream("text.bag") << "#ROSBAG V1.2\nthis is not a version 2.0 bag\n";
    const Read r = ReadAll("text.bag");
    EXPECT_EQ(r.status.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(r.status.message().find("not a ROS 1 bag of format 2.0"), std::string::npos)
        << r.status;
  }
  for (const std::string compression : {"lz4", "zstd"}) {
    BagWriter w;
    w.BeginChunk();
    w.Connection(0, "/scan", kLaserScanType, kLaserScanMd5);
    w.EndChunk(compression);
    w.Write("compressed.bag");
    const Read r = ReadAll("compressed.bag");
    EXPECT_EQ(r.status.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(r.status.message().find(compression), std::string::npos) << r.status;
  }
  {
    BagWriter w;
    w.Message(3, 1.0, testing::SerializeTf({}));
    w.Write("orphan.bag");
    const Read r = ReadAll("orphan.bag");
    EXPECT_NE(r.status.message().find("connection 3, which no record declared"), std::string::npos)
        << r.status;
  }
}

TEST(RosbagReaderTest, LaserScansMustBeWhole) {
  const Bytes b = testing::SerializeLaserScan(Scan(5.0, {1, 2}));
  EXPECT_TRUE(DecodeLaserScan(b).ok());
  absl::StatusOr<RosLaserScan> none = DecodeLaserScan(testing::SerializeLaserScan(Scan(5.0, {})));
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_TRUE(none->ranges.empty());
  const Bytes cut(b.begin(), b.end() - 9);
  EXPECT_NE(DecodeLaserScan(cut).status().message().find("ends inside its ranges"),
            std::string::npos)
      << DecodeLaserScan(cut).status();
  Bytes longer = b;
  longer.push_back(0);
  EXPECT_NE(DecodeLaserScan(longer).status().message().find("1 bytes left over"),
            std::string::npos);
  // Without a finite first bearing and step no return has a direction.
  for (float RosLaserScan::*field : {&RosLaserScan::angle_min, &RosLaserScan::angle_increment}) {
    RosLaserScan bad = Scan(5.0, {1, 2});
    bad.*field = std::nanf("");
    absl::StatusOr<RosLaserScan> s = DecodeLaserScan(testing::SerializeLaserScan(bad));
    EXPECT_NE(s.status().message().find("is not finite"), std::string::npos) << s.status();
  }
}

TEST(RosbagReaderTest, CloudsReadXyzWhereverTheFieldsSit) {
  const float nan = std::nanf("");
  const std::vector<Eigen::Vector3f> pts = {{1, 2, 3}, {4, nan, 6}, {0, 0, 0}, {-1, -2, -3}};
  absl::StatusOr<RosPointCloud> c =
      DecodePointCloud2(testing::SerializeCloud({1, 2.5, "cam"}, 2, 2, pts));
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->height, 2u);
  EXPECT_EQ(c->width, 2u);
  ASSERT_EQ(c->points.size(), 4u);
  EXPECT_EQ(c->points[0], Eigen::Vector3f(1, 2, 3));
  EXPECT_TRUE(std::isnan(c->points[1].x())) << "a point with one NaN is a no-return";
  EXPECT_TRUE(std::isnan(c->points[2].x())) << "a point at the origin is a no-return";
  EXPECT_EQ(c->points[3], Eigen::Vector3f(-1, -2, -3));
  EXPECT_NE(DecodePointCloud2(testing::SerializeCloud({1, 2.5, "cam"}, 2, 2, pts, true))
                .status()
                .message()
                .find("big-endian"),
            std::string::npos);
  // Three points of data for a 2 × 2 cloud.
  const Bytes short_data =
      testing::SerializeCloud({1, 2.5, "cam"}, 2, 2, {pts.begin(), pts.end() - 1});
  EXPECT_NE(DecodePointCloud2(short_data).status().message().find("need more than"),
            std::string::npos)
      << DecodePointCloud2(short_data).status();
  // Without its points a cloud is checked all the same.
  absl::StatusOr<RosPointCloud> layout = DecodePointCloud2(
      testing::SerializeCloud({1, 2.5, "cam"}, 2, 2, pts), RosEncoding::kRos1, false);
  ASSERT_TRUE(layout.ok()) << layout.status();
  EXPECT_EQ(layout->height, 2u);
  EXPECT_EQ(layout->header.frame_id, "cam");
  EXPECT_TRUE(layout->points.empty());
  EXPECT_FALSE(DecodePointCloud2(short_data, RosEncoding::kRos1, false).ok());
}

TEST(RosbagReaderTest, TransformsNeedUnitQuaternions) {
  RosTransform t;
  t.header = {0, 3.0, "odom"};
  t.child_frame_id = "base_link";
  t.translation = {1, 2, 3};
  t.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  absl::StatusOr<std::vector<RosTransform>> d = DecodeTfMessage(testing::SerializeTf({t, t}));
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_EQ(d->size(), 2u);
  EXPECT_EQ((*d)[1].child_frame_id, "base_link");
  EXPECT_TRUE((*d)[1].rotation.isApprox(t.rotation));
  t.rotation.coeffs() *= 1.1;
  EXPECT_NE(DecodeTfMessage(testing::SerializeTf({t})).status().message().find("unit quaternion"),
            std::string::npos);
}

}  // namespace
}  // namespace carvemap
