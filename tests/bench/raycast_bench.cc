// Ray caster and simulator throughput on a preset building (default "office"):
//   raycast_bench [preset] [seconds of walk]
// 1. single-thread rays/s of RayCaster::Cast in each CastMode, on the rays the backpack's three
//    full-rate scanners cast along the first seconds of the walk;
// 2. SimulateBuilding throughput (full rate, noise on, into a sink that drops the data) with
//    1 and 2 threads.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "services/building/building_presets.h"
#include "services/sim/backpack_rig.h"
#include "services/sim/raycaster.h"
#include "services/sim/simulator.h"
#include "services/sim/walk_planner.h"

namespace carvemap {
namespace {

class NullSink : public ScanSink {
 public:
  absl::Status AppendPath(std::span<const PathRecord>, std::span<const PathCovariance>) override {
    return absl::OkStatus();
  }
  absl::StatusOr<int> AddSensor(const SensorInfo&) override { return sensors_++; }
  absl::Status AppendFrame(int, double, std::span<const Eigen::Vector3f>) override {
    return absl::OkStatus();
  }
  absl::Status AppendMagnetometer(std::span<const MagnetometerRecord>) override {
    return absl::OkStatus();
  }

 private:
  int sensors_ = 0;
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

int Main(int argc, char** argv) {
  const std::string preset = argc > 1 ? argv[1] : "office";
  const double walk_s = argc > 2 ? std::atof(argv[2]) : 30.0;
  auto building = MakePresetBuilding(preset, 1);
  if (!building.ok()) {
    std::fprintf(stderr, "%s\n", std::string(building.status().message()).c_str());
    return 1;
  }
  auto t0 = std::chrono::steady_clock::now();
  auto caster = RayCaster::Create(StructureMesh(*building), ObjectsMesh(*building));
  if (!caster.ok()) return 1;
  std::printf("building %s: %zu triangles, BVH build %.3f s\n", preset.c_str(),
              (*caster)->triangle_count(), Seconds(t0));
  auto walk = PlanWalk(*building, WalkOptions{});
  if (!walk.ok()) {
    std::fprintf(stderr, "%s\n", std::string(walk.status().message()).c_str());
    return 1;
  }
  std::printf("walk: %.1f s, %.1f m\n", walk->path.back().t, walk->length_m);

  // The rays of the first `walk_s` seconds, as the simulator casts them.
  const std::vector<LineScanner> rig = MakeBackpackRig(RigOptions{});
  std::vector<RayQuery> rays;
  for (const LineScanner& sc : rig) {
    for (double t = sc.phase_s; t < std::min(walk_s, walk->path.back().t); t += 1 / sc.rate_hz) {
      const Pose T = PoseAtTime(walk->path, t) * sc.T_system_sensor;
      const Eigen::Matrix3f R = T.rotation.toRotationMatrix().cast<float>();
      for (const Eigen::Vector3f& d : sc.beams_sensor) {
        rays.push_back(RayQuery{T.translation.cast<float>(), R * d, 30.0f});
      }
    }
  }
  std::vector<RayHitResult> hits(rays.size());
  const char* names[] = {"rtcIntersect1 loop (coherent)", "rtcIntersect1M stream",
                         "rtcIntersect16 packets"};
  for (CastMode mode : {CastMode::kSingle, CastMode::kStream, CastMode::kPacket}) {
    double best = 1e300;
    for (int rep = 0; rep < 3; ++rep) {
      // Frame-sized batches, as the simulator calls it.
      t0 = std::chrono::steady_clock::now();
      for (size_t first = 0; first < rays.size(); first += 1081) {
        const size_t n = std::min<size_t>(1081, rays.size() - first);
        (*caster)->Cast(std::span(rays).subspan(first, n), std::span(hits).subspan(first, n),
                        mode);
      }
      best = std::min(best, Seconds(t0));
    }
    size_t hit = 0;
    for (const RayHitResult& h : hits) hit += h.hit();
    std::printf("cast %-30s %zu rays (%.1f%% hit): %.2f M rays/s single thread\n",
                names[static_cast<int>(mode)], rays.size(), 100.0 * hit / rays.size(),
                rays.size() / best * 1e-6);
  }

  for (int threads : {1, 2}) {
    SimulateOptions o;
    o.preset = preset;
    o.threads = threads;
    o.max_duration_s = walk_s;
    NullSink sink;
    t0 = std::chrono::steady_clock::now();
    auto summary = SimulateBuilding(*building, o, sink);
    if (!summary.ok()) return 1;
    std::printf("simulate %d thread(s): %.1f s of walk, %llu rays in %.2f s scanning "
                "(%.2f M rays/s), %.2f s total, %.1fx real time\n",
                threads, summary->duration_s, static_cast<unsigned long long>(summary->rays),
                summary->elapsed_s, summary->rays_per_s * 1e-6, Seconds(t0),
                summary->duration_s / Seconds(t0));
  }
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
