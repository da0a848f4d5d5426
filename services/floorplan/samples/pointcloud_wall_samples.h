// Wall samples from a 3D point cloud (§3.1.1; docs/DESIGN.md §6 stage 4): the points of each level
// are binned on a d_s grid in the horizontal plane; the neighbourhood N_g of cell g is every
// point within horizontal distance d_s of its centre (a point is in several neighbourhoods).
// N_g is a wall when
//   - it is dense: |N_g| ≥ min_points (50);
//   - it is tall: its vertical support (max z − min z) ≥ min_wall_height_m (H = 2 m), which
//     leaves furniture and cubicle walls out;
//   - it is uniform in height: of a height_bins (16) histogram over the level's floor_z to
//     ceiling_z, at least min_filled_bins (12) are non-empty, and min_filled_top_bins (3) of the
//     top_bins (4) highest, so it reaches the ceiling;
//   - it is flat: with λ1 ≤ λ2 the eigenvalues of the 2×2 covariance of its xy positions, the
//     confidence c = 1 − 2λ1/(λ1 + λ2) ≥ min_normal_confidence (0.15).
// Its sample is the median horizontal position of N_g when that lies inside g, with normal e1
// (PCA, λ1's eigenvector) flipped towards the scanners that saw N_g, floor_z / ceiling_z the
// minimum / maximum height of N_g (§3.1.1: "the minimum and maximum height values of the points
// that sample represents"), and as poses the scanner positions whose rays ended in N_g (each
// point's frame time gives its pose: §3.1.1 "the poses of the scanners that observed the sample
// location"; a ray that ends there had a line of sight to it).
//
// Streaming, never the whole cloud in memory: the cloud is read three times through a
// CloudStreamFn (the dissertation's "cannot be done in a streaming fashion" is about one pass).
// PointCloudHeightHistogram is the first pass (levels, §2.5). Pass 2 keeps per cell only counts,
// extremes, a 16-bit mask of the height bins and the sums of the PCA; pass 3 revisits only the
// cells that passed: per-axis histograms of x and y (median_bins bins over the neighbourhood's
// 2 d_s: the median to d_s / 32 = 1.6 mm at 5 cm, not exact) and the poses.
//
// Plain functions over plain data: no files, no logging. The caller wraps the scan reader
// (scan_cloud_stream.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/pose.h"
#include "services/floorplan/wall_samples.h"
#include "services/levels/level_split.h"

namespace carvemap {

// One measured point in the world frame, with where it was measured from.
struct CloudPoint {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // m
  Eigen::Vector3d sensor = Eigen::Vector3d::Zero();  // the sensor's position at the frame, m
  double t = 0;                                      // the frame's time, s
};

// Receives the cloud in batches; an error stops the stream and is returned by it.
using CloudBatchSink = std::function<absl::Status(std::span<const CloudPoint>)>;
// Streams the whole cloud once into `sink`, in any order; may be called several times and must
// give the same points each time. Returns the sink's error or its own (e.g. a read failure).
using CloudStreamFn = std::function<absl::Status(const CloudBatchSink& sink)>;

struct PointCloudWallSampleOptions {
  double spacing_m = 0.05;            // d_s (§3.1.1: "a typical value ... 5 cm")
  uint32_t min_points = 50;           // |N_g| ≥ this (§3.1.1)
  double min_wall_height_m = 2.0;     // H (§3.1.1)
  int height_bins = 16;               // §3.1.1; at most 16 (a 16-bit mask per cell)
  int min_filled_bins = 12;           // of height_bins
  int top_bins = 4;                   // the highest bins ...
  int min_filled_top_bins = 3;        // ... of which this many must be non-empty
  double min_normal_confidence = 0.15;  // c (§3.1.1)
  int median_bins = 64;               // per axis, over the neighbourhood's 2 d_s (pass 3)
  // Poses: the path on each level, a kept position every min_pose_spacing_m of walk (as the
  // other wall-sample sources do, grid_visibility.h), broken where the walk left the level.
  double min_pose_spacing_m = 0.25;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

struct PointCloudWallSampleReport {
  uint64_t points = 0;            // points of this level (z in [split_z_low, split_z_high))
  size_t cells = 0;               // cells with a non-empty neighbourhood
  size_t dense = 0;               // of those, |N_g| ≥ min_points
  size_t tall = 0;                // ... and vertical support ≥ H
  size_t uniform = 0;             // ... and the histogram rule
  size_t flat = 0;                // ... and confidence ≥ min_normal_confidence
  size_t samples = 0;             // ... and the median inside the cell
  size_t samples_with_poses = 0;  // of the samples, seen from at least one kept pose
  size_t poses = 0;               // kept poses of this level
};

// §2.5's point-height histograms for SplitLevelsFromHistogram, in one pass: a point whose ray
// goes down to it (sensor above the point) counts as floor, one seen from below as ceiling.
// Only rays at least min_elevation_deg from horizontal count (§2.5: "scanned from above, in a
// downward direction"): a level scanner's rays hit every wall at the scanner's height, just
// below it, which on the simulated room made a "floor" peak at 1.9 m twice the real floor's.
// Errors: the stream's; InvalidArgument for bin_m ≤ 0, min_elevation_deg outside [0, 90), a
// non-finite point, or heights spanning more than 10^6 bins.
[[nodiscard]] absl::StatusOr<HeightHistogram> PointCloudHeightHistogram(
    const CloudStreamFn& stream, double bin_m = 0.02, double min_elevation_deg = 20);

// One WallSampleSet per level (same order), §3.1.1 as in the file comment, in two passes over
// the stream. `path` is the recorded system path (time order): each level's poses are its
// positions with z in the level's split range, subsampled; a point's pose is the kept pose
// nearest in time to its frame, if that pose is within 2·min_pose_spacing_m (horizontally) of
// the path at that time, else none. Samples come in cell order (by y, then x). Deterministic.
// Errors: the stream's; InvalidArgument for bad options, levels (non-finite, floor_z ≥
// ceiling_z, split_z_low ≥ split_z_high) or path (non-finite, time not ascending), or a
// non-finite point.
[[nodiscard]] absl::StatusOr<std::vector<WallSampleSet>> PointCloudWallSamples(
    const CloudStreamFn& stream, std::span<const Level> levels, std::span<const TimedPose> path,
    const PointCloudWallSampleOptions& options,
    std::vector<PointCloudWallSampleReport>* reports = nullptr);

}  // namespace carvemap
