#include "coordinator/scan_north.h"

#include <cmath>
#include <filesystem>
#include <numbers>

#include <gtest/gtest.h>

#include "services/building/building_presets.h"
#include "services/sim/scan_sink.h"
#include "services/sim/simulator.h"
#include "storage/scan_writer.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
constexpr double kDeg = std::numbers::pi / 180;

class ScanNorthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) / "scan_north_test";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // The office preset's walk (a thin rig), its path recorded in a frame turned by `turn_deg`.
  std::string Write(const std::string& name, double turn_deg, bool magnetometer = true) {
    absl::StatusOr<Building> building = MakePresetBuilding("office", 2);
    EXPECT_TRUE(building.ok());
    SimulateOptions o;
    o.seed = 2;
    o.rig.rate_hz = 2;
    o.rig.beam_step_deg = 20;
    o.max_duration_s = 120;
    o.noise.magnetometer = magnetometer;
    o.frame_yaw_deg = turn_deg;
    const std::string path = (dir_ / name).string();
    absl::StatusOr<std::unique_ptr<ScanWriter>> writer = ScanWriter::Create(path);
    EXPECT_TRUE(writer.ok()) << writer.status();
    ScanWriterSink sink(**writer);
    EXPECT_TRUE(SimulateBuilding(*building, o, sink).ok());
    EXPECT_TRUE((*writer)->Close().ok());
    return path;
  }

  fs::path dir_;
};

TEST_F(ScanNorthTest, ATurnedScanIsTurnedBack) {
  const std::string plain = Write("plain.h5", 0);
  const std::string turned = Write("turned.h5", 37);
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(turned);
  ASSERT_TRUE(reader.ok()) << reader.status();
  absl::StatusOr<ScanNorth> north = NorthOfScan(**reader, NorthMode::kAuto);
  ASSERT_TRUE(north.ok()) << north.status();
  EXPECT_TRUE(north->decision.turned);
  EXPECT_NEAR(north->decision.yaw_rad, -37 * kDeg, 1.0 * kDeg);
  const nlohmann::json j = NorthJson(*north);
  EXPECT_EQ(j["mode"], "auto");
  EXPECT_EQ(j["turned"], true);
  EXPECT_NEAR(j["yaw_deg"].get<double>(), -37, 1.0);
  EXPECT_EQ(j["fit"]["readings"], north->estimate.readings);

  // Read with that turn, the turned scan's path lies where the plain scan's does (within the
  // fit's error over the walk's extent), poses, covariances and positions alike.
  ScanReader::OpenOptions open;
  open.world_yaw_rad = north->decision.yaw_rad;
  absl::StatusOr<std::unique_ptr<ScanReader>> back = ScanReader::Open(turned, open);
  absl::StatusOr<std::unique_ptr<ScanReader>> ref = ScanReader::Open(plain);
  ASSERT_TRUE(back.ok() && ref.ok());
  const auto& a = (*back)->timed_path();
  const auto& b = (*ref)->timed_path();
  ASSERT_EQ(a.size(), b.size());
  double worst = 0, worst_angle = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, (a[i].pose.translation - b[i].pose.translation).norm());
    worst_angle = std::max(worst_angle, a[i].pose.rotation.angularDistance(b[i].pose.rotation));
  }
  EXPECT_LT(worst, 0.5);  // ≤ 1° over the office's ~25 m
  EXPECT_LT(worst_angle, 1.0 * kDeg);
  absl::StatusOr<std::vector<Eigen::Vector3d>> positions = (*back)->PathPositions();
  ASSERT_TRUE(positions.ok());
  EXPECT_NEAR(((*positions)[7] - a[7].pose.translation).norm(), 0, 1e-9);
  // The covariances turn with the frame: their traces stay.
  const PathCovariance& ca = (*back)->path_covariance()->at(5);
  const PathCovariance& cb = (*ref)->path_covariance()->at(5);
  EXPECT_NEAR(ca[0] + ca[3] + ca[5], cb[0] + cb[3] + cb[5], 1e-6);
}

TEST_F(ScanNorthTest, AScanAlreadyFacingNorthIsKept) {
  const std::string plain = Write("plain.h5", 0);
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(plain);
  ASSERT_TRUE(reader.ok());
  absl::StatusOr<ScanNorth> north = NorthOfScan(**reader, NorthMode::kAuto);
  ASSERT_TRUE(north.ok()) << north.status();
  EXPECT_FALSE(north->decision.turned);  // the fit is within a degree of 0
  EXPECT_EQ(north->decision.yaw_rad, 0);
  EXPECT_LT(std::abs(north->estimate.yaw_rad), 1.0 * kDeg);
  EXPECT_NE(NorthJson(*north)["note"].get<std::string>().find("under 1.0°"), std::string::npos);
}

// True north at a known place and date: the turn is the fit's less the World Magnetic
// Model's declination there; a scan whose times are not dates needs the date.
TEST_F(ScanNorthTest, TrueNorthAtAPlace) {
  const std::string turned = Write("turned.h5", 37);
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(turned);
  ASSERT_TRUE(reader.ok());
  absl::StatusOr<ScanNorth> magnetic = NorthOfScan(**reader, NorthMode::kAuto);
  ASSERT_TRUE(magnetic.ok());
  // Reykjavík, where magnetic north lies ~10° west of true north.
  absl::StatusOr<NorthPlace> place = ParseNorthPlace("64.15,-21.94", "2026-06-01", "location");
  ASSERT_TRUE(place.ok());
  absl::StatusOr<ScanNorth> north = NorthOfScan(**reader, NorthMode::kAuto, *place);
  ASSERT_TRUE(north.ok()) << north.status();
  EXPECT_LT(north->declination_deg, -5);
  EXPECT_GT(north->declination_deg, -20);
  EXPECT_NEAR(north->decision.yaw_rad,
              magnetic->decision.yaw_rad - north->declination_deg * kDeg, 1e-9);
  const nlohmann::json j = NorthJson(*north);
  EXPECT_EQ(j["reference"], "true north");
  EXPECT_EQ(j["place"]["model"], "WMM-2025");

  place->survey_date.clear();  // the simulator's times start at 0: no date to take
  north = NorthOfScan(**reader, NorthMode::kAuto, *place);
  ASSERT_FALSE(north.ok());
  EXPECT_EQ(north.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(north.status().message().find(turned), std::string::npos) << north.status();
  EXPECT_NE(north.status().message().find("survey date"), std::string::npos);
}

TEST_F(ScanNorthTest, WithoutReadings) {
  const std::string bare = Write("bare.h5", 37, /*magnetometer=*/false);
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(bare);
  ASSERT_TRUE(reader.ok());
  absl::StatusOr<ScanNorth> north = NorthOfScan(**reader, NorthMode::kAuto);
  ASSERT_TRUE(north.ok());
  EXPECT_FALSE(north->decision.turned);
  EXPECT_FALSE(NorthJson(*north).contains("fit"));
  north = NorthOfScan(**reader, NorthMode::kMagnetic);
  ASSERT_FALSE(north.ok());
  EXPECT_NE(north.status().message().find(bare), std::string::npos) << north.status();
  EXPECT_NE(north.status().message().find("no /magnetometer"), std::string::npos);
}

}  // namespace
}  // namespace carvemap
