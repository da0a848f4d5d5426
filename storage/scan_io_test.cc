// Round trips through ScanWriter and ScanReader (docs/DESIGN.md §3), streaming order and block
// boundaries, pose interpolation, the .partial protocol and byte-identical output.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "storage/scan_reader.h"
#include "storage/scan_writer.h"

namespace carvemap {
namespace {

using ::testing::HasSubstr;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// A fresh directory per test under gtest's temp dir (parameterized names hold '/').
std::string TempPath(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string test = std::string(info->test_suite_name()) + "." + info->name();
  std::replace(test.begin(), test.end(), '/', '_');
  const std::string dir = ::testing::TempDir() + "carvemap_scan_io_test/" + test;
  std::filesystem::create_directories(dir);
  return dir + "/" + name;
}

std::vector<PathRecord> MakePath(int n, double dt) {
  std::vector<PathRecord> path;
  for (int i = 0; i < n; ++i) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitZ()));
    path.push_back({i * dt, 0.5 * i, 0.1 * i, 1.5, q.w(), q.x(), q.y(), q.z()});
  }
  return path;
}

std::vector<PathCovariance> MakeCov(int n) {
  std::vector<PathCovariance> cov(n);
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < 12; ++k) cov[i][k] = 0.001f * (i + 1) + 0.0001f * k;
  }
  return cov;
}

SensorInfo MakeSensor(const std::string& name, SensorKind kind, uint32_t rows = 0,
                      uint32_t cols = 0) {
  SensorInfo info;
  info.name = name;
  info.kind = kind;
  info.rows = rows;
  info.cols = cols;
  info.R_s2c = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  info.T_s2c = Eigen::Vector3d(0.1, -0.2, 0.3);
  info.sigma_t_s = 0.002;
  info.range_sigma = {0.01, 0.002};
  info.max_range_m = 25.0;
  return info;
}

std::vector<Eigen::Vector3f> MakePoints(int n, float seed) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < n; ++i) points.emplace_back(seed + i, -seed * 0.5f, 0.25f * i);
  return points;
}

// The frames written, to compare with what is read.
struct WrittenFrame {
  int sensor;
  double t;
  std::vector<Eigen::Vector3f> points;
};

bool SamePoints(const std::vector<Eigen::Vector3f>& a, const std::vector<Eigen::Vector3f>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const bool both_nan = std::isnan(a[i][k]) && std::isnan(b[i][k]);
      if (!both_nan && a[i][k] != b[i][k]) return false;
    }
  }
  return true;
}

std::vector<ScanFrame> StreamAll(ScanReader& reader, size_t block_bytes) {
  std::vector<ScanFrame> frames;
  auto stream = reader.StreamFrames(block_bytes);
  ScanFrame frame;
  while (true) {
    absl::StatusOr<bool> more = stream->Next(frame);
    EXPECT_TRUE(more.ok()) << more.status();
    if (!more.ok() || !*more) break;
    frames.push_back(frame);
  }
  return frames;
}

// A scan with all three sensor kinds; frames interleave in time, one tie across sensors.
std::vector<WrittenFrame> WriteScan(const std::string& path, bool with_cov, bool with_mag) {
  auto writer = ScanWriter::Create(path);
  EXPECT_TRUE(writer.ok()) << writer.status();
  ScanWriter& w = **writer;
  const std::vector<PathRecord> poses = MakePath(11, 1.0);
  const std::vector<PathCovariance> cov = MakeCov(11);
  // Two calls: appends continue across calls.
  EXPECT_TRUE(w.AppendPath(std::span(poses).first(4),
                           with_cov ? std::span(cov).first(4) : std::span<PathCovariance>())
                  .ok());
  const int line = *w.AddSensor(MakeSensor("h0", SensorKind::kLine));
  const int grid = *w.AddSensor(MakeSensor("cam", SensorKind::kGrid, 2, 3));
  std::vector<WrittenFrame> frames;
  auto add = [&](int sensor, double t, std::vector<Eigen::Vector3f> pts) {
    EXPECT_TRUE(w.AppendFrame(sensor, t, pts).ok());
    frames.push_back({sensor, t, std::move(pts)});
  };
  std::vector<Eigen::Vector3f> with_nan = MakePoints(5, 1.0f);
  with_nan[2] = Eigen::Vector3f(kNaN, kNaN, kNaN);
  add(line, 0.5, with_nan);
  add(grid, 0.5, MakePoints(6, 2.0f));  // same time as the line frame: sensor index breaks it
  add(line, 1.5, MakePoints(5, 3.0f));
  // A sensor added after frames were written.
  const int cloud = *w.AddSensor(MakeSensor("cloud", SensorKind::kPoints));
  add(cloud, 1.0, MakePoints(7, 4.0f));
  add(cloud, 2.0, {});
  add(grid, 2.5, MakePoints(6, 5.0f));
  add(cloud, 3.0, MakePoints(2, 6.0f));
  EXPECT_TRUE(w.AppendPath(std::span(poses).subspan(4),
                           with_cov ? std::span(cov).subspan(4) : std::span<PathCovariance>())
                  .ok());
  if (with_mag) {
    const std::vector<MagnetometerRecord> mag = {{0.0, 1, 2, 3}, {1.0, 4, 5, 6}};
    EXPECT_TRUE(w.AppendMagnetometer(mag).ok());
  }
  EXPECT_TRUE(w.Close().ok());
  return frames;
}

class RoundTripTest : public ::testing::TestWithParam<std::tuple<bool, bool>> {};

TEST_P(RoundTripTest, EverySensorKind) {
  const auto [with_cov, with_mag] = GetParam();
  const std::string path = TempPath("scan.h5");
  const std::vector<WrittenFrame> written = WriteScan(path, with_cov, with_mag);
  ASSERT_TRUE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));

  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ScanReader& r = **reader;
  EXPECT_TRUE(r.Validate().ok()) << r.Validate();
  EXPECT_EQ(r.file(), path);

  const std::vector<PathRecord> poses = MakePath(11, 1.0);
  ASSERT_EQ(r.path().size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(r.path()[i].t, poses[i].t);
    EXPECT_EQ(r.path()[i].x, poses[i].x);
    EXPECT_EQ(r.path()[i].qz, poses[i].qz);
  }
  EXPECT_EQ(r.path_covariance().has_value(), with_cov);
  if (with_cov) {
    EXPECT_EQ(*r.path_covariance(), MakeCov(11));
  }
  EXPECT_EQ(r.magnetometer().has_value(), with_mag);
  if (with_mag) {
    ASSERT_EQ(r.magnetometer()->size(), 2u);
    EXPECT_EQ((*r.magnetometer())[1].my, 5.0);
  }

  // Sensors come back in the order they were added, with their attributes.
  ASSERT_EQ(r.sensors().size(), 3u);
  const std::vector<SensorInfo> expected = {MakeSensor("h0", SensorKind::kLine),
                                            MakeSensor("cam", SensorKind::kGrid, 2, 3),
                                            MakeSensor("cloud", SensorKind::kPoints)};
  for (size_t i = 0; i < expected.size(); ++i) {
    const SensorInfo& s = r.sensors()[i];
    EXPECT_EQ(s.name, expected[i].name);
    EXPECT_EQ(s.kind, expected[i].kind);
    EXPECT_EQ(s.rows, expected[i].rows);
    EXPECT_EQ(s.cols, expected[i].cols);
    EXPECT_TRUE(s.R_s2c.isApprox(expected[i].R_s2c, 0));
    EXPECT_EQ(s.T_s2c, expected[i].T_s2c);
    EXPECT_EQ(s.sigma_t_s, expected[i].sigma_t_s);
    EXPECT_EQ(s.range_sigma, expected[i].range_sigma);
    EXPECT_EQ(s.max_range_m, expected[i].max_range_m);
  }
  EXPECT_EQ(r.frame_count(0), 2u);
  EXPECT_EQ(r.point_count(0), 10u);
  EXPECT_EQ(r.frame_count(2), 3u);
  EXPECT_EQ(r.point_count(2), 9u);

  // Random access: every written frame, NaN rows kept.
  std::vector<uint64_t> next_row(3, 0);
  for (const WrittenFrame& f : written) {
    auto frame = r.ReadFrame(f.sensor, next_row[f.sensor]++);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->t, f.t);
    EXPECT_TRUE(SamePoints(frame->points_sensor, f.points));
  }
  EXPECT_FALSE(r.ReadFrame(0, 2).ok());
  EXPECT_FALSE(r.ReadFrame(3, 0).ok());
}

INSTANTIATE_TEST_SUITE_P(CovAndMagnetometer, RoundTripTest,
                         ::testing::Combine(::testing::Bool(), ::testing::Bool()));

TEST(ScanStreamTest, GlobalTimeOrderAcrossSensors) {
  const std::string path = TempPath("scan.h5");
  const std::vector<WrittenFrame> written = WriteScan(path, false, false);
  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status();
  const std::vector<ScanFrame> frames = StreamAll(**reader, 4 << 20);
  ASSERT_EQ(frames.size(), written.size());
  const std::vector<std::pair<int, double>> expected_order = {
      {0, 0.5}, {1, 0.5}, {2, 1.0}, {0, 1.5}, {2, 2.0}, {1, 2.5}, {2, 3.0}};
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].sensor, expected_order[i].first) << i;
    EXPECT_EQ(frames[i].t, expected_order[i].second) << i;
  }
  EXPECT_EQ(frames[0].row, 0u);
  EXPECT_EQ(frames[3].row, 1u);
  EXPECT_TRUE(std::isnan(frames[0].points_sensor[2].x()));
}

// Many frames of varying sizes in three sensors, written with random times and read with a
// tiny block budget (a block boundary at nearly every frame) and a large one.
// Row ranges: exactly the frames of those rows, in the same merged order as the whole stream;
// bad ranges are refused. FrameRecords gives every row.
TEST(ScanStreamTest, RowRangesStreamThoseRows) {
  const std::string path = TempPath("scan.h5");
  WriteScan(path, false, false);
  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status();
  const std::vector<ScanFrame> all = StreamAll(**reader, 4 << 20);
  const std::vector<ScanReader::RowRange> rows = {{1, 2}, {0, 0}, {1, 3}};
  auto stream = (*reader)->StreamFrames(rows);
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::vector<ScanFrame> got;
  ScanFrame f;
  while (true) {
    absl::StatusOr<bool> more = (*stream)->Next(f);
    ASSERT_TRUE(more.ok()) << more.status();
    if (!*more) break;
    got.push_back(f);
  }
  std::vector<ScanFrame> want;
  for (const ScanFrame& a : all) {
    if (a.row >= rows[a.sensor].begin && a.row < rows[a.sensor].end) want.push_back(a);
  }
  ASSERT_EQ(got.size(), want.size());
  ASSERT_EQ(got.size(), 3u);
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].sensor, want[i].sensor);
    EXPECT_EQ(got[i].row, want[i].row);
    EXPECT_EQ(got[i].t, want[i].t);
    EXPECT_TRUE(SamePoints(got[i].points_sensor, want[i].points_sensor));
  }
  const std::vector<ScanReader::RowRange> past = {{0, 3}, {0, 0}, {0, 0}};
  EXPECT_EQ((*reader)->StreamFrames(past).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ((*reader)->StreamFrames(std::span(rows).first(2)).status().code(),
            absl::StatusCode::kInvalidArgument);
  auto records = (*reader)->FrameRecords(2);
  ASSERT_TRUE(records.ok()) << records.status();
  ASSERT_EQ(records->size(), 3u);
  EXPECT_EQ((*records)[0].t, 1.0);
  EXPECT_EQ((*records)[2].t, 3.0);
  EXPECT_EQ((*records)[1].first, (*records)[0].first + (*records)[0].count);
  EXPECT_FALSE((*reader)->FrameRecords(3).ok());
}

TEST(ScanStreamTest, TinyBlockBudgetGivesTheSameFrames) {
  const std::string path = TempPath("scan.h5");
  std::mt19937 rng(301);
  {
    auto writer = ScanWriter::Create(path);
    ASSERT_TRUE(writer.ok()) << writer.status();
    ASSERT_TRUE((*writer)->AppendPath(MakePath(101, 1.0)).ok());
    const int a = *(*writer)->AddSensor(MakeSensor("a", SensorKind::kLine));
    const int b = *(*writer)->AddSensor(MakeSensor("b", SensorKind::kPoints));
    const int c = *(*writer)->AddSensor(MakeSensor("c", SensorKind::kGrid, 4, 5));
    double ta = 0, tb = 0, tc = 0;
    for (int i = 0; i < 600; ++i) {
      const int pick = static_cast<int>(rng() % 3);
      const double step = (rng() % 4 + 1) * 0.01;  // coarse steps: ties across sensors happen
      absl::Status s;
      if (pick == 0) s = (*writer)->AppendFrame(a, ta += step, MakePoints(300, i));
      if (pick == 1) s = (*writer)->AppendFrame(b, tb += step, MakePoints(rng() % 50, i));
      if (pick == 2) s = (*writer)->AppendFrame(c, tc += step, MakePoints(20, i));
      ASSERT_TRUE(s.ok()) << s;
    }
    ASSERT_TRUE((*writer)->Close().ok());
  }
  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ASSERT_TRUE((*reader)->Validate().ok()) << (*reader)->Validate();
  const std::vector<ScanFrame> large = StreamAll(**reader, 64 << 20);
  const std::vector<ScanFrame> tiny = StreamAll(**reader, 1);
  const std::vector<ScanFrame> small = StreamAll(**reader, 1000);
  ASSERT_EQ(large.size(), 600u);
  ASSERT_EQ(tiny.size(), large.size());
  ASSERT_EQ(small.size(), large.size());
  for (size_t i = 0; i < large.size(); ++i) {
    for (const auto* other : {&tiny[i], &small[i]}) {
      EXPECT_EQ(other->sensor, large[i].sensor);
      EXPECT_EQ(other->row, large[i].row);
      EXPECT_EQ(other->t, large[i].t);
      EXPECT_TRUE(SamePoints(other->points_sensor, large[i].points_sensor));
    }
    if (i > 0) {
      const auto key = [](const ScanFrame& f) { return std::tuple(f.t, f.sensor, f.row); };
      EXPECT_LT(key(large[i - 1]), key(large[i]));
    }
    auto direct = (*reader)->ReadFrame(large[i].sensor, large[i].row);
    ASSERT_TRUE(direct.ok());
    EXPECT_TRUE(SamePoints(direct->points_sensor, large[i].points_sensor));
  }
}

TEST(ScanReaderTest, PoseAtInterpolates) {
  const std::string path = TempPath("scan.h5");
  WriteScan(path, false, false);
  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status();
  const Pose mid = (*reader)->PoseAt(2.25);
  EXPECT_TRUE(mid.translation.isApprox(Eigen::Vector3d(1.125, 0.225, 1.5), 1e-12));
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(0.225, Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(mid.rotation.angularDistance(expected), 0.0, 1e-9);
  // Clamped at the ends.
  EXPECT_TRUE((*reader)->PoseAt(-5).translation.isApprox(Eigen::Vector3d(0, 0, 1.5)));
  EXPECT_TRUE((*reader)->PoseAt(99).translation.isApprox(Eigen::Vector3d(5, 1, 1.5)));
}

// Only the poses around some frames: the same poses, covariances and angular velocities at
// those frames' times as from the whole path, from fewer rows.
TEST(ScanReaderTest, PathAroundFramesGivesTheSamePoses) {
  const std::string path = TempPath("scan.h5");
  WriteScan(path, true, true);
  auto whole = ScanReader::Open(path);
  ASSERT_TRUE(whole.ok()) << whole.status();
  ScanReader::OpenOptions options;
  options.path_rows = ScanReader::PathRows::kFrames;
  // h0 row 1 (t 1.5), cam row 1 (2.5), cloud row 0 (1.0).
  options.frame_rows = {{1, 2}, {1, 2}, {0, 1}};
  auto part = ScanReader::Open(path, options);
  ASSERT_TRUE(part.ok()) << part.status();
  const std::vector<TimedPose>& poses = (*part)->timed_path();
  ASSERT_EQ(poses.size(), 5u);  // t 0..4: one row more either way of [1, 3]
  EXPECT_EQ(poses.front().t, 0.0);
  EXPECT_EQ(poses.back().t, 4.0);
  ASSERT_TRUE((*part)->path_covariance().has_value());
  EXPECT_EQ((*part)->path_covariance()->size(), poses.size());
  EXPECT_EQ((*part)->path_covariance()->front(), (*whole)->path_covariance()->at(0));
  EXPECT_FALSE((*part)->magnetometer().has_value());
  for (double t : {1.0, 1.5, 2.0, 2.5}) {
    const Pose a = (*whole)->PoseAt(t), b = (*part)->PoseAt(t);
    EXPECT_EQ(a.translation, b.translation) << t;
    EXPECT_EQ(a.rotation.coeffs(), b.rotation.coeffs()) << t;
  }
  // Near the path's start the rows begin at its first pose; a wrong count of ranges is an error.
  options.frame_rows = {{0, 1}, {0, 0}, {0, 0}};  // t 0.5
  auto head = ScanReader::Open(path, options);
  ASSERT_TRUE(head.ok()) << head.status();
  ASSERT_EQ((*head)->timed_path().size(), 3u);
  EXPECT_EQ((*head)->timed_path().front().t, 0.0);
  EXPECT_EQ((*head)->PoseAt(0.5).translation, (*whole)->PoseAt(0.5).translation);
  options.frame_rows = {{0, 1}};
  EXPECT_THAT(ScanReader::Open(path, options).status().message(), HasSubstr("3 sensors"));
  // No path at all: frames still stream, and Validate still reads the path's rows.
  options.path_rows = ScanReader::PathRows::kNone;
  auto none = ScanReader::Open(path, options);
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_TRUE((*none)->timed_path().empty());
  EXPECT_EQ((*none)->FrameRecords(0)->size(), 2u);
  EXPECT_TRUE((*none)->Validate().ok());
  // The positions alone are still read whole, from the file, not from what Open kept.
  absl::StatusOr<std::vector<Eigen::Vector3d>> positions = (*none)->PathPositions();
  ASSERT_TRUE(positions.ok()) << positions.status();
  ASSERT_EQ(positions->size(), (*whole)->path().size());
  for (size_t i = 0; i < positions->size(); ++i) {
    const PathRecord& r = (*whole)->path()[i];
    EXPECT_EQ((*positions)[i], Eigen::Vector3d(r.x, r.y, r.z)) << i;
  }
  // So is the horizontal position error: the RMS of √((xx + yy) / 2) over every pose.
  double sum = 0;
  for (const PathCovariance& c : *(*whole)->path_covariance()) sum += 0.5 * (double(c[0]) + c[3]);
  absl::StatusOr<std::optional<double>> sigma = (*none)->HorizontalPositionSigma();
  ASSERT_TRUE(sigma.ok()) << sigma.status();
  ASSERT_TRUE(sigma->has_value());
  EXPECT_GT(**sigma, 0);
  EXPECT_NEAR(**sigma, std::sqrt(sum / (*whole)->path_covariance()->size()), 1e-9);
  const std::string bare = TempPath("bare.h5");
  WriteScan(bare, false, false);
  auto without = ScanReader::Open(bare);
  ASSERT_TRUE(without.ok()) << without.status();
  sigma = (*without)->HorizontalPositionSigma();
  ASSERT_TRUE(sigma.ok()) << sigma.status();
  EXPECT_FALSE(sigma->has_value());
}

TEST(ScanWriterTest, NoFileWhenNotClosed) {
  const std::string path = TempPath("scan.h5");
  {
    auto writer = ScanWriter::Create(path);
    ASSERT_TRUE(writer.ok()) << writer.status();
    ASSERT_TRUE((*writer)->AppendPath(MakePath(3, 1.0)).ok());
    EXPECT_TRUE(std::filesystem::exists(path + ".partial"));
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(ScanWriterTest, SameContentGivesSameBytes) {
  const std::string a = TempPath("a.h5");
  const std::string b = TempPath("b.h5");
  WriteScan(a, true, true);
  // Object time stamps have a one-second resolution: make sure they would differ.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  WriteScan(b, true, true);
  const std::string bytes_a = ReadBytes(a);
  EXPECT_GT(bytes_a.size(), 0u);
  EXPECT_TRUE(bytes_a == ReadBytes(b));
}

TEST(ScanWriterTest, RejectsBadArguments) {
  const std::string path = TempPath("scan.h5");
  auto writer = ScanWriter::Create(path);
  ASSERT_TRUE(writer.ok()) << writer.status();
  ScanWriter& w = **writer;
  const std::vector<PathRecord> poses = MakePath(5, 1.0);
  ASSERT_TRUE(w.AppendPath(std::span(poses).first(3)).ok());
  // Path time must keep ascending across calls.
  absl::Status s = w.AppendPath(std::span(poses).first(2));
  EXPECT_THAT(s.message(), HasSubstr("/path row 3"));
  // Covariances for all poses or none.
  const std::vector<PathCovariance> cov = MakeCov(2);
  EXPECT_FALSE(w.AppendPath(std::span(poses).subspan(3), cov).ok());

  const int grid = *w.AddSensor(MakeSensor("cam", SensorKind::kGrid, 2, 2));
  s = w.AppendFrame(grid, 0.5, MakePoints(3, 0));
  EXPECT_THAT(s.message(), HasSubstr("/sensors/cam/frames row 0"));
  EXPECT_THAT(s.message(), HasSubstr("expected 2x2"));
  EXPECT_TRUE(w.AppendFrame(grid, 0.5, MakePoints(4, 0)).ok());
  EXPECT_FALSE(w.AppendFrame(grid, 0.5, MakePoints(4, 0)).ok());  // time not ascending
  EXPECT_THAT(w.AppendFrame(7, 1.0, {}).message(), HasSubstr("unknown sensor index 7"));
  EXPECT_FALSE(w.AppendFrame(-1, 1.0, {}).ok());

  EXPECT_THAT(w.AddSensor(MakeSensor("cam", SensorKind::kLine)).status().message(),
              HasSubstr("already added"));
  for (const char* bad : {"", "a/b", "."}) {
    EXPECT_FALSE(w.AddSensor(MakeSensor(bad, SensorKind::kLine)).ok()) << bad;
  }
  EXPECT_FALSE(w.AddSensor(MakeSensor("g", SensorKind::kGrid, 0, 3)).ok());
  EXPECT_TRUE(w.AddSensor(MakeSensor("late", SensorKind::kPoints)).ok());
  ASSERT_TRUE(w.Close().ok());
  EXPECT_EQ(w.Close().code(), absl::StatusCode::kFailedPrecondition);
}

TEST(ScanReaderTest, MissingFileIsNotFound) {
  auto reader = ScanReader::Open(TempPath("nothing.h5"));
  EXPECT_EQ(reader.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(reader.status().message(), HasSubstr("nothing.h5"));
}

}  // namespace
}  // namespace carvemap
