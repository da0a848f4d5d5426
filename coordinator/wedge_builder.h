// Turns the frames of a scan into wedges (§4.2.1, §4.3.1; docs/DESIGN.md §3, §5): every ray gets
// its noise model (§4.1.1, eqs 4.1–4.6) once, and neighbouring rays are joined into wedges:
//   line   — rays j, j+1 of frames i and i+1 of one sensor:
//            rays = {(i, j), (i, j+1), (i+1, j), (i+1, j+1)}
//   grid   — pixels of one frame: rays = {(r, c), (r, c+1), (r+1, c), (r+1, c+1)}
//   points — one single-ray wedge per ray (num_rays = 1).
// A wedge needs all its rays to have returns (a NaN row carves nothing) and to meet one surface:
// no depth discontinuity between them, no occlusion edge, and (line) no wide gap between frames
// (WedgeBuilderOptions). Every return that ends up in no wedge is still carved, as a
// single-ray wedge (num_rays = 1, the ray copied into all four slots so the bytes are defined).
// A grid frame's wedges come in row order: the wedges joining rows y and y + 1, then row y's
// single-ray wedges, so the lowest row a wedge touches never decreases within a frame.
//
// Streaming: memory holds only the previous frame of each line sensor, whatever the scan size.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/carving_types.h"
#include "geometry/noise_model.h"
#include "geometry/pose.h"
#include "storage/scan_reader.h"
#include "storage/scan_types.h"

namespace carvemap {

struct WedgeBuilderOptions {
  NoiseModelOptions noise;
  // Depth discontinuity: rays are not joined when max − min of their ranges exceeds
  // max(min_jump_m, (max_range_ratio − 1)·min). A wedge across a near object's edge would carve
  // the space between the edge and the surface behind it. The ratio term follows the ray
  // spacing: on a plane seen at incidence θ, neighbouring rays Δφ apart differ by ≈ r·Δφ·tanθ,
  // which for a 0.25° scanner stays below 25 % up to θ ≈ 89°, so floors seen at grazing angles
  // stay joined while a chair edge 2 m in front of a wall 3 m away (ratio 1.5) is split. The
  // absolute term keeps range noise (1–3 cm std-dev) from splitting smooth surfaces at short
  // range, where 25 % is only a few centimetres; 10 cm is below the 3σ extension of wedges.
  double max_range_ratio = 1.25;
  double min_jump_m = 0.10;
  // Neighbouring rays meet one surface only when one's point lies at most this many times
  // the rays' spacing (across the ray) from the other's: a surface met at θ from head-on puts
  // them 1/cos θ apart, 4 is θ = 75.5°. Both wedges and the sampling term below need it. An
  // occlusion edge can pass the range rule: on the simulated office a wedge from a desk's
  // front edge to the chair seat 27 cm below it (25 cm farther, ~8 spacings) carved a solid
  // sheet that joined desk and chair; with this rule 98.5 % of the observed leaves are
  // labelled right, against 97.9 % without (docs/BENCHMARKS.md).
  double max_obliquity = 4.0;
  // Returns closer than this to the sensor have no usable direction: treated as no return.
  double min_range_m = 0.01;
  // Line sensors: frames further apart than this are not joined (a pause in the recording or
  // many dropped frames; 0.5 s is 20 frames of a 40 Hz scanner).
  double max_frame_gap_s = 0.5;
  // Line sensors: frames whose rays lie more than this apart across the rays, at the points,
  // join only where the surface faces the scanner (their ranges differ by at most half their
  // spacing). §4.2.1 interpolates between frames as if one surface lay between them; while
  // the walker turns, consecutive frames lie far apart (0.9 m at 7.5 m on the simulated office
  // at 10 Hz), and a near chair back and the wall 1.3 m behind it, under the desk, look like
  // one surface met at 40° to the rules above: the wedge carved the space behind the chair
  // solid. Measured there (docs/BENCHMARKS.md): objects found 67 % without this limit, 74 %
  // with it. Wedges only: the sampling term below still spreads a ray towards such a
  // neighbour (dropping it there too cost 9 % of the observed volume and the wall samples'
  // poses).
  double max_frame_gap_m = 0.5;
  // The sampling term of each ray's point covariance (SamplingCovariance, §4.2.1): the variance
  // of the point towards each neighbour's point, as a fraction of their squared distance, in
  // frame and frame to frame (grid: along rows and along columns). 1/12, a uniform spread over
  // the gap; 0 leaves rays as wide as the localization covariance alone.
  double sampling_share = 1.0 / 12;

  [[nodiscard]] absl::Status Validate() const;
};

struct WedgeBuilderStats {
  uint64_t frames = 0;
  uint64_t rays = 0;
  uint64_t rays_without_return = 0;   // NaN rows and returns closer than min_range_m
  uint64_t wedges = 0;                // four-ray wedges emitted
  uint64_t single_ray_wedges = 0;     // one-ray wedges emitted
  uint64_t discontinuities = 0;       // four valid rays not joined (range, obliquity, gap)
  bool default_covariance = false;    // BuildWedges: the scan had no /path_cov
};

// Everything about the system at a frame's time that the noise model needs.
struct FrameContext {
  Pose pose_world_sys;
  PoseCovariance covariance;
  Eigen::Vector3d omega_world = Eigen::Vector3d::Zero();  // rad/s, world frame
};

// The context at time t: pose interpolated along `path` (§2.4), /path_cov rows interpolated
// linearly (option defaults when `path_cov` is empty), angular velocity from the neighbouring
// poses. REQUIRES: path non-empty and sorted.
[[nodiscard]] absl::StatusOr<FrameContext> FrameContextAt(
    std::span<const TimedPose> path, std::span<const PathCovariance> path_cov, double t,
    const NoiseModelOptions& options);

// Receives each wedge and the ids of its rays (ids[r] names wedge.rays[r]; RayId: equal ids,
// the same ray; one frame, one sensor Gaussian), so a consumer can store each ray once. A
// non-OK status stops the builder and is returned by the caller's AddFrame/Finish. Both
// references are valid only during the call.
using WedgeSink = std::function<absl::Status(const Wedge&, std::span<const RayId> ids)>;

// Not thread-safe; one builder per scan.
class WedgeBuilder {
 public:
  // `sensors` are indexed by ScanFrame::sensor. Errors: InvalidArgument for bad options or a
  // grid sensor without rows/cols.
  static absl::StatusOr<WedgeBuilder> Create(std::vector<SensorInfo> sensors,
                                             const WedgeBuilderOptions& options, WedgeSink sink);

  // Feeds one frame (frames of one sensor in ascending time and row; sensors may interleave).
  // Emits the wedges it completes; its rays' RayId::frame is frame.row. Errors:
  // InvalidArgument for an unknown sensor, time going backwards, a row not after the sensor's
  // previous one or a grid frame of the wrong size; or the sink's error.
  absl::Status AddFrame(const ScanFrame& frame, const FrameContext& context);
  // Emits what is still pending (single-ray wedges of each line sensor's last frame). Call once
  // at the end; AddFrame after Finish starts fresh sequences.
  absl::Status Finish();

  [[nodiscard]] const WedgeBuilderStats& stats() const { return stats_; }

 private:
  struct SensorState {
    SensorInfo info;
    SensorNoiseParams noise;
    uint32_t index = 0;       // the sensor's index (RayId::sensor)
    bool seen_any = false;
    uint64_t last_row = 0;    // the last frame's row (RayId::frame is the row)
    bool has_prev = false;
    double prev_t = 0;
    uint64_t prev_row = 0;
    // The previous frame (line sensors): its rays, ranges (NaN = no return) and whether a
    // wedge used each ray.
    std::vector<RayModel> prev_rays;
    std::vector<float> prev_range;
    std::vector<uint8_t> prev_covered;
  };

  WedgeBuilder(std::vector<SensorState> sensors, const WedgeBuilderOptions& options,
               WedgeSink sink);

  // Fills cur_rays_/cur_range_/cur_covered_ for `frame`.
  void ComputeRays(const SensorState& s, const ScanFrame& frame, const FrameContext& context);
  // Adds the sampling covariance to cur_rays_' point covariances: neighbours along the frame
  // (line: j ± 1) or along rows and columns (grid); for a line sensor, also the previous
  // frame's ray of the same index when `prev` is given.
  void AddSamplingCovariance(const SensorState& s, const SensorState* prev);
  [[nodiscard]] bool Continuous(float a, float b, float c, float d) const;
  // Rays a, b (one row) and c, d (the next) meet one surface (max_obliquity; for a `line`
  // sensor, whose rows are frames, max_frame_gap_m).
  [[nodiscard]] bool OneSurface(const RayModel& a, const RayModel& b, const RayModel& c,
                                const RayModel& d, bool line) const;
  absl::Status EmitWedge(const RayModel& a, const RayModel& b, const RayModel& c,
                         const RayModel& d, const std::array<RayId, 4>& ids);
  // The single-ray wedges of rays [begin, end) not in any wedge.
  absl::Status EmitSingles(const SensorState& s, uint64_t frame, std::span<const RayModel> rays,
                           std::span<const float> range, std::span<const uint8_t> covered,
                           size_t begin = 0, size_t end = SIZE_MAX);
  absl::Status AddLineFrame(SensorState& s, const ScanFrame& frame);
  absl::Status AddGridFrame(SensorState& s, const ScanFrame& frame);

  std::vector<SensorState> sensors_;
  WedgeBuilderOptions options_;
  WedgeSink sink_;
  WedgeBuilderStats stats_;
  // Scratch for the current frame, reused to avoid allocations per frame.
  std::vector<RayModel> cur_rays_;
  std::vector<float> cur_range_;
  std::vector<uint8_t> cur_covered_;
  Wedge wedge_;
};

// Streams every frame of `reader` (in time order) through a WedgeBuilder, computing each
// frame's context from the reader's path and /path_cov (stats.default_covariance says when the
// option defaults were used instead). `after_frame`, if set, sees the running stats after every
// frame (for progress). REQUIRES: HDF5 calls serialized (see scan_reader.h).
absl::StatusOr<WedgeBuilderStats> BuildWedges(
    ScanReader& reader, const WedgeBuilderOptions& options, WedgeSink sink,
    const std::function<void(const WedgeBuilderStats&)>& after_frame = {});

}  // namespace carvemap
