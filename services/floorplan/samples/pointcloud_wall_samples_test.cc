// Tests of the wall samples from a point cloud (§3.1.1): each rule on small clouds made here
// whose neighbourhoods are known exactly (d_s grid, |N_g| ≥ 50, vertical support ≥ H = 2 m, the
// 16-bin height histogram, the PCA normal's confidence ≥ 0.15 and its orientation, the median
// inside the cell), then the whole route on the simulator's `room` and `office` presets: the
// scan.h5 streamed as a cloud (scan_cloud_stream.h), its levels from §2.5's point histogram,
// the samples against gt/building.json (positions, normals, heights, poses).
#include "services/floorplan/samples/pointcloud_wall_samples.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "services/building/building.h"
#include "services/floorplan/samples/scan_cloud_stream.h"
#include "services/floorplan/samples/wall_samples_test_util.h"
#include "services/levels/level_split.h"
#include "services/sim/simulator.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using testing::TruthRoom;

constexpr double kDs = 0.05;

// A cloud held in memory, streamed in batches of 1000.
CloudStreamFn StreamOf(const std::vector<CloudPoint>& cloud) {
  return [&cloud](const CloudBatchSink& sink) -> absl::Status {
    for (size_t i = 0; i < cloud.size(); i += 1000) {
      const size_t n = std::min<size_t>(1000, cloud.size() - i);
      if (absl::Status s = sink(std::span<const CloudPoint>(cloud.data() + i, n)); !s.ok()) {
        return s;
      }
    }
    return absl::OkStatus();
  };
}

Level OneLevel(double floor_z = 0, double ceiling_z = 2.5) {
  Level l;
  l.floor_z = floor_z;
  l.ceiling_z = ceiling_z;
  l.split_z_low = floor_z - 0.5;
  l.split_z_high = ceiling_z + 0.5;
  return l;
}

// A vertical column of n points at (x, y), evenly over [z0, z1], measured from `sensor` at t.
void AddColumn(std::vector<CloudPoint>& cloud, const Vector2d& xy, double z0, double z1, int n,
               const Vector3d& sensor, double t = 0) {
  for (int i = 0; i < n; ++i) {
    const double z = z0 + (z1 - z0) * (i + 0.5) / n;
    cloud.push_back({Vector3d(xy.x(), xy.y(), z), sensor, t});
  }
}

// A wall x = x0, y ∈ [y0, y1] (columns every 1 cm, 26 points each over [z0, z1]) seen from
// `sensor`: every neighbourhood near it holds ≥ 9 columns, ≥ 234 points.
void AddWallX(std::vector<CloudPoint>& cloud, double x0, double y0, double y1, double z0,
              double z1, const Vector3d& sensor, double t = 0) {
  for (double y = y0; y <= y1 + 1e-9; y += 0.01) {
    AddColumn(cloud, {x0, y}, z0, z1, 26, sensor, t);
  }
}

absl::StatusOr<WallSampleSet> SamplesOf(const std::vector<CloudPoint>& cloud,
                                        const PointCloudWallSampleOptions& options = {},
                                        PointCloudWallSampleReport* report = nullptr,
                                        std::vector<TimedPose> path = {}) {
  const Level level = OneLevel();
  std::vector<PointCloudWallSampleReport> reports;
  absl::StatusOr<std::vector<WallSampleSet>> sets =
      PointCloudWallSamples(StreamOf(cloud), {&level, 1}, path, options, &reports);
  if (!sets.ok()) return sets.status();
  if (sets->size() != 1) return absl::InternalError("expected one level");
  if (report != nullptr) *report = reports[0];
  return (*sets)[0];
}

// Samples whose position lies in cell (ix, iy) of the d_s grid.
size_t SamplesInCell(const WallSampleSet& set, int ix, int iy) {
  size_t n = 0;
  for (const WallSample& s : set.samples) {
    n += static_cast<int>(std::floor(s.position.x() / kDs)) == ix &&
         static_cast<int>(std::floor(s.position.y() / kDs)) == iy;
  }
  return n;
}

TEST(PointCloudWallSamples, OptionsLevelsAndPathAreValidated) {
  PointCloudWallSampleOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.spacing_m = 0;
  EXPECT_NE(o.Validate().message().find("spacing_m"), std::string::npos);
  o = {};
  o.height_bins = 17;  // one 16-bit mask per cell
  EXPECT_NE(o.Validate().message().find("height_bins"), std::string::npos);
  o = {};
  o.min_filled_top_bins = 5;
  EXPECT_NE(o.Validate().message().find("min_filled_top_bins"), std::string::npos);
  o = {};
  o.min_normal_confidence = 1.5;
  EXPECT_NE(o.Validate().message().find("min_normal_confidence"), std::string::npos);

  std::vector<CloudPoint> cloud;
  AddWallX(cloud, 0.01, 0, 1, 0, 2.5, {1, 0.5, 1.2});
  Level bad = OneLevel(2.5, 0);  // floor above ceiling
  absl::StatusOr<std::vector<WallSampleSet>> r =
      PointCloudWallSamples(StreamOf(cloud), {&bad, 1}, {}, {});
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("level 0"), std::string::npos) << r.status();

  const Level level = OneLevel();
  std::vector<TimedPose> path(2);
  path[0].t = 1;
  path[1].t = 0;  // not in time order
  r = PointCloudWallSamples(StreamOf(cloud), {&level, 1}, path, {});
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("path pose 1"), std::string::npos) << r.status();

  // A non-finite point is refused, not binned.
  cloud.push_back({Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 1), {1, 0.5, 1.2}, 0});
  EXPECT_EQ(SamplesOf(cloud).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(PointCloudHeightHistogram(StreamOf(cloud)).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(PointCloudWallSamples, StreamErrorsAreReturned) {
  const Level level = OneLevel();
  const CloudStreamFn failing = [](const CloudBatchSink&) {
    return absl::DataLossError("scan.h5: /frames row 7 unreadable");
  };
  absl::StatusOr<std::vector<WallSampleSet>> r =
      PointCloudWallSamples(failing, {&level, 1}, {}, {});
  EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(r.status().message().find("row 7"), std::string::npos);
}

// A dense, tall, flat wall at x = 0.01: one sample per d_s cell along it (in the cells that
// hold the wall: x ∈ [0, 0.05)), each within 2 mm of the wall (the median's histogram
// resolution is d_s / 32), the normal ±x towards the sensor, heights the points' extremes.
TEST(PointCloudWallSamples, WallGivesOneSamplePerCellOnTheWall) {
  for (double sensor_x : {1.0, -1.0}) {
    std::vector<CloudPoint> cloud;
    AddWallX(cloud, 0.01, 0, 2, 0.03, 2.47, {sensor_x, 1, 1.2});
    PointCloudWallSampleReport rep;
    absl::StatusOr<WallSampleSet> set = SamplesOf(cloud, {}, &rep);
    ASSERT_TRUE(set.ok()) << set.status();
    EXPECT_DOUBLE_EQ(set->spacing_m, kDs);
    // Cells iy = 1..38 lie along the wall away from its ends (the end cells see half the
    // neighbourhood: their median leaves the cell).
    EXPECT_GE(set->samples.size(), 38u);
    EXPECT_LE(set->samples.size(), 40u);
    std::set<std::pair<int, int>> cells;
    for (const WallSample& s : set->samples) {
      EXPECT_NEAR(s.position.x(), 0.01, 0.002);
      EXPECT_GE(s.position.y(), -0.001);
      EXPECT_LE(s.position.y(), 2.001);
      EXPECT_EQ(static_cast<int>(std::floor(s.position.x() / kDs)), 0) << s.position.transpose();
      EXPECT_TRUE(cells.insert({static_cast<int>(std::floor(s.position.x() / kDs)),
                                static_cast<int>(std::floor(s.position.y() / kDs))})
                      .second)
          << "two samples in one cell at " << s.position.transpose();
      EXPECT_NEAR(s.normal.x(), sensor_x, 1e-6) << "towards the sensor";
      EXPECT_NEAR(s.normal.y(), 0, 1e-6);
      // 26 points over [0.03, 2.47]: the lowest at 0.03 + 2.44 / 52, the highest symmetric.
      EXPECT_NEAR(s.floor_z, 0.03 + 2.44 / 52, 1e-5);
      EXPECT_NEAR(s.ceiling_z, 2.47 - 2.44 / 52, 1e-5);
      EXPECT_TRUE(s.poses.empty());  // no path given
    }
    EXPECT_EQ(rep.samples, set->samples.size());
    EXPECT_GE(rep.flat, rep.samples);
    EXPECT_GE(rep.uniform, rep.flat);
    EXPECT_GE(rep.tall, rep.uniform);
    EXPECT_GE(rep.dense, rep.tall);
    EXPECT_EQ(rep.points, cloud.size());
  }
}

// |N_g| ≥ 50 (§3.1.1), to the point: three columns 1.5 cm apart in one cell, the only
// neighbourhood that holds all three; 49 points give no sample there, 50 give one.
TEST(PointCloudWallSamples, FiftyPointsMakeAWallFortyNineDoNot) {
  for (int n : {49, 50}) {
    std::vector<CloudPoint> cloud;
    const Vector3d sensor(0.027, 1, 1.2);
    AddColumn(cloud, {0.012, 0.025}, 0, 2.5, n / 3 + (n % 3 > 0), sensor);
    AddColumn(cloud, {0.027, 0.025}, 0, 2.5, n / 3 + (n % 3 > 1), sensor);
    AddColumn(cloud, {0.042, 0.025}, 0, 2.5, n / 3, sensor);
    ASSERT_EQ(cloud.size(), static_cast<size_t>(n));
    PointCloudWallSampleReport rep;
    absl::StatusOr<WallSampleSet> set = SamplesOf(cloud, {}, &rep);
    ASSERT_TRUE(set.ok()) << set.status();
    EXPECT_EQ(SamplesInCell(*set, 0, 0), n >= 50 ? 1u : 0u) << n << " points";
    EXPECT_EQ(rep.dense, n >= 50 ? 1u : 0u) << n << " points";
    EXPECT_EQ(set->samples.size(), n >= 50 ? 1u : 0u);
    if (n >= 50) {
      EXPECT_NEAR(set->samples[0].position.x(), 0.027, 0.002);
      EXPECT_NEAR(set->samples[0].position.y(), 0.025, 0.002);
      EXPECT_NEAR(std::abs(set->samples[0].normal.y()), 1, 1e-9);  // the columns lie along x
      EXPECT_GT(set->samples[0].normal.y(), 0);                    // towards the sensor
    }
  }
}

// Vertical support ≥ H = 2 m: two walls whose histograms pass (their tops reach the ceiling,
// ≥ 12 of 16 bins filled), one 2.1 m tall, one 1.9 m tall.
TEST(PointCloudWallSamples, WallsShorterThanTwoMetresAreNotWalls) {
  std::vector<CloudPoint> cloud;
  AddWallX(cloud, 0.01, 0, 1, 0.4, 2.5, {1, 0.5, 1.2});  // points over 0.44–2.46: 2.02 m
  AddWallX(cloud, 1.01, 2, 3, 0.6, 2.5, {2, 2.5, 1.2});  // 0.64–2.46: 1.83 m
  PointCloudWallSampleReport rep;
  absl::StatusOr<WallSampleSet> set = SamplesOf(cloud, {}, &rep);
  ASSERT_TRUE(set.ok()) << set.status();
  size_t tall = 0, short_wall = 0;
  for (const WallSample& s : set->samples) {
    (s.position.x() < 0.5 ? tall : short_wall) += 1;
    EXPECT_GE(s.ceiling_z - s.floor_z, 2.0);
  }
  EXPECT_GE(tall, 18u);
  EXPECT_EQ(short_wall, 0u);
  // The same with H = 1.8 m: the short wall is a wall too.
  PointCloudWallSampleOptions low;
  low.min_wall_height_m = 1.8;
  set = SamplesOf(cloud, low);
  ASSERT_TRUE(set.ok()) << set.status();
  short_wall = 0;
  for (const WallSample& s : set->samples) short_wall += s.position.x() > 0.5;
  EXPECT_GE(short_wall, 18u);
}

// The 16-bin histogram over the level's floor to ceiling (§3.1.1): ≥ 12 bins non-empty and
// ≥ 3 of the top 4. Four walls, all taller than 2 m and equally dense:
//   A: the full height with one bin empty (15 filled)                → wall
//   B: z ∈ [0, 0.8] ∪ [1.9, 2.5]: 5 + 4 = 9 bins filled               → not (a table and a shelf)
//   C: z ∈ [0, 2.1]: 14 bins, but only 2 of the top 4 (not to the ceiling) → not
//   D: z ∈ [0, 2.2] ∪ [2.35, 2.5]: 14 + 1 bins, 3 of the top 4        → wall
// Bins are 2.5 / 16 = 0.15625 m.
TEST(PointCloudWallSamples, HeightHistogramRule) {
  const double b = 2.5 / 16;
  std::vector<CloudPoint> cloud;
  auto wall = [&](double x, std::vector<std::pair<double, double>> spans) {
    for (double y = 0; y <= 1 + 1e-9; y += 0.01) {
      for (const auto& [z0, z1] : spans) {
        AddColumn(cloud, {x, y}, z0, z1, static_cast<int>(std::round((z1 - z0) / 0.05)),
                  {x + 1, 0.5, 1.2});
      }
    }
  };
  wall(0.01, {{0, 7 * b - 0.01}, {8 * b + 0.01, 2.5}});   // A: bin 7 empty
  wall(2.01, {{0, 0.8}, {1.9, 2.5}});                     // B
  wall(4.01, {{0, 2.1}});                                 // C
  wall(6.01, {{0, 14 * b - 0.01}, {15 * b + 0.01, 2.5}}); // D: bin 14 empty
  PointCloudWallSampleReport rep;
  absl::StatusOr<WallSampleSet> set = SamplesOf(cloud, {}, &rep);
  ASSERT_TRUE(set.ok()) << set.status();
  size_t per_wall[4] = {0, 0, 0, 0};
  for (const WallSample& s : set->samples) {
    per_wall[std::clamp(static_cast<int>(s.position.x() / 2), 0, 3)] += 1;
  }
  EXPECT_GE(per_wall[0], 18u) << "A";
  EXPECT_EQ(per_wall[1], 0u) << "B";
  EXPECT_EQ(per_wall[2], 0u) << "C";
  EXPECT_GE(per_wall[3], 18u) << "D";
  EXPECT_GT(rep.tall, rep.uniform);  // B and C are tall and dense but not uniform
}

// PCA confidence c = 1 − 2λ1/(λ1+λ2) ≥ 0.15 (§3.1.1): four columns at the cell centre ± (u, 0)
// and ± (0, v) give λ = u²/2, v²/2, so c = (v² − u²)/(v² + u²): v/u = 1.175 gives c = 0.160
// (a wall), v/u = 1.151 gives c = 0.140 (not). The centre cell is the only neighbourhood that
// holds all four columns (200 points); the others hold at most two.
TEST(PointCloudWallSamples, NormalConfidenceThreshold) {
  for (double ratio : {1.151, 1.175}) {
    const double u = 0.02, v = u * ratio;
    const double c = (v * v - u * u) / (v * v + u * u);
    std::vector<CloudPoint> cloud;
    const Vector2d centre(0.025, 0.025);
    const Vector3d sensor(0.025, 2, 1.2);
    for (const Vector2d& d : {Vector2d(u, 0), Vector2d(-u, 0), Vector2d(0, v), Vector2d(0, -v)}) {
      AddColumn(cloud, centre + d, 0, 2.5, 50, sensor);
    }
    absl::StatusOr<WallSampleSet> set = SamplesOf(cloud);
    ASSERT_TRUE(set.ok()) << set.status();
    EXPECT_EQ(SamplesInCell(*set, 0, 0), c >= 0.15 ? 1u : 0u) << "c = " << c;
    if (c >= 0.15) {
      // λ1's eigenvector is along x (the narrower spread). The sensor lies along +y, square
      // to it, so the flip has no side to choose: only the axis is checked.
      for (const WallSample& s : set->samples) {
        if (static_cast<int>(std::floor(s.position.x() / kDs)) != 0) continue;
        EXPECT_NEAR(std::abs(s.normal.x()), 1, 1e-9);
        EXPECT_NEAR((s.position - centre).norm(), 0, 0.002);
      }
    }
  }
  // A solid round column (a pillar thinner than a cell): no direction, c ≈ 0, no sample.
  std::vector<CloudPoint> pillar;
  for (int k = 0; k < 24; ++k) {
    const double a = 2 * M_PI * k / 24;
    AddColumn(pillar, Vector2d(0.025, 0.025) + 0.015 * Vector2d(std::cos(a), std::sin(a)), 0,
              2.5, 20, {1, 1, 1.2});
  }
  PointCloudWallSampleReport rep;
  absl::StatusOr<WallSampleSet> set = SamplesOf(pillar, {}, &rep);
  ASSERT_TRUE(set.ok()) << set.status();
  EXPECT_EQ(SamplesInCell(*set, 0, 0), 0u);
  EXPECT_GT(rep.uniform, rep.flat);
}

// Poses (§3.1.1: the scanners that observed the sample): a wall scanned from one end of the
// path gets that end's kept poses, not the other's; a pose off the level is not kept.
TEST(PointCloudWallSamples, PosesAreTheScannersThatSawTheSample) {
  std::vector<TimedPose> path;
  for (int i = 0; i <= 40; ++i) {  // 10 m in 10 s along y = 5, at z = 1.2
    TimedPose p;
    p.t = 0.25 * i;
    p.pose.translation = Vector3d(0.25 * i, 5, 1.2);
    path.push_back(p);
  }
  std::vector<CloudPoint> cloud;
  // Wall W1 (x = 0.01, y ∈ [3, 4]) seen at t = 1 s (x = 1); W2 (x = 9.01) at t = 9 s (x = 9).
  AddWallX(cloud, 0.01, 3, 4, 0, 2.5, {1, 5, 1.2}, 1.0);
  AddWallX(cloud, 9.01, 3, 4, 0, 2.5, {9, 5, 1.2}, 9.0);
  std::vector<PointCloudWallSampleReport> reports;
  const Level level = OneLevel();
  absl::StatusOr<std::vector<WallSampleSet>> sets =
      PointCloudWallSamples(StreamOf(cloud), {&level, 1}, path, {}, &reports);
  ASSERT_TRUE(sets.ok()) << sets.status();
  const WallSampleSet& set = (*sets)[0];
  EXPECT_EQ(set.poses.size(), 41u);  // every 0.25 m
  EXPECT_EQ(reports[0].poses, 41u);
  ASSERT_GE(set.samples.size(), 36u);
  for (const WallSample& s : set.samples) {
    ASSERT_EQ(s.poses.size(), 1u) << s.position.transpose();
    const Vector2d& q = set.poses[s.poses[0]];
    EXPECT_NEAR(q.x(), s.position.x() < 5 ? 1.0 : 9.0, 1e-9);
    EXPECT_NEAR(q.y(), 5, 1e-9);
  }
  EXPECT_EQ(reports[0].samples_with_poses, set.samples.size());
}

// §2.5's histogram: points seen from above count as floor, from below as ceiling; a level
// scanner's near-horizontal rays (a wall 3 m away, 1 cm below the scanner) count as neither.
TEST(PointCloudWallSamples, HeightHistogramSplitsFloorAndCeiling) {
  std::vector<CloudPoint> cloud;
  for (int i = 0; i < 100; ++i) {
    cloud.push_back({Vector3d(0.01 * i, 0, 0.01), {0, 0, 1.2}, 0});  // floor, seen from above
    cloud.push_back({Vector3d(0.01 * i, 0, 2.61), {0, 0, 1.2}, 0});  // ceiling, from below
    cloud.push_back({Vector3d(3, 0.01 * i, 1.19), {0, 0, 1.2}, 0});  // a wall, level ray
  }
  absl::StatusOr<HeightHistogram> h = PointCloudHeightHistogram(StreamOf(cloud), 0.02);
  ASSERT_TRUE(h.ok()) << h.status();
  double floor_total = 0, ceiling_total = 0;
  for (size_t b = 0; b < h->floor.size(); ++b) {
    const double z = h->z0_m + (b + 0.5) * h->bin_m;
    floor_total += h->floor[b];
    ceiling_total += h->ceiling[b];
    if (h->floor[b] > 0) {
      EXPECT_NEAR(z, 0.01, 0.011);
    }
    if (h->ceiling[b] > 0) {
      EXPECT_NEAR(z, 2.61, 0.011);
    }
  }
  EXPECT_EQ(floor_total, 100);
  EXPECT_EQ(ceiling_total, 100);
  // With every ray counted, the wall's 100 points make a floor peak at the scanner's height.
  h = PointCloudHeightHistogram(StreamOf(cloud), 0.02, 0);
  ASSERT_TRUE(h.ok()) << h.status();
  const size_t wall_bin = static_cast<size_t>(std::floor((1.19 - h->z0_m) / h->bin_m));
  EXPECT_EQ(h->floor[wall_bin], 100);
  EXPECT_EQ(PointCloudHeightHistogram(StreamOf(cloud), 0.02, 90).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(PointCloudHeightHistogram(StreamOf(cloud), 0).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------- simulated buildings

struct PresetCase {
  const char* preset;
  double walk_s;  // 0 = the whole walk
  // Measured (printed below), bounds a margin under them.
  double min_samples;
  double min_within_5cm;    // fraction of samples
  double min_normal_ok;     // fraction: into a true room and within 10° of the nearest wall's
  double min_floor_ok;      // fraction of those facing a room: floor within 5 cm of the truth
  double min_ceiling_ok;    // same for the ceiling
  double min_with_poses;    // fraction of samples
};

void PrintTo(const PresetCase& c, std::ostream* os) { *os << c.preset << " " << c.walk_s << " s"; }

class SimulatedPointCloudWallSamples : public ::testing::TestWithParam<PresetCase> {};

// The targets for wall samples: the median ≤ 2 cm from the true walls; here also the
// normals (into the room the sample faces, perpendicular to the wall), the heights (the room's
// floor and ceiling: the cloud's wall extremes) and the poses (a kept pose on the sample's
// side of the wall, the side its normal faces).
TEST_P(SimulatedPointCloudWallSamples, SamplesLieOnTheTrueWalls) {
  const PresetCase& c = GetParam();
  SimulateOptions sim;
  sim.preset = c.preset;
  sim.seed = 1;
  sim.rig.rate_hz = 20;
  sim.rig.beam_step_deg = 0.5;
  sim.noise.drift = false;  // range noise and clock jitter stay on
  sim.max_duration_s = c.walk_s;
  sim.threads = 2;
  sim.output_dir = ::testing::TempDir() + "/pcws_" + c.preset;
  absl::StatusOr<SimulationSummary> summary = Simulate(sim);
  ASSERT_TRUE(summary.ok()) << summary.status();

  absl::StatusOr<std::unique_ptr<ScanCloudStream>> scan = ScanCloudStream::Open(summary->scan_path);
  ASSERT_TRUE(scan.ok()) << scan.status();
  std::ifstream in(summary->gt_dir + "/building.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json truth = nlohmann::json::parse(in);

  // Levels from the cloud's own histogram (§2.5), as `carvemap floorplan --cloud` does.
  absl::StatusOr<HeightHistogram> hist = PointCloudHeightHistogram((*scan)->Stream());
  ASSERT_TRUE(hist.ok()) << hist.status();
  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromHistogram(*hist);
  ASSERT_TRUE(levels.ok()) << levels.status();
  ASSERT_EQ(levels->size(), 1u);
  const double true_floor = truth.at("levels").at(0).at("floor_z").get<double>();
  EXPECT_NEAR((*levels)[0].floor_z, true_floor, 0.05);

  std::vector<PointCloudWallSampleReport> reports;
  absl::StatusOr<std::vector<WallSampleSet>> sets = PointCloudWallSamples(
      (*scan)->Stream(), *levels, (*scan)->path(), PointCloudWallSampleOptions{}, &reports);
  ASSERT_TRUE(sets.ok()) << sets.status();
  ASSERT_EQ(sets->size(), 1u);
  const WallSampleSet& set = (*sets)[0];
  ASSERT_TRUE(set.Validate().ok()) << set.Validate();
  const PointCloudWallSampleReport& rep = reports[0];

  const std::vector<TruthRoom> rooms = testing::TruthRoomsOfLevel(truth, 0);
  ASSERT_FALSE(rooms.empty());

  const size_t n = set.samples.size();
  ASSERT_GE(n, c.min_samples);
  std::vector<double> dist;
  size_t within_5cm = 0, normal_ok = 0, facing_room = 0, floor_ok = 0, ceiling_ok = 0,
         outside_room_heights = 0, with_poses = 0, pose_on_side = 0;
  std::set<std::pair<int, int>> cells;
  for (const WallSample& w : set.samples) {
    EXPECT_NEAR(w.normal.norm(), 1, 1e-9);
    EXPECT_TRUE(cells
                    .insert({static_cast<int>(std::floor(w.position.x() / kDs)),
                             static_cast<int>(std::floor(w.position.y() / kDs))})
                    .second)
        << "two samples in one d_s cell";
    EXPECT_GE(w.ceiling_z - w.floor_z, 2.0);  // H
    const testing::NearestWall wall = testing::NearestTrueWall(rooms, w.position);
    const double best = wall.distance_m;
    const Vector2d& wall_dir = wall.direction;
    dist.push_back(best);
    within_5cm += best <= 0.05;
    with_poses += !w.poses.empty();
    // The room the normal points into.
    const Vector2d inside = w.position + 0.15 * w.normal;
    const TruthRoom* room = nullptr;
    for (const TruthRoom& r : rooms) {
      if (RingContains(r.rings[0], inside)) room = &r;
    }
    const bool perpendicular = std::abs(w.normal.dot(wall_dir)) <= std::sin(10 * M_PI / 180);
    normal_ok += room != nullptr && perpendicular;
    if (room != nullptr) {
      ++facing_room;
      floor_ok += std::abs(w.floor_z - room->floor_z) <= 0.05;
      ceiling_ok += std::abs(w.ceiling_z - room->ceiling_z) <= 0.05;
      // The extremes of a wall's points can miss the wall's ends (hidden behind furniture or
      // a door header) but never pass the room's floor or ceiling (only range noise).
      outside_room_heights +=
          w.floor_z < room->floor_z - 0.05 || w.ceiling_z > room->ceiling_z + 0.05;
    }
    bool side = false;
    for (uint32_t p : w.poses) side |= (set.poses[p] - w.position).dot(w.normal) > 0;
    pose_on_side += side;
  }
  std::vector<double> sorted = dist;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[n / 2];
  std::printf(
      "[%s %.0f s] %llu points, %zu cells, dense %zu tall %zu uniform %zu flat %zu, samples %zu "
      "(%zu with poses, %zu poses); level floor %.3f ceiling %.3f (truth floor %.3f); distance "
      "to true walls median %.4f m p90 %.4f m, within 5 cm %.1f%%; normal into a room and "
      "perpendicular %.1f%%; facing a room %zu: floor within 5 cm %.1f%%, ceiling %.1f%%, "
      "beyond the room's %zu; a pose on the normal's side %.1f%%\n",
      c.preset, summary->duration_s, static_cast<unsigned long long>(rep.points), rep.cells,
      rep.dense, rep.tall, rep.uniform, rep.flat, rep.samples, rep.samples_with_poses, rep.poses,
      (*levels)[0].floor_z, (*levels)[0].ceiling_z, true_floor, median, sorted[n * 9 / 10],
      100.0 * within_5cm / n, 100.0 * normal_ok / n, facing_room,
      100.0 * floor_ok / std::max<size_t>(1, facing_room),
      100.0 * ceiling_ok / std::max<size_t>(1, facing_room), outside_room_heights,
      100.0 * pose_on_side / n);
  EXPECT_EQ(rep.samples, n);
  EXPECT_LE(median, 0.02);
  EXPECT_GE(within_5cm, c.min_within_5cm * n);
  EXPECT_GE(normal_ok, c.min_normal_ok * n);
  ASSERT_GE(facing_room, 0.95 * n);
  EXPECT_GE(floor_ok, c.min_floor_ok * facing_room);
  EXPECT_GE(ceiling_ok, c.min_ceiling_ok * facing_room);
  EXPECT_EQ(outside_room_heights, 0u);
  EXPECT_GE(with_poses, c.min_with_poses * n);
  EXPECT_GE(pose_on_side, c.min_with_poses * n);
}

// Measured (20 Hz, 0.5° beams, no drift): room (whole 24 s walk) 413 samples,
// median 0.2 mm from the walls, 100 % within 5 cm, normals 96.9 %, floor 88.3 % (the misses
// are up to 0.7 m high: furniture against the wall hides its foot), ceiling 100 %, poses 100 %;
// office (first 20 s) 782 samples, median 0.4 mm, 99.7 % within 5 cm, normals 94.9 %, floor
// 79.2 %, ceiling 80.4 % (the misses are the far offices' walls seen through a door, their
// tops under the header and feet behind furniture), poses 100 %.
INSTANTIATE_TEST_SUITE_P(Presets, SimulatedPointCloudWallSamples,
                         ::testing::Values(PresetCase{"room", 0, 350, 0.97, 0.93, 0.85, 0.97, 0.95},
                                           PresetCase{"office", 20, 650, 0.97, 0.9, 0.75, 0.75,
                                                      0.95}),
                         [](const auto& info) { return std::string(info.param.preset); });

}  // namespace
}  // namespace carvemap
