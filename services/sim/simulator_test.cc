#include "services/sim/simulator.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include "services/sim/raycaster.h"
#include "services/sim/sim_test_util.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

std::vector<TimedPose> ToTimed(const std::vector<PathRecord>& path) {
  std::vector<TimedPose> out;
  for (const PathRecord& r : path) {
    out.push_back(TimedPose{r.t, Pose{Eigen::Quaterniond(r.qw, r.qx, r.qy, r.qz), {r.x, r.y, r.z}}});
  }
  return out;
}

SimulateOptions Thin(uint64_t seed = 1) {
  SimulateOptions o;
  o.seed = seed;
  o.rig.rate_hz = 10;
  o.rig.beam_step_deg = 1;
  return o;
}

Pose SensorPose(const SensorInfo& s) {
  return Pose{Eigen::Quaterniond(s.R_s2c).normalized(), s.T_s2c};
}

class SimulatorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    room_ = testing::MakeBoxRoom();
    auto c = RayCaster::Create(StructureMesh(room_), ObjectsMesh(room_));
    ASSERT_TRUE(c.ok()) << c.status();
    caster_ = *std::move(c);
  }
  Building room_;
  std::unique_ptr<RayCaster> caster_;
};

TEST_F(SimulatorTest, NoiselessPointsLieOnTheTruthMesh) {
  SimulateOptions o = Thin();
  o.noise.enabled = false;
  MemoryScanSink sink;
  auto summary = SimulateBuilding(room_, o, sink);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_GT(summary->frames, 100u);
  EXPECT_EQ(summary->hits, summary->rays);  // a closed room: every beam returns
  ASSERT_EQ(sink.sensors.size(), 3u);
  const std::vector<TimedPose> path = ToTimed(sink.path);
  double worst = 0;
  size_t checked = 0;
  for (const auto& f : sink.frames) {
    const Pose T = PoseAtTime(path, f.t) * SensorPose(sink.sensors[f.sensor]);
    for (const Eigen::Vector3f& p : f.points_sensor) {
      ASSERT_TRUE(p.allFinite());
      const Eigen::Vector3f w = (T * p.cast<double>()).cast<float>();
      worst = std::max(worst, double(caster_->Closest(w).distance_m));
      ++checked;
    }
  }
  EXPECT_GT(checked, 50000u);
  EXPECT_LT(worst, 1e-3);
  // The recorded path is the true path.
  ASSERT_EQ(sink.path.size(), summary->true_path.size());
  for (size_t i = 0; i < sink.path.size(); i += 50) {
    EXPECT_NEAR(sink.path[i].x, summary->true_path[i].pose.translation.x(), 1e-12);
  }
}

TEST_F(SimulatorTest, RangeNoiseAndClockJitterStatistics) {
  SimulateOptions o = Thin(3);
  o.noise.drift = false;
  MemoryScanSink sink;
  std::vector<double> z;            // (noisy − true) / (a + b·range)
  std::vector<double> jitter;
  std::vector<double> last(3, -1);
  bool ascending = true;
  auto summary = SimulateBuilding(room_, o, sink, {}, [&](const FrameTruth& f) {
    for (size_t j = 0; j < f.true_ranges_m.size(); ++j) {
      if (!std::isfinite(f.true_ranges_m[j])) continue;
      const double r = f.true_ranges_m[j];
      z.push_back((f.points_sensor[j].norm() - r) / (o.noise.range_a_m + o.noise.range_b * r));
    }
    jitter.push_back(f.recorded_t - f.true_t);
    ascending = ascending && f.recorded_t > last[f.sensor];
    last[f.sensor] = f.recorded_t;
  });
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_TRUE(ascending);
  ASSERT_GT(z.size(), 30000u);
  double m = 0, v = 0;
  for (double x : z) m += x;
  m /= z.size();
  for (double x : z) v += (x - m) * (x - m);
  EXPECT_NEAR(m, 0.0, 0.02);
  EXPECT_NEAR(std::sqrt(v / z.size()), 1.0, 0.02);
  double jv = 0;
  for (double x : jitter) jv += x * x;
  EXPECT_NEAR(std::sqrt(jv / jitter.size()), o.noise.sigma_t_s, 0.15 * o.noise.sigma_t_s);
  EXPECT_DOUBLE_EQ(sink.sensors[0].range_sigma[0], o.noise.range_a_m);
  EXPECT_DOUBLE_EQ(sink.sensors[0].sigma_t_s, o.noise.sigma_t_s);
  // Frame times strictly ascending per sensor in what was written too.
  std::vector<double> prev(3, -1);
  for (const auto& f : sink.frames) {
    EXPECT_GT(f.t, prev[f.sensor]);
    prev[f.sensor] = f.t;
    EXPECT_GE(f.t, sink.path.front().t);
    EXPECT_LE(f.t, sink.path.back().t);
  }
}

TEST_F(SimulatorTest, DriftMatchesItsCovariance) {
  // A short correlation time so a box-room walk spans many of them; over several seeds the
  // normalized errors e^T C^{-1} e average 3 per block (position, rotation).
  double pos = 0, rot = 0, n = 0, sxy = 0;
  for (uint64_t seed = 1; seed <= 24; ++seed) {
    SimulateOptions o = Thin(seed);
    o.rig.rate_hz = 2;
    o.rig.beam_step_deg = 10;
    o.noise.drift_options.tau_s = 3;
    MemoryScanSink sink;
    auto summary = SimulateBuilding(room_, o, sink);
    ASSERT_TRUE(summary.ok()) << summary.status();
    ASSERT_EQ(sink.path_cov.size(), sink.path.size());
    for (size_t i = 0; i < sink.path.size(); ++i) {
      const PathRecord& r = sink.path[i];
      const Pose& truth = summary->true_path[i].pose;
      const Eigen::Vector3d ep = Eigen::Vector3d(r.x, r.y, r.z) - truth.translation;
      const Eigen::Vector3d er =
          RotationLog(Eigen::Quaterniond(r.qw, r.qx, r.qy, r.qz) * truth.rotation.conjugate());
      const PathCovariance& c = sink.path_cov[i];
      pos += ep.x() * ep.x() / c[0] + ep.y() * ep.y() / c[3] + ep.z() * ep.z() / c[5];
      rot += er.x() * er.x() / c[6] + er.y() * er.y() / c[9] + er.z() * er.z() / c[11];
      sxy += ep.x() * ep.x();
      n += 1;
    }
  }
  EXPECT_NEAR(pos / n, 3.0, 0.6);
  EXPECT_NEAR(rot / n, 3.0, 0.6);
  EXPECT_GT(std::sqrt(sxy / n), 0.05);
  EXPECT_LT(std::sqrt(sxy / n), 0.15);
}

TEST_F(SimulatorTest, MagnetometerPointsNorthAndDown) {
  MemoryScanSink sink;
  auto summary = SimulateBuilding(room_, Thin(), sink);
  ASSERT_TRUE(summary.ok()) << summary.status();
  ASSERT_GT(sink.magnetometer.size(), 50u);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const MagnetometerRecord& m : sink.magnetometer) {
    const Pose truth = PoseAtTime(summary->true_path, m.t);
    mean += truth.rotation * Eigen::Vector3d(m.mx, m.my, m.mz);
  }
  mean /= sink.magnetometer.size();
  EXPECT_LT((mean - kWorldMagneticField_uT).norm(), 1.0);
}

TEST_F(SimulatorTest, DeterministicAcrossThreadCounts) {
  auto run = [&](uint64_t seed, int threads) {
    SimulateOptions o = Thin(seed);
    o.threads = threads;
    MemoryScanSink sink;
    EXPECT_TRUE(SimulateBuilding(room_, o, sink).ok());
    return sink;
  };
  const MemoryScanSink a = run(5, 1), b = run(5, 2), c = run(6, 1);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  bool same_as_c = a.frames.size() == c.frames.size();
  for (size_t i = 0; i < a.frames.size(); ++i) {
    ASSERT_EQ(a.frames[i].t, b.frames[i].t);
    ASSERT_EQ(a.frames[i].sensor, b.frames[i].sensor);
    ASSERT_EQ(a.frames[i].points_sensor.size(), b.frames[i].points_sensor.size());
    ASSERT_EQ(0, std::memcmp(a.frames[i].points_sensor.data(), b.frames[i].points_sensor.data(),
                             a.frames[i].points_sensor.size() * sizeof(Eigen::Vector3f)));
    if (same_as_c && i < c.frames.size()) same_as_c = a.frames[i].t == c.frames[i].t;
  }
  EXPECT_FALSE(same_as_c);
  ASSERT_EQ(a.path.size(), b.path.size());
  EXPECT_EQ(0, std::memcmp(a.path.data(), b.path.data(), a.path.size() * sizeof(PathRecord)));
}

TEST_F(SimulatorTest, WritesAReadableScanFile) {
  const std::string dir = ::testing::TempDir() + "/sim_write";
  std::filesystem::create_directories(dir);
  const std::string file = dir + "/scan.h5";
  SimulateOptions o = Thin();
  o.noise.enabled = false;
  {
    auto writer = ScanWriter::Create(file);
    ASSERT_TRUE(writer.ok()) << writer.status();
    ScanWriterSink sink(**writer);
    auto summary = SimulateBuilding(room_, o, sink);
    ASSERT_TRUE(summary.ok()) << summary.status();
    ASSERT_TRUE((*writer)->Close().ok());
  }
  auto reader = ScanReader::Open(file);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ASSERT_TRUE((*reader)->Validate().ok()) << (*reader)->Validate();
  ASSERT_EQ((*reader)->sensors().size(), 3u);
  auto stream = (*reader)->StreamFrames();
  ScanFrame frame;
  double worst = 0;
  size_t frames = 0;
  while (true) {
    auto more = stream->Next(frame);
    ASSERT_TRUE(more.ok()) << more.status();
    if (!*more) break;
    ++frames;
    const Pose T = (*reader)->PoseAt(frame.t) * SensorPose((*reader)->sensors()[frame.sensor]);
    for (const Eigen::Vector3f& p : frame.points_sensor) {
      worst = std::max(worst, double(caster_->Closest((T * p.cast<double>()).cast<float>())
                                         .distance_m));
    }
  }
  EXPECT_GT(frames, 100u);
  EXPECT_LT(worst, 1e-3);
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(Simulate, RoomPresetIsByteIdenticalPerSeed) {
  auto run = [](uint64_t seed, const std::string& name) -> absl::StatusOr<SimulationSummary> {
    SimulateOptions o = Thin(seed);
    o.preset = "room";
    o.output_dir = ::testing::TempDir() + "/sim_room_" + name;
    std::filesystem::remove_all(o.output_dir);
    return Simulate(o);
  };
  auto a = run(1, "a");
  if (a.status().code() == absl::StatusCode::kUnimplemented) GTEST_SKIP() << a.status();
  ASSERT_TRUE(a.ok()) << a.status();
  auto b = run(1, "b");
  auto c = run(2, "c");
  ASSERT_TRUE(b.ok() && c.ok());
  EXPECT_TRUE(std::filesystem::exists(a->gt_dir + "/building.json"));
  EXPECT_TRUE(std::filesystem::exists(a->gt_dir + "/surfaces.ply"));
  const std::string fa = ReadBytes(a->scan_path), fb = ReadBytes(b->scan_path),
                    fc = ReadBytes(c->scan_path);
  EXPECT_GT(fa.size(), 1000u);
  EXPECT_TRUE(fa == fb) << "same seed, different bytes";
  EXPECT_FALSE(fa == fc);
  EXPECT_GT(a->path_length_m / a->duration_s, 0.7);
  EXPECT_LT(a->path_length_m / a->duration_s, 1.3);
  EXPECT_GE(a->rooms_entered, 1);
}

}  // namespace
}  // namespace carvemap
