#include "storage/import/las_import.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "storage/import/las_reader.h"

namespace carvemap {
namespace {

// Half a second of a mobile mapper's survey of a corridor (tests/tools/make_las.py; its
// headers and points agree with independent readers from the npm registry): the box
// [0, 20] × [0, 8] × [0, 3] m placed at (500000, 4100000, 100) in the LAS frame, a profiler at
// p(s) = (2 + 1.5 s, 4 + 0.5 sin(s / 4), 1.8), yaw 0.05 s rad, s seconds after GPS time 1e8,
// 100 profiles of 90 beams a second.
const std::string kDir = std::string(CARVEMAP_TEST_DATA_DIR) + "/las";
const Eigen::Vector3d kScene(500000, 4100000, 100);
constexpr double kT0 = 1.0e8;

Eigen::Vector3d TruePosition(double t) {
  const double s = t - kT0;
  return Eigen::Vector3d(2 + 1.5 * s, 4 + 0.5 * std::sin(s / 4), 1.8);
}

bool OnTheBox(const Eigen::Vector3d& p, double tol) {
  const Eigen::Vector3d box(20, 8, 3);
  bool inside = true, on_face = false;
  for (int d = 0; d < 3; ++d) {
    inside = inside && p[d] > -tol && p[d] < box[d] + tol;
    on_face = on_face || std::abs(p[d]) < tol || std::abs(p[d] - box[d]) < tol;
  }
  return inside && on_face;
}

std::vector<char> Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

std::string Write(const std::vector<char>& b, const std::string& name) {
  std::ofstream(name, std::ios::binary).write(b.data(), static_cast<std::streamsize>(b.size()));
  return name;
}

LasImportOptions Options() {
  LasImportOptions o;
  o.trajectory = kDir + "/corridor_trajectory.txt";
  return o;
}

class LasImportFormats : public ::testing::TestWithParam<const char*> {};

TEST_P(LasImportFormats, EveryPointsRayStartsOnTheTrajectoryAndEndsOnTheWalls) {
  const std::string file = kDir + "/" + GetParam();
  absl::StatusOr<LasReader> reader = LasReader::Open(file);
  ASSERT_TRUE(reader.ok()) << reader.status();
  std::vector<LasPoint> all, batch;
  do {
    ASSERT_TRUE(reader->Next(batch, 1000).ok());
    all.insert(all.end(), batch.begin(), batch.end());
  } while (!batch.empty());
  ASSERT_EQ(all.size(), reader->header().point_count);
  ASSERT_GT(all.size(), 1000u);
  EXPECT_TRUE(reader->header().adjusted_gps_time);
  for (int d = 0; d < 3; ++d) {  // the header's bounds are the points'
    double lo = INFINITY, hi = -INFINITY;
    for (const LasPoint& p : all) lo = std::min(lo, p.p[d]), hi = std::max(hi, p.p[d]);
    EXPECT_NEAR(lo, reader->header().min[d], 1e-6) << d;
    EXPECT_NEAR(hi, reader->header().max[d], 1e-6) << d;
  }

  absl::StatusOr<LasImport> las = LasImport::Open(file, Options());
  ASSERT_TRUE(las.ok()) << las.status();
  EXPECT_EQ(las->sensor().kind, SensorKind::kPoints);
  LasReport report;
  absl::StatusOr<ImportedScan> scan = las->Run(nullptr, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(report.shift, Eigen::Vector3d(500000, 4100000, 0)) << "whole kilometres, z kept";
  EXPECT_EQ(report.points, all.size());
  ASSERT_EQ(scan->path.size(), scan->frames.size());
  // 100 profiles a second, each spread over its 10 ms: about one frame per profile.
  EXPECT_NEAR(double(scan->frames.size()), (all.back().t - all.front().t) * 100, 3);
  size_t i = 0;
  double worst_path = 0, worst_point = 0, worst_origin = 0, worst_box = 0;
  for (size_t f = 0; f < scan->frames.size(); ++f) {
    const PathRecord& row = scan->path[f];
    EXPECT_EQ(row.t, scan->frames[f].t);
    const Eigen::Vector3d o(row.x, row.y, row.z);
    const Eigen::Quaterniond q(row.qw, row.qx, row.qy, row.qz);
    const Eigen::Vector3d scene_origin = o - Eigen::Vector3d(0, 0, 100);
    worst_path = std::max(worst_path, (scene_origin - TruePosition(row.t)).norm());
    for (const Eigen::Vector3f& local : scan->frames[f].points_sensor) {
      ASSERT_LT(i, all.size());
      const Eigen::Vector3d world = q * local.cast<double>() + o + report.shift;
      worst_point = std::max(worst_point, (world - all[i].p).norm());
      // The point's own origin, where its ray truly started, against the frame's.
      worst_origin = std::max(worst_origin, (scene_origin - TruePosition(all[i].t)).norm());
      const Eigen::Vector3d scene = all[i].p - kScene;
      if (!OnTheBox(scene, 2e-3)) worst_box = std::max(worst_box, 1.0);
      ++i;
    }
  }
  EXPECT_EQ(i, all.size());
  EXPECT_LT(worst_path, 1e-5) << "/path is the trajectory at the frames' times";
  EXPECT_LT(worst_point, 1e-4) << "points back in the LAS frame where the file has them";
  EXPECT_LT(worst_origin, 1.5 * 0.0101 + 1e-3) << "speed × frame_seconds";
  EXPECT_EQ(worst_box, 0) << "every point on the corridor's faces";
  // The farthest beam reaches the corridor's far upper corner, 4.4 m off.
  EXPECT_GT(las->sensor().max_range_m, 4.0);
  EXPECT_LT(las->sensor().max_range_m, 4.5);
}

INSTANTIATE_TEST_SUITE_P(Files, LasImportFormats,
                         ::testing::Values("corridor_v12_pf1.las", "corridor_v13_pf3.las",
                                           "corridor_v14_pf6.las"),
                         [](const auto& info) {
                           std::string n = info.param;
                           return n.substr(9, n.size() - 13);  // v12_pf1 …
                         });

TEST(LasImportTest, BadFilesNameTheFileAndWhatIsWrong) {
  auto error = [](const std::string& file, LasImportOptions o = Options()) {
    absl::StatusOr<LasImport> las = LasImport::Open(file, o);
    return las.ok() ? las->Run().status() : las.status();
  };
  absl::Status s = error(kDir + "/corridor_pf0.las");
  EXPECT_NE(s.message().find("corridor_pf0.las: point data format 0 carries no GPS time"),
            std::string::npos)
      << s;

  const std::vector<char> good = Bytes(kDir + "/corridor_v12_pf1.las");
  ASSERT_GT(good.size(), 1000u);
  s = error(Write({good.begin(), good.begin() + static_cast<long>(good.size() / 2)}, "cut.las"));
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_NE(s.message().find("cut.las: "), std::string::npos) << s;
  EXPECT_NE(s.message().find("cut short"), std::string::npos) << s;

  std::vector<char> b = good;
  b[25] = 5;  // LAS 1.5
  s = error(Write(b, "v15.las"));
  EXPECT_NE(s.message().find("v15.las: LAS version 1.5"), std::string::npos) << s;
  b = good;
  b[104] = static_cast<char>(b[104] | 0x80);
  s = error(Write(b, "laz.las"));
  EXPECT_NE(s.message().find("LAZ"), std::string::npos) << s;
  b = good;
  std::memcpy(b.data(), "LASG", 4);
  s = error(Write(b, "sig.las"));
  EXPECT_NE(s.message().find("sig.las: not a LAS file"), std::string::npos) << s;

  // Two points swapped: out of time order, named.
  b = good;
  uint32_t at = 0;
  uint16_t len = 0;
  std::memcpy(&at, b.data() + 96, 4);
  std::memcpy(&len, b.data() + 105, 2);
  std::vector<char> rec(b.begin() + at + 10 * len, b.begin() + at + 11 * len);
  std::copy(b.begin() + at + 11 * len, b.begin() + at + 12 * len, b.begin() + at + 10 * len);
  std::copy(rec.begin(), rec.end(), b.begin() + at + 11 * len);
  s = error(Write(b, "swapped.las"));
  EXPECT_NE(s.message().find("swapped.las: point 11 at GPS time"), std::string::npos) << s;
  EXPECT_NE(s.message().find("not in time order"), std::string::npos) << s;

  // A trajectory that ends early: an error naming the first point past it, or skipped points.
  std::ifstream in(kDir + "/corridor_trajectory.txt");
  std::ofstream half("half_trajectory.txt");
  std::string line;
  for (int n = 0; std::getline(in, line) && n < 80; ++n) half << line << "\n";  // to s ≈ 0.3
  half.close();
  LasImportOptions o = Options();
  o.trajectory = "half_trajectory.txt";
  s = error(kDir + "/corridor_v12_pf1.las", o);
  EXPECT_EQ(s.code(), absl::StatusCode::kOutOfRange) << s;
  EXPECT_NE(s.message().find("lies outside the trajectory half_trajectory.txt"), std::string::npos)
      << s;
  o.skip_outside_trajectory = true;
  absl::StatusOr<LasImport> las = LasImport::Open(kDir + "/corridor_v12_pf1.las", o);
  ASSERT_TRUE(las.ok()) << las.status();
  LasReport report;
  absl::StatusOr<ImportedScan> scan = las->Run(nullptr, &report);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_GT(report.skipped_outside_trajectory, 0u);
  EXPECT_EQ(scan->point_count + report.skipped_outside_trajectory, report.points);

  // Trajectories that are not one.
  std::ofstream("backwards.txt") << "# t x y z qx qy qz qw\n1 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n";
  EXPECT_NE(ReadTrajectoryText("backwards.txt")
                .status()
                .message()
                .find("backwards.txt: line 3: time 1 is not after the previous 1"),
            std::string::npos);
  std::ofstream("squashed.txt") << "1 0 0 0 0 0 0 2\n2 0 0 0 0 0 0 1\n";
  EXPECT_NE(ReadTrajectoryText("squashed.txt").status().message().find("squashed.txt: line 1"),
            std::string::npos);
}

}  // namespace
}  // namespace carvemap
