// The Eigencrust floor plan's labelling (§3.2.1–§3.2.3; docs/DESIGN.md §6 stage 5, the second
// floor-plan method): which triangles of the wall samples' Delaunay triangulation are inside the
// building.
//
//  §3.2.1 SmoothWallSamples: each sample moves to the mean of the samples within
//    smoothing_distance_m along its normal, 3·d_s across it, whose normals are within π/8 of its
//    own, so a wall scanned twice with a registration error comes out once.
//  §3.2.2 LabelEigencrust: the 2D Delaunay triangulation (CGAL) of the samples and four corners
//    of a box around them and the poses. The poles of a sample are the two triangles of its
//    Voronoi cell's extreme vertices (Amenta: u the farthest circumcentre, v the farthest on the
//    other side of the sample). The pole graph joins u and v of each sample with the negative
//    weight of eq 3.1, −exp(4 + 4 cos φ + 2 sin θ1 + 2 sin θ2), and the poles of the two ends of
//    every Delaunay edge with the positive weight of eq 3.2, exp(4 − 4 cos φ), φ the angle at
//    which the two circumcircles intersect (0 when they only touch, π when they coincide).
//    Known labels: outside for triangles with a box corner; inside for triangles the middle
//    half of ≥ min_sight_lines scanner-to-sample segments crosses, triangles holding a pose,
//    and triangles crossed by the path between consecutive poses that both saw samples. The
//    known poles are contracted into an inside and an outside super-node, and the generalized
//    eigensystem L x = λ D x (L_ij = −w_ij, L_ii = Σ|w_ij|, D = diag L) is solved for the
//    eigenvector of the smallest eigenvalue that splits the graph (Spectra's shift-invert
//    solver, Eigen's sparse LDLᵀ for the inverse); its signs label the poles, the super-nodes'
//    signs telling which sign is inside. Then the non-pole graph: every other triangle, with the
//    labelled poles and the known triangles contracted into the two super-nodes, edges between
//    all touching triangles, eq 3.1 between the two super-nodes and eq 3.2 otherwise, solved the
//    same way (H y = μ D_H y).
//  §3.2.3 Clean-up: connected components (union-find) of one label with fewer than
//    min_union_triangles triangles flip, inside ones first; then protrusions (a triangle whose
//    only same-label neighbour lies across its shortest edge) flip, inside ones first.
//
// θ1, θ2 of eq 3.1 are the angles between the normals at s1, s2 and the segment s1s2 the two
// triangles share; sin θ = |n · d|, d the unit direction between the two circumcentres (which is
// perpendicular to s1s2). For the two poles of one sample, which share only the sample, the same
// formula is used with that sample's normal twice (d is then the direction from one pole's
// circumcentre to the other's: the Voronoi edge a wall sample's long cell stretches along). A
// zero normal (a grid-map sample on a one-cell wall) gives sin θ = 0.
//
// Where the dissertation is silent: pole-graph components that touch neither super-node are not
// solved (their sign would be arbitrary); their poles are labelled with the non-pole graph.
// Parallel edges made by contracting nodes add up. A triangle that is known both inside and outside
// (a pose in a corner triangle) is outside.
//
// Plain functions over plain data: no files, no logging. Thread-compatible.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/floorplan/wall_samples.h"

namespace carvemap {

struct EigencrustOptions {
  // §3.2.1. Off by default: "not necessary if the registration error is smaller than d_s", and
  // on the real floor maps it costs room F1 (docs/BENCHMARKS.md). smoothing_distance_m must be
  // below the closest spacing of parallel walls and at least the registration error.
  bool smooth = false;
  double smoothing_distance_m = 0.10;
  double smoothing_across_spacings = 3;   // × d_s (§3.2.1: "3 d_s")
  double smoothing_max_angle_deg = 22.5;  // π/8
  // §3.2.2: the box's corners lie this far outside the samples and poses, m.
  double box_margin_m = 1.0;
  // §3.2.2: a triangle crossed by the middle sight_middle_fraction of at least min_sight_lines
  // scanner-to-sample segments is inside ("the center 50%", "10 or more scan lines").
  int min_sight_lines = 10;
  double sight_middle_fraction = 0.5;
  // §3.2.3: components of one label with fewer triangles flip ("30 triangles"); 0 = off.
  int min_union_triangles = 30;
  bool remove_protrusions = true;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

struct EigencrustReport {
  size_t samples = 0;             // distinct sample positions
  size_t smoothed = 0;            // samples moved by §3.2.1 (more than 1 µm)
  size_t triangles = 0;           // finite Delaunay triangles (box corners included)
  size_t poles = 0;               // distinct pole triangles
  size_t negative_edges = 0;      // pole graph: eq 3.1 edges
  size_t positive_edges = 0;      // pole graph: eq 3.2 edges
  size_t sight_lines = 0;         // scanner-to-sample segments walked
  size_t known_inside = 0;        // triangles labelled inside a priori
  size_t known_outside = 0;       // triangles labelled outside a priori (box corners)
  size_t conflicts = 0;           // known both ways (kept outside)
  size_t pole_nodes_solved = 0;   // pole-graph nodes in a component with a super-node
  double pole_eigenvalue = 0;     // the eigenvalue used (pole graph's largest component)
  size_t nonpole_nodes = 0;       // non-pole graph nodes (super-nodes not counted)
  double nonpole_eigenvalue = 0;
  size_t inside_before_cleanup = 0;
  size_t flipped_unions = 0;      // triangles flipped by the small-union rule
  size_t flipped_protrusions = 0; // triangles flipped as protrusions
  size_t inside = 0;              // inside triangles at the end
  size_t boundary_edges = 0;      // |B|
  // Wall time of the parts, s: triangulation, a priori labels (sight lines, path), the pole
  // graph and its eigenvector, the non-pole graph and its eigenvector, the clean-up.
  double seconds_triangulation = 0, seconds_known = 0, seconds_poles = 0, seconds_nonpoles = 0,
         seconds_cleanup = 0;
};

// The labelled triangulation. Vertices 0..samples−1 are the samples' distinct positions in
// (x, y) order (as room_labeling.h numbers them), then the four box corners.
struct EigencrustLabeling {
  std::vector<Eigen::Vector2d> vertices;
  std::vector<Eigen::Vector2d> normals;         // per vertex; zero for the corners
  std::vector<std::array<int, 3>> triangles;    // counter-clockwise
  std::vector<std::array<int, 3>> neighbours;   // across the edge opposite vertex i; −1 = none
  std::vector<char> inside;                     // per triangle
  size_t samples = 0;                           // vertices that are samples
  // B (§3.2.3): the edges between an inside and an outside triangle, as vertex pairs with the
  // inside on the left of first → second.
  std::vector<std::array<int, 2>> boundary;

  // Whether point p lies in an inside triangle (false outside the box). `hint` is a triangle
  // to start the walk from (updated to the one found); −1 = triangle 0.
  [[nodiscard]] bool InsideAt(const Eigen::Vector2d& p, int* hint = nullptr) const;
  // The triangle holding p (closed), −1 outside the box.
  [[nodiscard]] int Locate(const Eigen::Vector2d& p, int hint = -1) const;
};

// §3.2.1 on a copy: positions move, nothing else changes. InvalidArgument for bad options or
// samples (WallSampleSet::Validate).
[[nodiscard]] absl::StatusOr<WallSampleSet> SmoothWallSamples(const WallSampleSet& samples,
                                                              const EigencrustOptions& options);

// §3.2.2–§3.2.3 on the samples as given (smoothing is the caller's: SmoothWallSamples).
// Errors: InvalidArgument for bad options or samples, or fewer than 3 distinct non-collinear
// samples; Internal when CGAL or the eigensolver fails (naming which).
[[nodiscard]] absl::StatusOr<EigencrustLabeling> LabelEigencrust(
    const WallSampleSet& samples, const EigencrustOptions& options,
    EigencrustReport* report = nullptr);

}  // namespace carvemap
