#include "storage/import/e57_import.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "storage/import/import_writer.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

// Three setups of a scanner in a box room with a pillar and a window of no returns
// (tests/tools/e57/make_e57.py; an independent npm reader agrees with the files), in a
// georeferenced frame: the room is [E0, E0 + 8] × [N0, N0 + 6] × [100, 103] m.
const std::string kDir = std::string(CARVEMAP_TEST_DATA_DIR) + "/e57";
const Eigen::Vector3d kKilometres(512000, 4181000, 0);  // the automatic shift

nlohmann::json Truth() {
  std::ifstream in(kDir + "/truth.json");
  return nlohmann::json::parse(in);
}

Eigen::Vector3d Vec(const nlohmann::json& j) {
  return Eigen::Vector3d(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
}

// Distance from `p` to the nearest face of the axis-aligned box [lo, hi], for a point on it.
bool OnBoxSurface(const Eigen::Vector3d& p, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                  double tol) {
  bool inside = true, on_face = false;
  for (int d = 0; d < 3; ++d) {
    inside = inside && p[d] > lo[d] - tol && p[d] < hi[d] + tol;
    on_face = on_face || std::abs(p[d] - lo[d]) < tol || std::abs(p[d] - hi[d]) < tol;
  }
  return inside && on_face;
}

struct Frame {
  int sensor;
  double t;
  std::vector<Eigen::Vector3f> points;
};

struct Imported {
  std::vector<SensorInfo> sensors;
  std::vector<Frame> frames;
  std::vector<PathRecord> path;
  E57Report report;
};

Imported Import(const std::string& file, const E57ImportOptions& options = {}) {
  Imported out;
  absl::StatusOr<E57Import> e57 = E57Import::Open(file, options);
  EXPECT_TRUE(e57.ok()) << e57.status();
  if (!e57.ok()) return out;
  out.sensors = e57->sensors();
  auto path = e57->Run(
      [&](int sensor, double t, std::span<const Eigen::Vector3f> p) {
        out.frames.push_back(Frame{sensor, t, {p.begin(), p.end()}});
        return absl::OkStatus();
      },
      &out.report);
  EXPECT_TRUE(path.ok()) << path.status();
  if (path.ok()) out.path = *path;
  return out;
}

class E57ImportFiles : public ::testing::TestWithParam<const char*> {};

TEST_P(E57ImportFiles, EveryReturnLiesOnTheRoomAndTheWindowHasNone) {
  const nlohmann::json truth = Truth();
  const nlohmann::json scans = truth["files"][GetParam()]["scans"];
  const Imported in = Import(kDir + "/" + GetParam());
  ASSERT_EQ(in.frames.size(), scans.size());
  ASSERT_EQ(in.path.size(), scans.size());
  EXPECT_EQ(in.report.shift, kKilometres);
  const Eigen::Vector3d room_lo = Vec(truth["room_box"]["min"]) - kKilometres;
  const Eigen::Vector3d room_hi = Vec(truth["room_box"]["max"]) - kKilometres;
  const Eigen::Vector3d pillar_lo = Vec(truth["pillar_box"]["min"]) - kKilometres;
  const Eigen::Vector3d pillar_hi = Vec(truth["pillar_box"]["max"]) - kKilometres;
  double farthest = 0;
  for (size_t i = 0; i < scans.size(); ++i) {
    const nlohmann::json& s = scans[i];
    const Frame& f = in.frames[i];
    const SensorInfo& sensor = in.sensors[static_cast<size_t>(f.sensor)];
    EXPECT_EQ(f.t, static_cast<double>(i));
    if (s["structured"].get<bool>()) {
      EXPECT_EQ(sensor.kind, SensorKind::kGrid);
      EXPECT_EQ(sensor.rows, s["rows"].get<uint32_t>());
      EXPECT_EQ(sensor.cols, s["cols"].get<uint32_t>());
      EXPECT_EQ(f.points.size(), sensor.rows * sensor.cols);
    } else {
      EXPECT_EQ(sensor.kind, SensorKind::kPoints);
      EXPECT_EQ(f.points.size(), s["records"].get<size_t>());
    }
    // The path is the scan's pose, shifted.
    const PathRecord& p = in.path[i];
    const nlohmann::json& pose = s["pose"];
    EXPECT_NEAR(p.x, pose["translation"]["x"].get<double>() - kKilometres.x(), 1e-9);
    EXPECT_NEAR(p.y, pose["translation"]["y"].get<double>() - kKilometres.y(), 1e-9);
    EXPECT_NEAR(p.z, pose["translation"]["z"].get<double>(), 1e-9);
    const Eigen::Quaterniond q(p.qw, p.qx, p.qy, p.qz);
    EXPECT_NEAR(q.w(), pose["rotation"]["w"].get<double>(), 1e-12);
    EXPECT_NEAR(q.z(), pose["rotation"]["z"].get<double>(), 1e-12);

    size_t no_return = 0, on_walls = 0;
    for (const Eigen::Vector3f& local : f.points) {
      if (std::isnan(local.x())) {
        ++no_return;
        continue;
      }
      farthest = std::max(farthest, double(local.norm()));
      const Eigen::Vector3d w = q * local.cast<double>() + Eigen::Vector3d(p.x, p.y, p.z);
      on_walls +=
          OnBoxSurface(w, room_lo, room_hi, 1e-3) || OnBoxSurface(w, pillar_lo, pillar_hi, 1e-3);
    }
    // A grid's missing pixels are rays with no return; an unstructured scan's omitted
    // directions are not rays at all.
    EXPECT_EQ(no_return, s["structured"].get<bool>()
                             ? s["no_return"].get<size_t>()
                             : s["records"].get<size_t>() - s["returns"].get<size_t>())
        << s["name"];
    EXPECT_EQ(on_walls, f.points.size() - no_return) << s["name"];
  }
  for (const SensorInfo& s : in.sensors) {
    EXPECT_DOUBLE_EQ(s.max_range_m, std::ceil(farthest * 100) / 100);
    EXPECT_EQ(s.R_s2c, Eigen::Matrix3d::Identity());
  }
}

INSTANTIATE_TEST_SUITE_P(Files, E57ImportFiles,
                         ::testing::Values("room_scaled.e57", "room_spherical.e57",
                                           "room_points.e57"));

TEST(E57Import, ScansOfTwoGridSizesAreTwoGridSensors) {
  const Imported in = Import(kDir + "/room_scaled.e57");
  ASSERT_EQ(in.sensors.size(), 2u);
  EXPECT_EQ(in.sensors[0].name, "grid_70x160");
  EXPECT_EQ(in.sensors[1].name, "grid_50x120");
  ASSERT_EQ(in.frames.size(), 3u);
  EXPECT_EQ(in.frames[0].sensor, 0);
  EXPECT_EQ(in.frames[1].sensor, 0);
  EXPECT_EQ(in.frames[2].sensor, 1);
  EXPECT_EQ(in.report.structured_scans, 3u);
  const Imported points = Import(kDir + "/room_points.e57");
  ASSERT_EQ(points.sensors.size(), 1u);
  EXPECT_EQ(points.sensors[0].name, "points");
}

// The grid is row-major with rows of elevation and columns of azimuth: the same pixel from
// Cartesian scaled integers in row order (with indexBounds) and from spherical floats in
// shuffled order (without them, window pixels left out) is the same ray.
TEST(E57Import, CartesianAndSphericalFilesGiveTheSamePixels) {
  const Imported a = Import(kDir + "/room_scaled.e57");
  const Imported b = Import(kDir + "/room_spherical.e57");
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t i = 0; i < a.frames.size(); ++i) {
    ASSERT_EQ(a.frames[i].points.size(), b.frames[i].points.size());
    const uint32_t cols = a.sensors[static_cast<size_t>(a.frames[i].sensor)].cols;
    const uint32_t rows = a.sensors[static_cast<size_t>(a.frames[i].sensor)].rows;
    for (size_t k = 0; k < a.frames[i].points.size(); ++k) {
      const Eigen::Vector3f& p = a.frames[i].points[k];
      const Eigen::Vector3f& q = b.frames[i].points[k];
      ASSERT_EQ(std::isnan(p.x()), std::isnan(q.x())) << i << " " << k;
      if (std::isnan(p.x())) continue;
      ASSERT_LT((p - q).norm(), 2e-4) << i << " " << k;
      // truth.json's grid: row r at elevation −60° + 140° r / (rows − 1), column c at azimuth
      // 360° c / cols.
      const double r = double(k / cols), c = double(k % cols);
      const double elevation = (-60 + 140 * r / (rows - 1)) * M_PI / 180;
      const double azimuth = 2 * M_PI * c / cols;
      const Eigen::Vector3d dir(std::cos(elevation) * std::cos(azimuth),
                                std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
      ASSERT_GT(dir.dot(q.cast<double>().normalized()), std::cos(1e-4)) << i << " " << k;
    }
  }
}

TEST(E57Import, MaxRangeAndShiftAsGiven) {
  E57ImportOptions options;
  options.max_range_m = 3.0;
  options.shift = Eigen::Vector3d(512001, 4181002, 100);
  const Imported in = Import(kDir + "/room_scaled.e57", options);
  const Imported all = Import(kDir + "/room_scaled.e57");
  ASSERT_EQ(in.frames.size(), all.frames.size());
  for (const SensorInfo& s : in.sensors) EXPECT_EQ(s.max_range_m, 3.0);
  for (size_t i = 0; i < in.frames.size(); ++i) {
    for (size_t k = 0; k < in.frames[i].points.size(); ++k) {
      const Eigen::Vector3f& p = all.frames[i].points[k];
      const bool kept = !std::isnan(p.x()) && p.norm() <= 3.0f;
      EXPECT_EQ(!std::isnan(in.frames[i].points[k].x()), kept);
    }
    EXPECT_NEAR(in.path[i].x, all.path[i].x - 1, 1e-9);
    EXPECT_NEAR(in.path[i].y, all.path[i].y - 2, 1e-9);
    EXPECT_NEAR(in.path[i].z, all.path[i].z - 100, 1e-9);
  }
  EXPECT_GT(in.report.no_return, all.report.no_return);
}

// Through the writer: a scan.h5 that validates, the sensors in order; a damaged file leaves
// nothing behind.
TEST(E57Import, WritesAValidScanOrNothing) {
  const std::string out = ::testing::TempDir() + "e57_room.h5";
  absl::StatusOr<E57Import> e57 = E57Import::Open(kDir + "/room_scaled.e57", {});
  ASSERT_TRUE(e57.ok()) << e57.status();
  auto summary = WriteImportSensors(out, e57->sensors(),
                                    [&](const SensorFrameSink& sink) { return e57->Run(sink); });
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 3u);
  EXPECT_EQ(summary->points, 2u * 70 * 160 + 50 * 120);
  auto reader = ScanReader::Open(out);
  ASSERT_TRUE(reader.ok()) << reader.status();
  EXPECT_TRUE((*reader)->Validate().ok());
  ASSERT_EQ((*reader)->sensors().size(), 2u);
  EXPECT_EQ((*reader)->sensors()[1].name, "grid_50x120");
  EXPECT_EQ((*reader)->frame_count(0), 2u);

  const std::string failed = ::testing::TempDir() + "e57_failed.h5";
  std::filesystem::remove(failed);
  auto bad = WriteImportSensors(failed, e57->sensors(), [&](const SensorFrameSink& sink) {
    return e57->Run([&](int s, double t, std::span<const Eigen::Vector3f> p) -> absl::Status {
      if (t > 0) return absl::DataLossError("the disk went away");
      return sink(s, t, p);
    });
  });
  EXPECT_FALSE(bad.ok());
  EXPECT_FALSE(std::filesystem::exists(failed));
}

TEST(E57Import, OptionsOutOfRangeAreRefused) {
  E57ImportOptions o;
  o.max_range_m = -1;
  EXPECT_NE(E57Import::Open(kDir + "/room_scaled.e57", o).status().message().find("--max-range"),
            std::string::npos);
  o = {};
  o.range_sigma = {-0.1, 0};
  EXPECT_FALSE(E57Import::Open(kDir + "/room_scaled.e57", o).ok());
}

}  // namespace
}  // namespace carvemap
