#include "storage/import/rosbag_import.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "storage/import/rosbag_test_util.h"

namespace carvemap {
namespace {

using testing::BagWriter;

RosTransform Tf(const std::string& parent, const std::string& child, double t,
                const Eigen::Vector3d& p, double yaw = 0) {
  RosTransform tf;
  tf.header = {0, t, parent};
  tf.child_frame_id = child;
  tf.translation = p;
  tf.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  return tf;
}

RosLaserScan Scan(double stamp, const std::string& frame = "laser", int beams = 3) {
  RosLaserScan s;
  s.header = {0, stamp, frame};
  s.angle_min = -0.5f;
  s.angle_increment = 0.5f;
  s.angle_max = s.angle_min + (beams - 1) * s.angle_increment;
  s.range_min = 0.1f;
  s.range_max = 8.f;
  s.ranges.assign(beams, 2.f);
  s.ranges[0] = std::numeric_limits<float>::infinity();
  return s;
}

// map ➜ odom static, odom ➜ base_link moving along x at 1 m/s over [10, 12] s with yaw
// turning at 0.1 rad/s, base_link ➜ laser static; scans at the given stamps.
BagWriter Robot(const std::vector<double>& stamps) {
  BagWriter w;
  w.Connection(0, "/tf_static", kTfMessageType, kTfMessageMd5);
  w.Connection(1, "/tf", kTfMessageType, kTfMessageMd5);
  w.Connection(2, "/scan", kLaserScanType, kLaserScanMd5);
  w.Message(0, 10,
            testing::SerializeTf(
                {Tf("map", "odom", 0, {0, 0, 0}), Tf("base_link", "laser", 0, {0.2, 0, 0.3})}));
  for (int i = 0; i <= 4; ++i) {
    const double t = 10 + 0.5 * i;
    w.Message(1, t,
              testing::SerializeTf({Tf("odom", "base_link", t, {t - 10, 1, 0}, 0.1 * (t - 10))}));
  }
  for (double t : stamps) w.Message(2, t + 0.01, testing::SerializeLaserScan(Scan(t)));
  return w;
}

RosbagOptions Topic(const std::string& topic = "/scan") {
  RosbagOptions o;
  o.topics = {topic};
  return o;
}

// What Run gives: /path, and the frames in the order they came, each with its sensor.
struct Imported {
  std::vector<PathRecord> path;
  std::vector<ImportedFrame> frames;
  std::vector<int> sensor_of;
};

absl::StatusOr<Imported> RunAll(const RosbagImport& bag, RosbagReport* report = nullptr) {
  Imported out;
  absl::StatusOr<std::vector<PathRecord>> path = bag.Run(
      [&out](int sensor, double t, std::span<const Eigen::Vector3f> p) {
        out.frames.push_back(ImportedFrame{t, {p.begin(), p.end()}});
        out.sensor_of.push_back(sensor);
        return absl::OkStatus();
      },
      report);
  if (!path.ok()) return path.status();
  out.path = *std::move(path);
  return out;
}

TEST(RosbagImportTest, PathFromTfAtTheStampsMountingFromTfStatic) {
  Robot({9.5, 10.25, 11.0, 11.75, 12.5}).Write("robot.bag");
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("robot.bag", Topic());
  ASSERT_TRUE(bag.ok()) << bag.status();
  ASSERT_EQ(bag->sensors().size(), 1u);
  const SensorInfo& s = bag->sensors()[0];
  EXPECT_EQ(s.name, "scan");
  EXPECT_EQ(s.kind, SensorKind::kLine);
  EXPECT_TRUE(s.T_s2c.isApprox(Eigen::Vector3d(0.2, 0, 0.3)));
  EXPECT_DOUBLE_EQ(s.max_range_m, 8.0);
  RosbagReport report;
  absl::StatusOr<Imported> scan = RunAll(*bag, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(report.base_frame, "base_link");
  ASSERT_EQ(report.topics.size(), 1u);
  EXPECT_EQ(report.topics[0].topic, "/scan");
  EXPECT_EQ(report.topics[0].messages, 5u);
  EXPECT_EQ(report.topics[0].skipped_outside_tf, 2u)
      << "9.5 s and 12.5 s lie outside /tf's [10, 12] s";
  EXPECT_EQ(report.topics[0].no_return_rays, 3u);
  ASSERT_EQ(scan->path.size(), 3u);
  // At 10.25 s, between the samples at 10 and 10.5: x = 0.25, yaw 0.025 (SLERP of a turn
  // about z is linear in its angle).
  const PathRecord& p = scan->path[0];
  EXPECT_DOUBLE_EQ(p.t, 10.25);
  EXPECT_NEAR(p.x, 0.25, 1e-12);
  EXPECT_NEAR(p.y, 1.0, 1e-12);
  EXPECT_NEAR(2 * std::atan2(p.qz, p.qw), 0.025, 1e-12);
  ASSERT_EQ(scan->frames.size(), 3u);
  EXPECT_TRUE(std::isnan(scan->frames[0].points_sensor[0].x())) << "an inf range: no return";
  EXPECT_NEAR(scan->frames[0].points_sensor[1].x(), 2.0, 1e-6);  // the beam at angle 0
}

TEST(RosbagImportTest, ANamedBaseFrameCarriesThePath) {
  Robot({10.5}).Write("robot.bag");
  RosbagOptions o = Topic();
  o.base_frame = "laser";
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("robot.bag", o);
  ASSERT_TRUE(bag.ok()) << bag.status();
  EXPECT_TRUE(bag->sensors()[0].T_s2c.isZero());
  absl::StatusOr<Imported> scan = RunAll(*bag);
  ASSERT_TRUE(scan.ok()) << scan.status();
  // The laser at 0.2 m ahead of base_link, turned by 0.05 rad.
  EXPECT_NEAR(scan->path[0].x, 0.5 + 0.2 * std::cos(0.05), 1e-12);
  EXPECT_NEAR(scan->path[0].z, 0.3, 1e-12);
  // A system frame the sensor reaches only through /tf moves under it: refused.
  o.base_frame = "odom";
  absl::StatusOr<RosbagImport> moving = RosbagImport::Open("robot.bag", o);
  EXPECT_NE(moving.status().message().find("\"base_link\" moves in /tf"), std::string::npos)
      << moving.status();
}

TEST(RosbagImportTest, AllFramesOutsideTheTfSpanIsAnError) {
  Robot({8.0, 9.0}).Write("early.bag");
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("early.bag", Topic());
  ASSERT_TRUE(bag.ok()) << bag.status();
  absl::StatusOr<Imported> scan = RunAll(*bag);
  EXPECT_EQ(scan.status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(scan.status().message().find("early.bag: all 2 messages on /scan lie outside"),
            std::string::npos)
      << scan.status();
}

// Each error names the file and the message at fault.
TEST(RosbagImportTest, RefusesBagsItWouldMisread) {
  struct Case {
    std::string name;
    std::function<void(BagWriter&)> add;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"backwards", [](BagWriter& w) { w.Message(2, 12, testing::SerializeLaserScan(Scan(10.1))); },
       "(on /scan): stamp 10.1 s is not after the previous 11 s"},
      {"resized",
       [](BagWriter& w) { w.Message(2, 12, testing::SerializeLaserScan(Scan(11.5, "laser", 4))); },
       "1 × 4 rays where the first message had 1 × 3"},
      {"reframed",
       [](BagWriter& w) { w.Message(2, 12, testing::SerializeLaserScan(Scan(11.5, "base_link"))); },
       "frame \"base_link\" where the first message had \"laser\""},
      {"two_parents",
       [](BagWriter& w) {
         w.Message(0, 12, testing::SerializeTf({Tf("map", "laser", 0, {0, 0, 0})}));
       },
       "frame \"laser\" has two parents, \"base_link\" and \"map\""},
  };
  for (const Case& c : cases) {
    BagWriter w = Robot({10.5, 11.0});
    c.add(w);
    const std::string path = c.name + ".bag";
    w.Write(path);
    absl::StatusOr<RosbagImport> bag = RosbagImport::Open(path, Topic());
    EXPECT_FALSE(bag.ok()) << c.name;
    EXPECT_NE(bag.status().message().find(path + ": message "), std::string::npos) << bag.status();
    EXPECT_NE(bag.status().message().find(c.expected), std::string::npos) << bag.status();
  }
}

// A message type of the same name with another definition (its MD5) would be misread.
TEST(RosbagImportTest, RefusesAnotherDefinitionOfTheType) {
  BagWriter w;
  w.Connection(2, "/scan", kLaserScanType, "00000000000000000000000000000000");
  w.Message(2, 10, testing::SerializeLaserScan(Scan(10)));
  w.Write("old_scan.bag");
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("old_scan.bag", Topic());
  EXPECT_NE(bag.status().message().find("old_scan.bag: topic /scan says sensor_msgs/LaserScan "
                                        "with definition MD5 00000000000000000000000000000000"),
            std::string::npos)
      << bag.status();
}

TEST(RosbagImportTest, AScannerStandingStillNeedsOnlyTfStatic) {
  BagWriter w;
  w.Connection(0, "/tf_static", kTfMessageType, kTfMessageMd5);
  w.Connection(5, "/lidar/points", kPointCloud2Type, kPointCloud2Md5);
  w.Message(0, 1,
            testing::SerializeTf(
                {Tf("map", "tripod", 0, {3, 4, 0}, 0.5), Tf("tripod", "lidar", 0, {0, 0, 1.5})}));
  for (double t : {1.0, 2.0}) {
    w.Message(5, t,
              testing::SerializeCloud({0, t, "lidar"}, 1, 4,
                                      {{1, 0, 0}, {0, 2, 0}, {0, 0, 0}, {0, 0, 3}}));
  }
  w.Write("tripod.bag");
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("tripod.bag", Topic("/lidar/points"));
  ASSERT_TRUE(bag.ok()) << bag.status();
  const SensorInfo& lidar = bag->sensors()[0];
  EXPECT_EQ(lidar.name, "lidar_points");
  EXPECT_EQ(lidar.kind, SensorKind::kPoints);
  EXPECT_DOUBLE_EQ(lidar.max_range_m, 3.0);
  EXPECT_TRUE(lidar.T_s2c.isApprox(Eigen::Vector3d(3, 4, 1.5)))
      << "every link static: the system frame is the fixed frame";
  RosbagReport report;
  absl::StatusOr<Imported> scan = RunAll(*bag, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->frames.size(), 2u);
  EXPECT_EQ(report.topics[0].no_return_rays, 2u) << "the points at the sensor's origin";
  EXPECT_NEAR(scan->path[1].x, 0, 1e-12);
  EXPECT_NEAR(scan->path[1].qw, 1, 1e-12);
}

TEST(RosbagImportTest, NoChainToTheFixedFrameNamesTheBrokenLink) {
  Robot({10.5}).Write("robot.bag");
  RosbagOptions o = Topic();
  o.fixed_frame = "earth";
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("robot.bag", o);
  EXPECT_EQ(bag.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(
      bag.status().message().find(
          "robot.bag: no /tf chain from frame \"base_link\" to \"earth\": \"map\" has no parent"),
      std::string::npos)
      << bag.status();
}

// Two sensors on one body: a laser and a downward cloud, each mounted by /tf_static on
// base_link, their frames interleaved in the bag; one /path for both.
TEST(RosbagImportTest, SeveralTopicsAreSeveralSensorsOnOnePath) {
  BagWriter w = Robot({10.25, 11.0, 11.75});
  w.Connection(3, "/cloud", kPointCloud2Type, kPointCloud2Md5);
  w.Message(0, 10, testing::SerializeTf({Tf("base_link", "camera", 0, {0, 0, 1})}));
  for (double t : {10.5, 11.0, 11.5}) {  // 11.0: the laser's stamp too
    w.Message(3, t + 0.02,
              testing::SerializeCloud({0, t, "camera"}, 2, 2,
                                      {{1, 0, 0}, {1, 1, 0}, {1, 0, 1}, {1, 1, 1}}));
  }
  w.Write("two.bag");
  RosbagOptions o;
  o.topics = {"/cloud", "/scan"};
  absl::StatusOr<RosbagImport> bag = RosbagImport::Open("two.bag", o);
  ASSERT_TRUE(bag.ok()) << bag.status();
  ASSERT_EQ(bag->sensors().size(), 2u);
  EXPECT_EQ(bag->sensors()[0].name, "cloud");
  EXPECT_EQ(bag->sensors()[0].kind, SensorKind::kGrid);
  EXPECT_TRUE(bag->sensors()[0].T_s2c.isApprox(Eigen::Vector3d(0, 0, 1)));
  EXPECT_EQ(bag->sensors()[1].name, "scan");
  EXPECT_TRUE(bag->sensors()[1].T_s2c.isApprox(Eigen::Vector3d(0.2, 0, 0.3)));
  RosbagReport report;
  absl::StatusOr<Imported> scan = RunAll(*bag, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(report.base_frame, "base_link");
  ASSERT_EQ(report.topics.size(), 2u);
  EXPECT_EQ(report.topics[0].messages, 3u);
  EXPECT_EQ(report.topics[1].messages, 3u);
  ASSERT_EQ(scan->frames.size(), 6u);
  EXPECT_EQ(std::count(scan->sensor_of.begin(), scan->sensor_of.end(), 0), 3);
  // One row per distinct stamp, ascending: 10.25, 10.5, 11.0 (both), 11.5, 11.75.
  ASSERT_EQ(scan->path.size(), 5u);
  const double want[] = {10.25, 10.5, 11.0, 11.5, 11.75};
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_DOUBLE_EQ(scan->path[i].t, want[i]);
    EXPECT_NEAR(scan->path[i].x, want[i] - 10, 1e-12) << "base_link's pose at the stamp";
  }

  // Sensors hanging from different bodies need the user to name the one carrying both.
  BagWriter apart = Robot({10.5});
  apart.Connection(3, "/cloud", kPointCloud2Type, kPointCloud2Md5);
  apart.Message(
      0, 10,
      testing::SerializeTf({Tf("map", "pole", 0, {5, 0, 0}), Tf("pole", "camera", 0, {0, 0, 2})}));
  apart.Message(3, 10.5, testing::SerializeCloud({0, 10.5, "camera"}, 1, 1, {{1, 0, 0}}));
  apart.Write("apart.bag");
  o.topics = {"/scan", "/cloud"};
  absl::StatusOr<RosbagImport> refused = RosbagImport::Open("apart.bag", o);
  EXPECT_NE(refused.status().message().find("apart.bag: topic /scan hangs from \"base_link\" "
                                            "and topic /cloud from \"map\""),
            std::string::npos)
      << refused.status();
  o.topics = {"/scan", "/scan"};
  EXPECT_NE(RosbagImport::Open("two.bag", o).status().message().find("/scan given twice"),
            std::string::npos);
}

}  // namespace
}  // namespace carvemap
