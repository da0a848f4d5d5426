#include "storage/import/carmen_import.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <zlib.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "storage/import/import_writer.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

using ::testing::HasSubstr;
constexpr double kPi = std::numbers::pi;

const std::string kIntel = std::string(CARVEMAP_TEST_DATA_DIR) + "/carmen/intel-first100.log.gz";
const std::string kFreiburg =
    std::string(CARVEMAP_TEST_DATA_DIR) + "/carmen/freiburg101-first20.log.gz";

std::string WriteTemp(const std::string& name, const std::string& text) {
  const std::string path = (std::filesystem::path(::testing::TempDir()) / name).string();
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

// The whole of a (gzip) file, read with zlib's one-line API rather than the importer's reader.
std::string Gunzip(const std::string& path) {
  gzFile f = gzopen(path.c_str(), "rb");
  EXPECT_NE(f, nullptr) << path;
  std::string out;
  char buf[4096];
  int n;
  while ((n = gzread(f, buf, sizeof buf)) > 0) out.append(buf, n);
  gzclose(f);
  return out;
}

// An FLASER line as the README describes it, read with a stream: the known truth the
// importer is checked against.
struct Flaser {
  std::vector<double> r;
  double x, y, theta, t;
};

std::vector<Flaser> ReadFlaser(const std::string& path) {
  std::istringstream in(Gunzip(path));
  std::vector<Flaser> out;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string word;
    s >> word;
    if (word != "FLASER") continue;
    Flaser f;
    int n = 0;
    s >> n;
    f.r.resize(n);
    for (double& r : f.r) s >> r;
    double odom[3];
    s >> f.x >> f.y >> f.theta >> odom[0] >> odom[1] >> odom[2] >> f.t;
    EXPECT_TRUE(s) << line.substr(0, 60);
    out.push_back(std::move(f));
  }
  return out;
}

// Sensor-frame point ➜ world through the path row at the frame's time (all frames here sit
// exactly on a path row) and the sensor's T_s2c.
Eigen::Vector3d ToWorld(const PathRecord& p, const SensorInfo& s, const Eigen::Vector3f& q) {
  const Eigen::Quaterniond rot(p.qw, p.qx, p.qy, p.qz);
  return Eigen::Vector3d(p.x, p.y, p.z) + rot * (s.R_s2c * q.cast<double>() + s.T_s2c);
}

// The independent check of the README's geometry: pose ⊕ (r cos a, r sin a), a from theta − 90°.
void ExpectLogGeometry(const std::string& path, double step) {
  const std::vector<Flaser> truth = ReadFlaser(path);
  ASSERT_FALSE(truth.empty());
  CarmenOptions options;
  options.height_m = 0.45;
  CarmenReport report;
  auto scan = ImportCarmen(path, options, nullptr, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(report.laser_message, "FLASER");
  EXPECT_EQ(report.pose_message, "FLASER");
  ASSERT_EQ(scan->frame_count, truth.size());
  ASSERT_EQ(scan->frames.size(), truth.size());
  ASSERT_EQ(scan->path.size(), truth.size());
  const size_t n = truth[0].r.size();
  EXPECT_EQ(scan->point_count, truth.size() * n);
  EXPECT_EQ(scan->sensor.kind, SensorKind::kLine);
  EXPECT_EQ(scan->sensor.name, "front");

  uint64_t no_return = 0, checked = 0;
  for (size_t k = 0; k < truth.size(); ++k) {
    const Flaser& f = truth[k];
    const PathRecord& p = scan->path[k];
    EXPECT_EQ(p.t, f.t);
    EXPECT_EQ(scan->frames[k].t, f.t);
    if (k > 0) {
      EXPECT_GT(p.t, scan->path[k - 1].t);
    }
    ASSERT_EQ(scan->frames[k].points_sensor.size(), n);
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3f& q = scan->frames[k].points_sensor[i];
      if (f.r[i] >= 80.0) {
        ++no_return;
        EXPECT_TRUE(q.array().isNaN().all()) << k << " " << i;
        continue;
      }
      const double a = f.theta - kPi / 2 + double(i) * step;
      const Eigen::Vector3d expected(f.x + f.r[i] * std::cos(a), f.y + f.r[i] * std::sin(a), 0.45);
      const Eigen::Vector3d got = ToWorld(p, scan->sensor, q);
      ASSERT_LT((got - expected).norm(), 1e-5) << "frame " << k << " beam " << i;
      ++checked;
    }
  }
  EXPECT_EQ(report.no_return_rays, no_return);
  EXPECT_GT(checked, truth.size() * n / 2);

  // The first and last beams' directions in the sensor frame, on the first frame with both.
  for (size_t k = 0; k < truth.size(); ++k) {
    if (truth[k].r.front() >= 80.0 || truth[k].r.back() >= 80.0) continue;
    const auto& pts = scan->frames[k].points_sensor;
    EXPECT_NEAR(std::atan2(pts.front().y(), pts.front().x()), -kPi / 2, 1e-6);
    EXPECT_NEAR(std::atan2(pts.back().y(), pts.back().x()), -kPi / 2 + double(n - 1) * step, 1e-6);
    break;
  }
}

TEST(CarmenImportTest, IntelSliceMatchesTheLog) {
  const std::vector<Flaser> truth = ReadFlaser(kIntel);
  ASSERT_EQ(truth.size(), 100u);
  ASSERT_EQ(truth[0].r.size(), 180u);
  ExpectLogGeometry(kIntel, kPi / 180);  // 180 beams: π/n, last beam at +89°
}

TEST(CarmenImportTest, Freiburg360BeamsArePiOverNApart) {
  const std::vector<Flaser> truth = ReadFlaser(kFreiburg);
  ASSERT_EQ(truth.size(), 20u);
  ASSERT_EQ(truth[0].r.size(), 360u);
  ExpectLogGeometry(kFreiburg, kPi / 360);  // last beam at +89.5°
}

TEST(CarmenImportTest, PlainAndGzipGiveTheSameScan) {
  const std::string plain = WriteTemp("intel.log", Gunzip(kIntel));
  auto a = ImportCarmen(kIntel);
  auto b = ImportCarmen(plain);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status() << b.status();
  ASSERT_EQ(a->frames.size(), b->frames.size());
  for (size_t k = 0; k < a->frames.size(); ++k) {
    EXPECT_EQ(a->path[k].x, b->path[k].x);
    for (size_t i = 0; i < a->frames[k].points_sensor.size(); ++i) {
      const Eigen::Vector3f& p = a->frames[k].points_sensor[i];
      const Eigen::Vector3f& q = b->frames[k].points_sensor[i];
      EXPECT_TRUE(p == q || (p.array().isNaN().all() && q.array().isNaN().all()));
    }
  }
}

TEST(CarmenImportTest, WritesAScanThatValidates) {
  const std::string out = (std::filesystem::path(::testing::TempDir()) / "intel.h5").string();
  CarmenOptions options;
  auto summary = WriteImport(out, CarmenSensor(options), [&](const FrameSink& sink) {
    return ImportCarmen(kIntel, options, sink);
  });
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 100u);
  EXPECT_EQ(summary->points, 100u * 180);
  auto reader = ScanReader::Open(out);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ASSERT_TRUE((*reader)->Validate().ok()) << (*reader)->Validate();
  EXPECT_EQ((*reader)->frame_count(0), 100u);
  EXPECT_EQ((*reader)->point_count(0), 18000u);
  EXPECT_EQ((*reader)->path().size(), 100u);
  EXPECT_EQ((*reader)->sensors()[0].T_s2c, Eigen::Vector3d(0, 0, 0.3));
}

// n readings of value r, then a pose and a time, in the old format.
std::string FlaserLine(int n, double r, double x, double y, double theta, double t,
                       const char* type = "FLASER") {
  std::ostringstream s;
  s.precision(17);
  s << type << " " << n;
  for (int i = 0; i < n; ++i) s << " " << r;
  s << " " << x << " " << y << " " << theta << " 0 0 0 " << t << " host " << t << "\n";
  return s.str();
}

TEST(CarmenImportTest, OldFormatOddBeamCountsArePiOverNMinusOneApart) {
  for (int n : {181, 361}) {
    const std::string path = WriteTemp(
        "odd.log", FlaserLine(n, 2.0, 1, 2, 0.5, 10.0) + FlaserLine(n, 2.0, 1, 2, 0.5, 11.0));
    auto scan = ImportCarmen(path);
    ASSERT_TRUE(scan.ok()) << scan.status();
    const auto& pts = scan->frames[0].points_sensor;
    ASSERT_EQ(pts.size(), size_t(n));
    EXPECT_NEAR(std::atan2(pts.front().y(), pts.front().x()), -kPi / 2, 1e-6);
    EXPECT_NEAR(std::atan2(pts.back().y(), pts.back().x()), kPi / 2, 1e-6);  // the full 180°
    EXPECT_NEAR(std::atan2(pts[1].y(), pts[1].x()) + kPi / 2, kPi / (n - 1), 1e-6);
  }
}

TEST(CarmenImportTest, OldFormatWithoutLoggerTimestampIsRead) {
  std::string line = FlaserLine(180, 2.0, 1, 2, 0.5, 10.0);
  line.resize(line.rfind(' '));  // drop " 10" (logger_timestamp): the line ends with the host
  const std::string path = WriteTemp("nologger.log", line + "\n");
  auto scan = ImportCarmen(path);
  ASSERT_TRUE(scan.ok()) << scan.status();
  ASSERT_EQ(scan->frames.size(), 1u);
  EXPECT_EQ(scan->frames[0].t, 10.0);
  EXPECT_EQ(scan->path[0].x, 1.0);
}

TEST(CarmenImportTest, LeadingBlanksAndCommentsAreSkipped) {
  const std::string path =
      WriteTemp("blanks.log", "# CARMEN Logfile\n\n   " + FlaserLine(180, 2.0, 1, 2, 0.5, 10.0) +
                                  "\t" + FlaserLine(180, 2.0, 1, 2, 0.5, 11.0));
  auto scan = ImportCarmen(path);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->frames.size(), 2u);
}

TEST(CarmenImportTest, RearLaserIsItsOwnSensor) {
  const std::string path =
      WriteTemp("rear.log", FlaserLine(180, 1.0, 0, 0, 0, 1.0) +
                                FlaserLine(180, 1.0, 0, 0, kPi, 1.05, "RLASER") +
                                FlaserLine(180, 1.0, 0, 0, 0, 2.0));
  CarmenOptions options;
  options.laser = 2;
  auto scan = ImportCarmen(path, options);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->sensor.name, "rear");
  ASSERT_EQ(scan->frames.size(), 1u);
  EXPECT_EQ(scan->frames[0].t, 1.05);
  auto front = ImportCarmen(path);
  ASSERT_TRUE(front.ok()) << front.status();
  EXPECT_EQ(front->frames.size(), 2u);
}

// A ROBOTLASER1 line per the CARMEN header: 5 readings from start −1.0 rad, 0.25 rad apart,
// the line's max range 4 m; the laser pose differs from the robot pose.
std::string RobotLaserLine(double t, bool remission_mode) {
  std::ostringstream s;
  s << "ROBOTLASER1 0 -1.0 1.0 0.25 4.0 0.01 " << (remission_mode ? "0 " : "") << "5 1.0 2.0 4.0 "
    << "3.5 0 2 0.5 0.5 "
    << "10.0 20.0 1.2 9.8 20.0 1.2 0.1 0.0 0.5 0.3 0.0 " << t << " host " << t << "\n";
  return s.str();
}

TEST(CarmenImportTest, RobotLaserUsesItsAnglesAndLaserPose) {
  for (bool remission_mode : {true, false}) {
    const std::string path = WriteTemp(
        "robot.log", "# CARMEN Logfile\nODOM 0 0 0 0 0 0 0.5 host 0.5\n" +
                         RobotLaserLine(1.0, remission_mode) + RobotLaserLine(2.0, remission_mode));
    CarmenReport report;
    auto scan = ImportCarmen(path, {}, nullptr, &report);
    ASSERT_TRUE(scan.ok()) << scan.status();
    EXPECT_EQ(report.laser_message, "ROBOTLASER1");
    ASSERT_EQ(scan->frames.size(), 2u);
    ASSERT_EQ(scan->path.size(), 2u);  // the ODOM line is not the path when lines carry poses
    const PathRecord& p = scan->path[0];
    EXPECT_EQ(p.x, 10.0);
    EXPECT_EQ(p.y, 20.0);
    EXPECT_NEAR(2 * std::atan2(p.qz, p.qw), 1.2, 1e-12);
    const auto& pts = scan->frames[0].points_sensor;
    ASSERT_EQ(pts.size(), 5u);
    const double r[5] = {1.0, 2.0, 4.0, 3.5, 0};
    for (int i = 0; i < 5; ++i) {
      if (i == 2 || i == 4) {  // 4.0 ≥ the line's max range; 0 = nothing measured
        EXPECT_TRUE(pts[i].array().isNaN().all()) << i;
        continue;
      }
      const double a = -1.0 + 0.25 * i;
      EXPECT_NEAR(pts[i].x(), r[i] * std::cos(a), 1e-6) << i;
      EXPECT_NEAR(pts[i].y(), r[i] * std::sin(a), 1e-6) << i;
      EXPECT_EQ(pts[i].z(), 0.0f);
    }
    EXPECT_EQ(report.no_return_rays, 4u);
  }
}

std::string RawLaserLine(int id, double t) {
  std::ostringstream s;
  s << "RAWLASER" << id << " 0 -1.5707963267948966 3.14159 1.5707963267948966 50 0.01 0 3 "
    << "1.0 2.0 3.0 0 " << t << " host " << t << "\n";
  return s.str();
}

TEST(CarmenImportTest, RawLaserTakesItsPoseFromOdometry) {
  const std::string path = WriteTemp(
      "raw.log", RawLaserLine(1, 0.5) +  // before any pose: skipped
                     "ODOM 0 0 0 0 0 0 1.0 host 1.0\n" + RawLaserLine(1, 1.5) +
                     RawLaserLine(2, 1.6) + "ODOM 2 0 1.5707963267948966 0 0 0 2.0 host 2.0\n" +
                     RawLaserLine(1, 2.5));  // after the last pose: skipped
  CarmenReport report;
  auto scan = ImportCarmen(path, {}, nullptr, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(report.laser_message, "RAWLASER1");
  EXPECT_EQ(report.pose_message, "ODOM");
  EXPECT_EQ(report.skipped_outside_poses, 2u);
  ASSERT_EQ(scan->path.size(), 2u);
  EXPECT_EQ(scan->path[1].x, 2.0);
  ASSERT_EQ(scan->frames.size(), 1u);
  EXPECT_EQ(scan->frames[0].t, 1.5);
  const auto& pts = scan->frames[0].points_sensor;
  ASSERT_EQ(pts.size(), 3u);
  // Beams at −90°, 0°, +90° from the laser's heading.
  EXPECT_NEAR(pts[0].y(), -1.0, 1e-6);
  EXPECT_NEAR(pts[1].x(), 2.0, 1e-6);
  EXPECT_NEAR(pts[2].y(), 3.0, 1e-6);

  // The scan written and read back: the frame at 1.5 s lies halfway along the odometry.
  const std::string out = (std::filesystem::path(::testing::TempDir()) / "raw.h5").string();
  auto summary = WriteImport(out, CarmenSensor(),
                             [&](const FrameSink& sink) { return ImportCarmen(path, {}, sink); });
  ASSERT_TRUE(summary.ok()) << summary.status();
  auto reader = ScanReader::Open(out);
  ASSERT_TRUE(reader.ok());
  EXPECT_TRUE((*reader)->Validate().ok());
}

TEST(CarmenImportTest, RobotLaserWinsOverTheSameScansAsRawLaser) {
  const std::string path =
      WriteTemp("both.log", RawLaserLine(1, 0.9) + RobotLaserLine(1.0, true) +
                                RawLaserLine(1, 1.9) + RobotLaserLine(2.0, true));
  CarmenReport report;
  auto scan = ImportCarmen(path, {}, nullptr, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(report.laser_message, "ROBOTLASER1");
  EXPECT_EQ(report.ignored_laser_lines, 2u);
  EXPECT_EQ(scan->frames.size(), 2u);
}

// Each bad input: an error naming the file, the line and what is wrong.
void ExpectError(const std::string& name, const std::string& text, const std::string& line,
                 const std::string& what, const CarmenOptions& options = {}) {
  const std::string path = WriteTemp(name, text);
  auto scan = ImportCarmen(path, options);
  ASSERT_FALSE(scan.ok()) << name;
  const std::string message(scan.status().message());
  EXPECT_THAT(message, HasSubstr(path));
  if (!line.empty()) {
    EXPECT_THAT(message, HasSubstr(line + ": "));
  }
  EXPECT_THAT(message, HasSubstr(what));

  // And WriteImport leaves no scan.h5 behind.
  const std::string out = (std::filesystem::path(::testing::TempDir()) / (name + ".h5")).string();
  auto summary = WriteImport(out, CarmenSensor(options), [&](const FrameSink& sink) {
    return ImportCarmen(path, options, sink);
  });
  EXPECT_FALSE(summary.ok());
  EXPECT_FALSE(std::filesystem::exists(out)) << out;
}

TEST(CarmenImportTest, BadLinesAreNamed) {
  const std::string good = FlaserLine(180, 1.0, 0, 0, 0, 1.0);
  std::string cut = FlaserLine(180, 1.0, 0, 0, 0, 2.0);
  cut.resize(cut.size() / 2);
  ExpectError("cut.log", good + cut, "line 2", "cut short");
  std::string fewer = FlaserLine(180, 1.0, 0, 0, 0, 2.0);
  fewer.replace(0, 10, "FLASER 181");  // says 181 readings, holds 180
  ExpectError("count.log", good + fewer, "line 2", "wrong count of readings");
  std::string word = FlaserLine(180, 1.0, 0, 0, 0, 2.0);
  word.replace(word.find(" 1 "), 3, " x1 ");
  ExpectError("word.log", good + word, "line 2", "'x1' is not a finite number");
  ExpectError("nan.log", good + FlaserLine(180, 1.0, 0, 0, NAN, 2.0), "line 2",
              "is not a finite number");
  ExpectError("back.log", good + FlaserLine(180, 1.0, 0, 0, 0, 0.5), "line 2",
              "time 0.5 is not after the previous one's 1 (line 1)");
  ExpectError("same.log", good + FlaserLine(180, 1.0, 0, 0, 0, 1.0), "line 2",
              "is not after the previous");
  ExpectError("beams.log", FlaserLine(100, 1.0, 0, 0, 0, 1.0), "line 1",
              "known only for 180, 181, 360 or 361 readings");
  ExpectError("change.log", good + FlaserLine(360, 1.0, 0, 0, 0, 2.0), "line 2",
              "360 readings, but the earlier lines of this laser have 180");
  ExpectError("neg.log", FlaserLine(180, -1.0, 0, 0, 0, 1.0), "line 1", "negative");
  ExpectError("nolaser.log", "# CARMEN Logfile\nODOM 0 0 0 0 0 0 1 host 1\nPARAM a b host 0\n", "",
              "no lines of laser 1");
  ExpectError("otherlaser.log", FlaserLine(180, 1.0, 0, 0, 0, 1.0, "RLASER"), "",
              "the log has RLASER");
  ExpectError("empty.log", "", "", "no lines of laser 1");
  ExpectError("robot.log", RobotLaserLine(1.0, true).substr(0, 60) + "\n", "line 1", "cut short");
  ExpectError("rawnoodom.log", RawLaserLine(1, 1.0), "", "no ODOM lines");
  ExpectError("odomback.log",
              "ODOM 0 0 0 0 0 0 2 host 2\nODOM 0 0 0 0 0 0 1 host 1\n" + RawLaserLine(1, 1.5),
              "line 2", "ODOM time 1 is not after");
}

TEST(CarmenImportTest, MissingFileIsNamed) {
  const std::string path = (std::filesystem::path(::testing::TempDir()) / "none.log.gz").string();
  auto scan = ImportCarmen(path);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr(path));
  EXPECT_THAT(scan.status().message(), HasSubstr("cannot open"));
}

TEST(CarmenImportTest, BackwardTimesCanBeSkipped) {
  const std::string path = WriteTemp(
      "skip.log", FlaserLine(180, 1.0, 0, 0, 0, 1.0) + FlaserLine(180, 1.0, 0, 0, 0, 0.9) +
                      FlaserLine(180, 1.0, 0, 0, 0, 1.0) + FlaserLine(180, 1.0, 0, 0, 0, 2.0));
  CarmenOptions options;
  options.skip_backward_times = true;
  CarmenReport report;
  auto scan = ImportCarmen(path, options, nullptr, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->frames.size(), 2u);
  EXPECT_EQ(report.skipped_backward, 2u);
  EXPECT_EQ(report.first_skipped_line, 2);
}

TEST(CarmenImportTest, CutGzipIsNamed) {
  std::ifstream in(kIntel, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string path = WriteTemp("cut.log.gz", bytes.substr(0, bytes.size() / 2));
  auto scan = ImportCarmen(path);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr(path));
  EXPECT_THAT(scan.status().message(), HasSubstr("cut short"));
}

TEST(CarmenImportTest, BadOptionsAreRejected) {
  CarmenOptions options;
  options.laser = 5;
  EXPECT_FALSE(ImportCarmen(kIntel, options).ok());
  options = {};
  options.max_range_m = 0;
  EXPECT_FALSE(ImportCarmen(kIntel, options).ok());
}

}  // namespace
}  // namespace carvemap
