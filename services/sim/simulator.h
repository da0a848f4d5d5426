// The scanning simulator (docs/DESIGN.md §4): a backpack walks through a building with known truth
// and records line scans with localization drift, clock jitter and range noise (§2.1, §2.2,
// §4.1.1), written as scan.h5 (docs/DESIGN.md §3) plus gt/ (building.json, surfaces.ply,
// objects.ply).
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/pose.h"
#include "services/building/building.h"
#include "services/sim/backpack_rig.h"
#include "services/sim/localization_drift.h"
#include "services/sim/scan_sink.h"
#include "services/sim/walk_planner.h"

namespace carvemap {

struct NoiseOptions {
  bool enabled = true;       // master switch: false = exact data (no drift, jitter, range noise)
  bool drift = true;         // localization drift on /path (§2.2)
  bool clock_jitter = true;  // recorded frame time = true time + N(0, sigma_t) (§4.1.1)
  bool range_noise = true;   // range += N(0, a + b·range) (§2.1)
  DriftOptions drift_options;
  double sigma_t_s = 1e-3;
  double range_a_m = 0.01;
  double range_b = 0.001;
  bool magnetometer = true;  // /magnetometer at magnetometer_rate_hz (§2.3)
  double magnetometer_rate_hz = 10.0;
  double magnetometer_sigma_ut = 1.5;  // per-axis noise, µT
  [[nodiscard]] absl::Status Validate() const;
};

struct SimulateOptions {
  // The building: a preset ("room", "office", "office2") unless floormap_png is set.
  std::string preset = "office";
  std::string floormap_png;   // 2D floor map (docs/DESIGN.md §4 pixel convention)
  std::string furniture_png;  // optional furniture map of the same size
  std::string rooms_png;      // optional ground-truth room segmentation of the same size
  double resolution_m = 0.05; // floor map metres per pixel
  uint64_t seed = 1;          // building, walk and noise; same seed ⇒ same bytes
  std::string output_dir;     // receives scan.h5 and gt/
  RigOptions rig;
  WalkOptions walk;
  NoiseOptions noise;
  int threads = 1;            // ray-casting threads; output is identical for any count
  double max_duration_s = 0;  // > 0: stop the walk after this long (tests, benchmarks)
  // The recorded path's frame turned by this about the vertical through the building's origin,
  // degrees counter-clockwise: a localizer whose frame follows its first heading (§2.3) rather
  // than north. gt/ stays in the building's frame (ENU, +y north, as the magnetometer's field).
  double frame_yaw_deg = 0;
  [[nodiscard]] absl::Status Validate() const;
};

struct SimulationProgress {
  double sim_time_s = 0;  // walk time simulated so far
  double duration_s = 0;  // of the whole walk
  uint64_t rays = 0;
  double elapsed_s = 0;   // wall time
};
using ProgressCallback = std::function<void(const SimulationProgress&)>;

struct SimulationSummary {
  std::string building;
  std::string scan_path, gt_dir;   // empty when simulated into a sink
  double duration_s = 0;           // of the walk
  double path_length_m = 0;        // horizontal length of the true path
  uint64_t frames = 0, rays = 0, hits = 0;
  double elapsed_s = 0;            // wall time of the scanning loop
  double rays_per_s = 0;           // rays / elapsed_s
  int rooms_entered = 0;
  std::vector<int> rooms_visited;  // room indices in visit order
  std::vector<TimedPose> true_path;  // the TRUE system path (the file holds the drifted one)
};

// Per-frame truth for tests: the true time and ranges (+inf = no return) of the rays whose
// noisy end points were just recorded. Spans are valid only during the call.
struct FrameTruth {
  int sensor = 0;
  uint64_t index = 0;     // frame index of that sensor
  double true_t = 0, recorded_t = 0;
  std::span<const float> true_ranges_m;
  std::span<const Eigen::Vector3f> points_sensor;
};
using FrameTruthCallback = std::function<void(const FrameTruth&)>;

// Builds the building, writes OUT/gt/ and OUT/scan.h5 (through a .partial file).
absl::StatusOr<SimulationSummary> Simulate(const SimulateOptions& options,
                                           const ProgressCallback& progress = {});

// The scanning part alone over a given building, into any sink (no files). Frames go to the
// sink in time order across sensors; memory stays bounded by a batch of frames.
absl::StatusOr<SimulationSummary> SimulateBuilding(const Building& building,
                                                   const SimulateOptions& options,
                                                   ScanSink& sink,
                                                   const ProgressCallback& progress = {},
                                                   const FrameTruthCallback& truth = {});

// The magnetometer's world field: north (+y) and down, µT (a mid-latitude field).
inline const Eigen::Vector3d kWorldMagneticField_uT(0.0, 20.0, -45.0);

}  // namespace carvemap
