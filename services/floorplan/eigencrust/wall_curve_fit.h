// Lines and circles fitted to a floor plan's walls with RANSAC (§3.2.4; the last step of
// the Eigencrust floor plan, eigencrust_floorplan.h). Input: the boundary edges B between inside
// and outside (§3.2.3) and their vertices (wall samples, with normals).
//
//  1. Each iteration takes three unassigned samples, the circle through them and their line of
//     best fit, and finds each model's inliers: unassigned samples within inlier_distance_m of it
//     whose normal is within max_normal_angle_deg of the model's normal there (a zero normal
//     passes). Of the models with at least min_inliers, the one with the smallest mean distance
//     is kept (§3.2.4: "the line or circle model found with the smallest average error"), refit
//     to its inliers (total least squares line, algebraic circle) and its inliers taken again;
//     they are assigned. Repeated until `iterations` tries find no model.
//  2. The inliers of each model are split into connected components along B (union-find); a
//     component spanning less than min_component_m (1 m) is unassigned again.
//  3. Unassigned samples join the closest model of a neighbour along B (repeatedly, so models
//     grow along the walls towards each other) when within max_snap_m of it.
//  4. Every assigned sample moves onto its model. Where B passes from one line model to another
//     (more than 20° apart) and their intersection is within corner_snap_m of the pair's nearer
//     sample, that sample moves to the intersection: a sharp corner (§3.2.4: "encouraging sharp
//     corners").
//
// Where the dissertation is silent or too costly literally: the second and third samples of a try
// are drawn within neighbourhood_m of the first (three samples drawn from a whole building almost
// never lie on one wall; inliers are still searched everywhere, so the back walls of a row of
// offices can share one line, §3.2.4's example); the inlier test orients a model's normal by
// its three samples' normals, so the two faces of a thin wall are not one model; circles with a
// radius outside [min_radius_m, max_radius_m] are not tried.
//
// Deterministic for a seed. Plain function over plain data: no files, no logging.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace carvemap {

struct WallCurveFitOptions {
  double inlier_distance_m = 0;       // 0 = the samples' spacing d_s
  double max_normal_angle_deg = 30;
  int min_inliers = 10;
  int iterations = 100;               // tries per model search
  double neighbourhood_m = 1.0;
  double min_component_m = 1.0;       // §3.2.4: "less than a meter"
  double max_snap_m = 0;              // 0 = 2 d_s
  double corner_snap_m = 0;           // 0 = 3 d_s
  double min_radius_m = 0.2;
  double max_radius_m = 15.0;
  uint64_t seed = 1;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

struct WallCurve {
  enum class Kind { kLine, kCircle };
  Kind kind = Kind::kLine;
  Eigen::Vector2d point = Eigen::Vector2d::Zero();      // line: a point on it; circle: centre
  Eigen::Vector2d direction = Eigen::Vector2d::UnitX();  // line: unit direction
  double radius = 0;                                     // circle
  size_t samples = 0;                                    // assigned at the end
};

struct WallCurveFit {
  std::vector<WallCurve> curves;
  std::vector<int> curve_of;               // per vertex: index into curves, −1 = none
  std::vector<Eigen::Vector2d> fitted;     // per vertex: its new position (unchanged if none)
};

struct WallCurveFitReport {
  size_t boundary_samples = 0;   // distinct vertices of B
  size_t models_found = 0;       // step 1
  size_t dropped_short = 0;      // samples unassigned by step 2
  size_t snapped = 0;            // samples assigned by step 3
  size_t lines = 0, circles = 0; // at the end
  size_t assigned = 0;           // samples on a model at the end
  size_t corners = 0;            // samples moved to a corner
  double mean_move_m = 0;        // over the moved samples
};

// `vertices` and `normals` (unit or zero) are indexed by B's vertex ids; others are ignored.
// Errors: InvalidArgument for bad options, spacing, sizes or an edge out of range.
[[nodiscard]] absl::StatusOr<WallCurveFit> FitWallCurves(
    const std::vector<Eigen::Vector2d>& vertices, const std::vector<Eigen::Vector2d>& normals,
    const std::vector<std::array<int, 2>>& boundary, double spacing_m,
    const WallCurveFitOptions& options, WallCurveFitReport* report = nullptr);

}  // namespace carvemap
