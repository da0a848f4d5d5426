#include "geometry/north_alignment.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "geometry/pose.h"
#include "services/building/building_presets.h"
#include "services/sim/scan_sink.h"
#include "services/sim/simulator.h"

namespace carvemap {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

double AngleError(double a, double b) {
  return std::abs(std::remainder(a - b, 2 * std::numbers::pi));
}

// The simulator's walk through the office preset with its default noise (drift of the path,
// 1.5 µT per axis on the magnetometer): the readings in the world frame of the DRIFTED path
// (what the scan file holds), that frame turned by `turn` about the vertical, as if the
// localizer had started facing another way.
std::vector<Eigen::Vector3d> SimulatedReadings(uint64_t seed, double turn) {
  absl::StatusOr<Building> building = MakePresetBuilding("office", seed);
  EXPECT_TRUE(building.ok()) << building.status();
  SimulateOptions o;
  o.seed = seed;
  o.rig.rate_hz = 2;
  o.rig.beam_step_deg = 10;
  o.max_duration_s = 240;
  MemoryScanSink sink;
  absl::StatusOr<SimulationSummary> summary = SimulateBuilding(*building, o, sink);
  EXPECT_TRUE(summary.ok()) << summary.status();
  std::vector<TimedPose> path;
  for (const PathRecord& p : sink.path) {
    path.push_back({p.t, Pose{Eigen::Quaterniond(p.qw, p.qx, p.qy, p.qz).normalized(),
                              Eigen::Vector3d(p.x, p.y, p.z)}});
  }
  const Eigen::Quaterniond r(Eigen::AngleAxisd(turn, Eigen::Vector3d::UnitZ()));
  std::vector<Eigen::Vector3d> world;
  for (const MagnetometerRecord& m : sink.magnetometer) {
    world.push_back(r * (PoseAtTime(path, m.t).rotation * Eigen::Vector3d(m.mx, m.my, m.mz)));
  }
  EXPECT_GT(world.size(), 1000u);
  return world;
}

// A frame turned by θ comes back with a yaw of -θ: 0°, 37°, 180° and 271°, three walks each.
TEST(NorthAlignmentTest, TurnedFramesComeBackAligned) {
  std::vector<double> errors;
  for (const double turn_deg : {0.0, 37.0, 180.0, 271.0}) {
    for (uint64_t seed : {1, 2, 3}) {
      const std::vector<Eigen::Vector3d> readings = SimulatedReadings(seed, turn_deg * kDeg);
      const NorthEstimate e = EstimateNorth(readings);
      SCOPED_TRACE(testing::Message() << turn_deg << "° seed " << seed);
      EXPECT_TRUE(e.confident) << e.why_not;
      EXPECT_EQ(e.usable, int(readings.size()));
      EXPECT_GT(e.kept, 0.9 * e.usable);
      EXPECT_LT(e.spread_rad, 10 * kDeg);
      const double error = AngleError(e.yaw_rad, -turn_deg * kDeg);
      EXPECT_LT(error, 1.5 * kDeg);
      errors.push_back(error);
    }
  }
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  EXPECT_LT(errors[errors.size() / 2], 1.0 * kDeg);
}

// A steel wall: 10 % of the readings, one stretch of the walk, bent 60° about the vertical.
// The biweight drops them; a plain mean (eq 2.1 as written) would be pulled ~6° off.
TEST(NorthAlignmentTest, BentFieldNearSteelIsLeftOut) {
  for (const double turn_deg : {37.0, 271.0}) {
    std::vector<Eigen::Vector3d> readings = SimulatedReadings(4, turn_deg * kDeg);
    const Eigen::AngleAxisd bend(60 * kDeg, Eigen::Vector3d::UnitZ());
    const size_t first = readings.size() / 3, n = readings.size() / 10;
    for (size_t i = first; i < first + n; ++i) readings[i] = bend * readings[i];
    const NorthEstimate e = EstimateNorth(readings);
    SCOPED_TRACE(testing::Message() << turn_deg << "°");
    EXPECT_TRUE(e.confident) << e.why_not;
    EXPECT_LT(AngleError(e.yaw_rad, -turn_deg * kDeg), 3 * kDeg);
    EXPECT_LE(e.kept, int(readings.size() - n / 2));  // most of the bent ones left out
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& f : readings) sum += f;
    const double plain = std::remainder(std::numbers::pi / 2 - std::atan2(sum.y(), sum.x()),
                                        2 * std::numbers::pi);
    EXPECT_GT(AngleError(plain, -turn_deg * kDeg), 4 * kDeg);
  }
}

// Readings that agree on nothing, too few readings, or a field with no horizontal part: no
// confident answer, and a reason in words.
TEST(NorthAlignmentTest, NotConfidentWithoutAgreement) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> heading(-std::numbers::pi, std::numbers::pi);
  std::vector<Eigen::Vector3d> scattered;
  for (int i = 0; i < 2000; ++i) {
    const double h = heading(rng);
    scattered.emplace_back(20 * std::cos(h), 20 * std::sin(h), -45);
  }
  NorthEstimate e = EstimateNorth(scattered);
  EXPECT_FALSE(e.confident);
  EXPECT_FALSE(e.why_not.empty());

  const std::vector<Eigen::Vector3d> few(5, Eigen::Vector3d(0, 20, -45));
  e = EstimateNorth(few);
  EXPECT_FALSE(e.confident);
  EXPECT_NE(e.why_not.find("fewer than 20"), std::string::npos) << e.why_not;

  const std::vector<Eigen::Vector3d> vertical(100, Eigen::Vector3d(0, 0, -50));
  e = EstimateNorth(vertical);
  EXPECT_FALSE(e.confident);
  EXPECT_EQ(e.usable, 0);
}

// Exact readings: the answer is exact, whatever the heading, including across ±180°.
TEST(NorthAlignmentTest, ExactReadingsGiveTheExactTurn) {
  for (const double yaw_deg : {0.0, 10.0, -90.0, 179.9, -179.9}) {
    const Eigen::AngleAxisd away(-yaw_deg * kDeg, Eigen::Vector3d::UnitZ());
    const std::vector<Eigen::Vector3d> readings(50, away * Eigen::Vector3d(0, 20, -45));
    const NorthEstimate e = EstimateNorth(readings);
    EXPECT_TRUE(e.confident) << e.why_not;
    EXPECT_NEAR(AngleError(e.yaw_rad, yaw_deg * kDeg), 0, 1e-9) << yaw_deg;
  }
}

TEST(NorthAlignmentTest, DecisionFollowsTheMode) {
  NorthEstimate fit;
  fit.readings = fit.usable = fit.kept = 100;
  fit.confident = true;
  fit.yaw_rad = 0.5 * kDeg;
  // Auto: under a degree is kept as it is, without a warning; magnetic turns by it.
  absl::StatusOr<NorthDecision> d = DecideNorth(NorthMode::kAuto, true, fit);
  ASSERT_TRUE(d.ok());
  EXPECT_FALSE(d->turned);
  EXPECT_FALSE(d->warn);
  EXPECT_EQ(d->yaw_rad, 0);
  d = DecideNorth(NorthMode::kMagnetic, true, fit);
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->turned);
  EXPECT_EQ(d->yaw_rad, fit.yaw_rad);
  fit.yaw_rad = 37 * kDeg;
  d = DecideNorth(NorthMode::kAuto, true, fit);
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->turned);
  d = DecideNorth(NorthMode::kNone, true, fit);
  ASSERT_TRUE(d.ok());
  EXPECT_FALSE(d->turned);
  // A failed fit: auto warns and keeps the frame; magnetic is an error naming why.
  fit.confident = false;
  fit.why_not = "only 3 of 100 readings agree on a heading";
  d = DecideNorth(NorthMode::kAuto, true, fit);
  ASSERT_TRUE(d.ok());
  EXPECT_FALSE(d->turned);
  EXPECT_TRUE(d->warn);
  EXPECT_NE(d->note.find("only 3 of 100"), std::string::npos) << d->note;
  d = DecideNorth(NorthMode::kMagnetic, true, fit);
  EXPECT_EQ(d.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(d.status().message().find("only 3 of 100"), std::string::npos);
  d = DecideNorth(NorthMode::kMagnetic, false, NorthEstimate{});
  EXPECT_NE(d.status().message().find("no /magnetometer"), std::string::npos) << d.status();
  // True north: magnetic north 10° east of it, so the turn is 10° less.
  fit.confident = true;
  fit.yaw_rad = 37 * kDeg;
  d = DecideNorth(NorthMode::kAuto, true, fit, 10 * kDeg);
  ASSERT_TRUE(d.ok());
  EXPECT_NEAR(d->yaw_rad, 27 * kDeg, 1e-12);
  fit.yaw_rad = 10.5 * kDeg;  // 0.5° from true north: kept under auto
  d = DecideNorth(NorthMode::kAuto, true, fit, 10 * kDeg);
  EXPECT_FALSE(d->turned);
  EXPECT_NE(d->note.find("true north"), std::string::npos) << d->note;
  EXPECT_EQ(ParseNorthMode("").value(), NorthMode::kAuto);
  EXPECT_EQ(ParseNorthMode("none").value(), NorthMode::kNone);
  EXPECT_FALSE(ParseNorthMode("true").ok());
}

TEST(NorthAlignmentTest, PlacesAndDates) {
  absl::StatusOr<NorthPlace> p = ParseNorthPlace("52.52,13.405", "2026-11-28", "--location");
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->lat_deg, 52.52);
  EXPECT_EQ(p->lon_deg, 13.405);
  EXPECT_NEAR(DecimalYear("2026-11-28").value(), 2026 + 331.0 / 365, 1e-12);
  EXPECT_NEAR(DecimalYear("2028-03-01").value(), 2028 + 60.0 / 366, 1e-12);  // a leap year
  for (const char* bad : {"52.52", "91,0", "52,13,4", "north", "52;13"}) {
    p = ParseNorthPlace(bad, "", "--location");
    ASSERT_FALSE(p.ok()) << bad;
    EXPECT_NE(p.status().message().find("--location '"), std::string::npos) << p.status();
  }
  p = ParseNorthPlace("52,13", "28.11.2026", "--location");
  EXPECT_NE(p.status().message().find("YYYY-MM-DD"), std::string::npos) << p.status();
}

}  // namespace
}  // namespace carvemap
