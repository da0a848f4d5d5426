// Plain data shared by the coordinator (which builds wedges and bins them into chunks) and the
// workers (which carve them into chunk octrees): §4.1–§4.3, docs/DESIGN.md §5.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace carvemap {

// A symmetric 3×3 covariance stored as xx xy xz yy yz zz (m²), as /path_cov stores it.
using SymCov3f = std::array<float, 6>;

[[nodiscard]] inline Eigen::Matrix3d ToMatrix(const SymCov3f& c) {
  Eigen::Matrix3d m;
  m << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
  return m;
}
[[nodiscard]] inline SymCov3f ToSymCov(const Eigen::Matrix3d& m) {
  return {float(m(0, 0)), float(m(0, 1)), float(m(0, 2)),
          float(m(1, 1)), float(m(1, 2)), float(m(2, 2))};
}

// One scan ray in the world frame as two Gaussians (§4.1.1): the sensor position
// N(sensor_mean, sensor_cov) = eq 4.5 and the scan point N(point_mean, point_cov) = eq 4.6.
// Floats: world coordinates within ±10 km keep sub-millimetre precision, and a survey holds
// hundreds of millions of rays.
struct RayModel {
  Eigen::Vector3f sensor_mean;  // m, world
  Eigen::Vector3f point_mean;   // m, world
  SymCov3f sensor_cov;          // m²
  SymCov3f point_cov;           // m²
};

// A wedge (§4.2.1, §4.3.1): the volume between up to four neighbouring rays — rays j, j+1 of
// frames i, i+1 of a line sensor, or four neighbouring pixels of a grid sensor — or a single
// ray of a points sensor. Its volume is the convex hull of the sensor means and the point means
// extended 3σ along each ray (for a single ray: that segment widened by 1σ across the ray).
struct Wedge {
  std::array<RayModel, 4> rays;
  uint8_t num_rays = 4;  // 4, or 1 for `points` sensors
};

// Where a ray comes from, as the wedge builder numbers them: rays with equal ids are the same
// ray (bit-identical RayModels), and rays of one frame (sensor, frame) share their sensor
// Gaussian. frame is the frame's row in its sensor's /frames (ascending with time, so a time
// slice of a scan names its rays as the whole scan does); index is the ray's place in it.
struct RayId {
  uint32_t sensor = 0;
  uint64_t frame = 0;
  uint32_t index = 0;
  bool operator==(const RayId&) const = default;
};

// Wedges that share rays, each distinct ray stored once: how a slice holds its wedges
// (worker/slice_carver.h). Wedge w joins rays[wedges[w].ray[0 … num_rays)]; neighbouring
// wedges of a line or grid sensor share edges, so each ray belongs to up to four of them.
struct WedgeRef {
  std::array<uint32_t, 4> ray{};
  uint8_t num_rays = 4;  // 4, or 1 for a single-ray wedge
  uint64_t facets = 0;   // hull hint (HullOfWedgePoints); 0: none
};
struct IndexedWedges {
  std::vector<RayModel> rays;
  std::vector<WedgeRef> wedges;
  // Which rays vote (eq 4.8): empty, all of them; else one flag per ray. A ray that does not
  // vote here still shapes its wedges' hulls (so that the rays that do vote have all of their
  // wedges), and votes where it belongs: a time slice carries the wedges that join its first
  // and last frames to its neighbours' (coordinator/scan_slices.h).
  std::vector<uint8_t> votes;
  // Optional, one per ray: the far end of its wedges' hulls (ExtendedPointMean with
  // worker/chunk_octree.h's kWedgeHullSigmas), for a caller that has computed them already;
  // empty, the carve computes them.
  std::vector<Eigen::Vector3d> far_ends;
};

// How eq 4.7 is evaluated for each vote (the votes themselves, eq 4.8's S(L), are the same):
//   kExact — double precision (carve_map.h): the reference, what the tests of the model run.
//   kFast  — single precision, four leaves at a time (carve_map_float.h), summed in double
//            into a dense array of the chunk's leaves (worker/chunk_octree.h): the default.
//            The tolerance it is held to against kExact (worker/slice_carver_test,
//            tests/bench/carve_bench): ≥ 99.9 % of finest leaves with the same label and
//            |Δp| ≤ 0.01 on ≥ 99 % of stored leaves. What it gives: the same votes, every
//            label the same and |Δp| < 1e−6 on the simulated office2 (docs/BENCHMARKS.md),
//            ≥ 99.999 % of labels on slice_carver_test's office.
// Both are deterministic: the same input gives the same bytes on any x86-64 worker.
enum class CarveEvaluation { kExact, kFast };

// The fused statistics of one octree leaf (eq 4.8), kept as sums so that fusion is a plain
// accumulation and sibling leaves merge exactly when simplified (§4.3.2). Unobserved space
// (count 0) reads as p = 0.5.
struct LeafStats {
  double sum_w = 0;     // Σ w_i(x_L)
  double sum_wp = 0;    // Σ w_i p_i(x_L)
  double sum_wp2 = 0;   // Σ w_i p_i(x_L)²
  uint32_t count = 0;   // number of rays that contributed
  // §4.2.3's second voxel set ("voxels intersected by the input point cloud"): the scan points
  // that fell in the leaf. Not part of eq 4.8; segmentation reads it to keep fine detail
  // (legs, rods, boards) that the wedges carve away (segment_chunk.h).
  uint32_t points = 0;

  void Add(double p, double w) {
    sum_w += w;
    sum_wp += w * p;
    sum_wp2 += w * p * p;
    ++count;
  }
  void Merge(const LeafStats& o) {
    sum_w += o.sum_w;
    sum_wp += o.sum_wp;
    sum_wp2 += o.sum_wp2;
    count += o.count;
    points += o.points;
  }
  [[nodiscard]] bool observed() const { return count > 0 && sum_w > 0; }
  // eq 4.8: the weighted mean of the rays' carve-map values.
  [[nodiscard]] double p() const { return observed() ? sum_wp / sum_w : 0.5; }
  // Weighted variance of those values (0 when unobserved).
  [[nodiscard]] double variance() const {
    if (!observed()) return 0.0;
    const double m = p();
    const double v = sum_wp2 / sum_w - m * m;
    return v > 0 ? v : 0.0;
  }
  // §4.3.2: interior iff p > 0.5 strictly; unobserved space is exterior.
  [[nodiscard]] bool interior() const { return p() > 0.5; }
};

}  // namespace carvemap
