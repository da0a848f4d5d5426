#include "services/sim/simulator.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>
#include <random>
#include <thread>

#include "absl/strings/str_cat.h"
#include "services/building/building_presets.h"
#include "services/building/floormap_building.h"
#include "services/building/truth_writer.h"
#include "services/sim/raycaster.h"
#include "storage/scan_writer.h"

namespace carvemap {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInfF = std::numeric_limits<float>::infinity();
constexpr size_t kBatchFrames = 128;

uint64_t SplitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Every frame's noise comes from its own generator, so the output does not depend on which
// thread casts which frame.
uint64_t FrameSeed(uint64_t seed, int sensor, uint64_t frame) {
  return SplitMix(SplitMix(SplitMix(seed) ^ static_cast<uint64_t>(sensor + 1)) ^ frame);
}

struct FrameJob {
  double t;
  int sensor;
  uint64_t index;
};

struct FrameOutput {
  std::vector<Eigen::Vector3f> points;
  std::vector<float> true_ranges;
  double jitter_s = 0;
  uint64_t hits = 0;
};

struct ThreadScratch {
  std::vector<RayQuery> rays;
  std::vector<RayHitResult> hits;
};

class FrameSimulator {
 public:
  FrameSimulator(const RayCaster& caster, const std::vector<LineScanner>& rig,
                 std::span<const TimedPose> true_path, const SimulateOptions& o)
      : caster_(caster), rig_(rig), path_(true_path), o_(o) {}

  void Run(const FrameJob& job, ThreadScratch& scratch, FrameOutput& out) const {
    const LineScanner& sc = rig_[job.sensor];
    // Rays leave the TRUE sensor pose at the TRUE frame time (docs/DESIGN.md §4); the file gets the
    // drifted path and the jittered time.
    const Pose T_world_sensor = PoseAtTime(path_, job.t) * sc.T_system_sensor;
    const Eigen::Matrix3f R = T_world_sensor.rotation.toRotationMatrix().cast<float>();
    const Eigen::Vector3f origin = T_world_sensor.translation.cast<float>();
    const size_t n = sc.beams_sensor.size();
    scratch.rays.resize(n);
    scratch.hits.resize(n);
    for (size_t j = 0; j < n; ++j) {
      scratch.rays[j] = RayQuery{origin, R * sc.beams_sensor[j],
                                 static_cast<float>(sc.max_range_m)};
    }
    caster_.Cast(scratch.rays, scratch.hits);
    std::mt19937_64 rng(FrameSeed(o_.seed, job.sensor, job.index));
    std::normal_distribution<double> normal(0.0, 1.0);
    const bool noisy = o_.noise.enabled && o_.noise.range_noise;
    out.points.resize(n);
    out.true_ranges.resize(n);
    out.hits = 0;
    for (size_t j = 0; j < n; ++j) {
      const RayHitResult& h = scratch.hits[j];
      if (!h.hit()) {  // nothing within max range (e.g. out through a window): a NaN row
        out.points[j] = Eigen::Vector3f::Constant(kNaN);
        out.true_ranges[j] = kInfF;
        continue;
      }
      ++out.hits;
      double r = h.distance_m;
      out.true_ranges[j] = h.distance_m;
      // §2.1/§4.1.1: Hokuyo range noise, 1–2 cm, growing with range.
      if (noisy) r = std::max(0.0, r + (o_.noise.range_a_m + o_.noise.range_b * r) * normal(rng));
      out.points[j] = sc.beams_sensor[j] * static_cast<float>(r);
    }
    out.jitter_s = 0;
    if (o_.noise.enabled && o_.noise.clock_jitter) {
      // §4.1.1: σ_t ≈ 1 ms clock sync error; truncated well inside a frame period so per-sensor
      // times stay ascending.
      const double limit = 0.3 / sc.rate_hz;
      out.jitter_s = std::clamp(o_.noise.sigma_t_s * normal(rng), -limit, limit);
    }
  }

 private:
  const RayCaster& caster_;
  const std::vector<LineScanner>& rig_;
  std::span<const TimedPose> path_;
  const SimulateOptions& o_;
};

PathRecord ToRecord(double t, const Pose& p) {
  const Eigen::Quaterniond q = p.rotation.normalized();
  return PathRecord{t,     p.translation.x(), p.translation.y(), p.translation.z(),
                    q.w(), q.x(),             q.y(),             q.z()};
}

absl::StatusOr<Building> MakeBuilding(const SimulateOptions& o) {
  if (o.floormap_png.empty()) return MakePresetBuilding(o.preset, o.seed);
  FloormapOptions f;
  f.map_path = o.floormap_png;
  f.furniture_map_path = o.furniture_png;
  f.rooms_map_path = o.rooms_png;
  f.resolution_m = o.resolution_m;
  return MakeFloormapBuilding(f);
}

}  // namespace

absl::Status NoiseOptions::Validate() const {
  if (absl::Status s = drift_options.Validate(); !s.ok()) return s;
  if (!(sigma_t_s >= 0 && sigma_t_s < 0.01)) {
    return absl::InvalidArgumentError("noise: sigma_t_s must be in [0, 0.01)");
  }
  if (!(range_a_m >= 0 && range_a_m < 1 && range_b >= 0 && range_b < 0.1)) {
    return absl::InvalidArgumentError("noise: range sigma a must be in [0, 1) m, b in [0, 0.1)");
  }
  if (magnetometer && !(magnetometer_rate_hz > 0 && magnetometer_rate_hz <= 1000)) {
    return absl::InvalidArgumentError("noise: magnetometer_rate_hz must be in (0, 1000]");
  }
  return absl::OkStatus();
}

absl::Status SimulateOptions::Validate() const {
  if (floormap_png.empty() && preset.empty()) {
    return absl::InvalidArgumentError("simulate: give a preset or a floor map");
  }
  if (!floormap_png.empty() && !(resolution_m > 0)) {
    return absl::InvalidArgumentError("simulate: resolution_m must be > 0");
  }
  if (threads < 1 || threads > 256) {
    return absl::InvalidArgumentError("simulate: threads must be in [1, 256]");
  }
  if (max_duration_s < 0) return absl::InvalidArgumentError("simulate: max_duration_s < 0");
  if (!std::isfinite(frame_yaw_deg)) {
    return absl::InvalidArgumentError("simulate: frame_yaw_deg is not finite");
  }
  if (absl::Status s = rig.Validate(); !s.ok()) return s;
  if (absl::Status s = walk.Validate(); !s.ok()) return s;
  return noise.Validate();
}

absl::StatusOr<SimulationSummary> SimulateBuilding(const Building& building,
                                                   const SimulateOptions& o, ScanSink& sink,
                                                   const ProgressCallback& progress,
                                                   const FrameTruthCallback& truth) {
  if (absl::Status s = o.Validate(); !s.ok()) return s;
  SimulationSummary summary;
  summary.building = building.name;

  // The walk.
  WalkOptions walk_options = o.walk;
  walk_options.seed = SplitMix(o.seed ^ 0x57A1Cull);
  auto walk = PlanWalk(building, walk_options);
  if (!walk.ok()) return walk.status();
  std::vector<TimedPose> true_path = std::move(walk->path);
  if (o.max_duration_s > 0) {
    while (true_path.size() > 2 && true_path.back().t > o.max_duration_s) true_path.pop_back();
  }
  if (true_path.size() < 2) return absl::InvalidArgumentError("simulate: the walk is too short");
  const double duration = true_path.back().t;
  summary.duration_s = duration;
  for (size_t i = 1; i < true_path.size(); ++i) {
    summary.path_length_m +=
        (true_path[i].pose.translation - true_path[i - 1].pose.translation).head<2>().norm();
  }
  summary.rooms_visited = walk->route.rooms_visited;
  summary.rooms_entered = static_cast<int>(summary.rooms_visited.size());

  // /path: the drifted estimate with its covariances (§2.2, §4.1.1).
  {
    const bool drift = o.noise.enabled && o.noise.drift;
    std::vector<double> times(true_path.size());
    for (size_t i = 0; i < times.size(); ++i) times[i] = true_path[i].t;
    std::vector<Eigen::Matrix<double, 6, 1>> err;
    if (drift) err = SampleDrift(o.noise.drift_options, times, SplitMix(o.seed ^ 0xD21F7ull));
    DriftOptions none = o.noise.drift_options;
    if (!drift) none.sigma_xy_m = none.sigma_z_m = none.sigma_yaw_rad = none.sigma_roll_pitch_rad = 0;
    constexpr size_t kBlock = 4096;
    std::vector<PathRecord> records;
    std::vector<PathCovariance> covs;
    for (size_t first = 0; first < true_path.size(); first += kBlock) {
      const size_t last = std::min(true_path.size(), first + kBlock);
      records.clear();
      covs.clear();
      for (size_t i = first; i < last; ++i) {
        const Pose est = drift ? ApplyDrift(true_path[i].pose, err[i]) : true_path[i].pose;
        records.push_back(ToRecord(true_path[i].t, est));
        covs.push_back(DriftCovariance(none, true_path[i].t));
        if (o.frame_yaw_deg != 0) {
          const double yaw = o.frame_yaw_deg * std::numbers::pi / 180;
          TurnAboutVertical(yaw, records.back());
          TurnAboutVertical(yaw, covs.back());
        }
      }
      if (absl::Status s = sink.AppendPath(records, covs); !s.ok()) return s;
    }
  }

  // Sensors.
  const std::vector<LineScanner> rig = MakeBackpackRig(o.rig);
  for (const LineScanner& sc : rig) {
    SensorInfo info;
    info.name = sc.name;
    info.kind = SensorKind::kLine;
    info.R_s2c = sc.T_system_sensor.rotation.toRotationMatrix();
    info.T_s2c = sc.T_system_sensor.translation;
    const bool on = o.noise.enabled;
    info.sigma_t_s = on && o.noise.clock_jitter ? o.noise.sigma_t_s : 0.0;
    info.range_sigma = on && o.noise.range_noise
                           ? std::array<double, 2>{o.noise.range_a_m, o.noise.range_b}
                           : std::array<double, 2>{0.0, 0.0};
    info.max_range_m = sc.max_range_m;
    auto id = sink.AddSensor(info);
    if (!id.ok()) return id.status();
    if (*id != static_cast<int>(&sc - rig.data())) {
      return absl::InternalError("simulate: sink returned unexpected sensor index");
    }
  }

  // /magnetometer (§2.3): the world field seen in the TRUE system frame, with noise.
  if (o.noise.magnetometer) {
    std::mt19937_64 rng(SplitMix(o.seed ^ 0x3A6ull));
    std::normal_distribution<double> normal(0.0, 1.0);
    const double sigma = o.noise.enabled ? o.noise.magnetometer_sigma_ut : 0.0;
    std::vector<MagnetometerRecord> mags;
    for (uint64_t k = 0;; ++k) {
      const double t = k / o.noise.magnetometer_rate_hz;
      if (t > duration) break;
      const Eigen::Vector3d m =
          PoseAtTime(true_path, t).rotation.conjugate() * kWorldMagneticField_uT;
      const double nx = normal(rng), ny = normal(rng), nz = normal(rng);
      mags.push_back(MagnetometerRecord{t, m.x() + sigma * nx, m.y() + sigma * ny,
                                        m.z() + sigma * nz});
    }
    if (absl::Status s = sink.AppendMagnetometer(mags); !s.ok()) return s;
  }

  // The frames, in time order across sensors.
  std::vector<FrameJob> jobs;
  constexpr double kMargin = 0.01;  // keep jittered times inside the path's span
  for (size_t s = 0; s < rig.size(); ++s) {
    for (uint64_t k = 0;; ++k) {
      const double t = rig[s].phase_s + k / rig[s].rate_hz;
      if (t > duration - kMargin) break;
      if (t < kMargin) continue;
      jobs.push_back(FrameJob{t, static_cast<int>(s), k});
    }
  }
  std::sort(jobs.begin(), jobs.end(), [](const FrameJob& a, const FrameJob& b) {
    return a.t != b.t ? a.t < b.t : a.sensor < b.sensor;
  });

  auto caster = RayCaster::Create(StructureMesh(building), ObjectsMesh(building));
  if (!caster.ok()) return caster.status();
  const FrameSimulator frame_sim(**caster, rig, true_path, o);
  const int threads = o.threads;
  std::vector<ThreadScratch> scratch(threads);
  std::vector<FrameOutput> outputs(kBatchFrames);
  std::vector<double> last_t(rig.size(), -std::numeric_limits<double>::infinity());
  const auto start = std::chrono::steady_clock::now();
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  for (size_t first = 0; first < jobs.size(); first += kBatchFrames) {
    const size_t count = std::min(kBatchFrames, jobs.size() - first);
    if (threads == 1) {
      for (size_t i = 0; i < count; ++i) frame_sim.Run(jobs[first + i], scratch[0], outputs[i]);
    } else {
      std::atomic<size_t> next{0};
      auto work = [&](int tid) {
        for (size_t i = next++; i < count; i = next++) {
          frame_sim.Run(jobs[first + i], scratch[tid], outputs[i]);
        }
      };
      std::vector<std::thread> pool;
      for (int tid = 1; tid < threads; ++tid) pool.emplace_back(work, tid);
      work(0);
      for (std::thread& th : pool) th.join();
    }
    for (size_t i = 0; i < count; ++i) {
      const FrameJob& job = jobs[first + i];
      FrameOutput& out = outputs[i];
      const double t =
          std::max(job.t + out.jitter_s, std::nextafter(last_t[job.sensor], 1e300));
      last_t[job.sensor] = t;
      if (absl::Status s = sink.AppendFrame(job.sensor, t, out.points); !s.ok()) return s;
      if (truth) {
        truth(FrameTruth{job.sensor, job.index, job.t, t, out.true_ranges, out.points});
      }
      summary.frames += 1;
      summary.rays += out.points.size();
      summary.hits += out.hits;
    }
    if (progress) {
      progress(SimulationProgress{jobs[first + count - 1].t, duration, summary.rays, elapsed()});
    }
  }
  summary.elapsed_s = elapsed();
  summary.rays_per_s = summary.elapsed_s > 0 ? summary.rays / summary.elapsed_s : 0;
  summary.true_path = std::move(true_path);
  return summary;
}

absl::StatusOr<SimulationSummary> Simulate(const SimulateOptions& o,
                                           const ProgressCallback& progress) {
  if (absl::Status s = o.Validate(); !s.ok()) return s;
  if (o.output_dir.empty()) return absl::InvalidArgumentError("simulate: no output directory");
  auto building = MakeBuilding(o);
  if (!building.ok()) return building.status();
  std::error_code ec;
  std::filesystem::create_directories(o.output_dir, ec);
  if (ec) {
    return absl::PermissionDeniedError(
        absl::StrCat("simulate: cannot create ", o.output_dir, ": ", ec.message()));
  }
  const std::string gt_dir = (std::filesystem::path(o.output_dir) / "gt").string();
  const std::string scan_path = (std::filesystem::path(o.output_dir) / "scan.h5").string();
  if (absl::Status s = WriteTruth(*building, gt_dir); !s.ok()) return s;
  auto writer = ScanWriter::Create(scan_path);
  if (!writer.ok()) return writer.status();
  ScanWriterSink sink(**writer);
  auto summary = SimulateBuilding(*building, o, sink, progress);
  if (!summary.ok()) return summary.status();
  if (absl::Status s = (*writer)->Close(); !s.ok()) return s;
  summary->scan_path = scan_path;
  summary->gt_dir = gt_dir;
  return summary;
}

}  // namespace carvemap
