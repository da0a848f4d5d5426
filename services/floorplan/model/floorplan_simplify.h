// Simplification of floor-plan walls (§3.3.3, eqs 3.3–3.4): a 2D quadric-error variant that
// removes boundary vertices (on an interior/exterior edge) by collapsing the interior triangle on
// a boundary edge, so the room labelling of the area is kept.
//
// Error of removing boundary vertex u (neighbours p before and n after it along the boundary):
// the boundary p→u→n becomes the line l through p and n (a²+b²=1, eq 3.4), and
//   error_m = sqrt( Σ_x x̂ᵀ E_l x̂ ) = sqrt( lᵀ (Σ_x x̂ x̂ᵀ) l ),  x̂ = (x, y, 1),
// over every original sample x the new wall segment stands for (u and all samples removed into
// p→u and u→n before). So each boundary segment carries a 3×3 quadric (the moment matrix of its
// samples), and a collapse sums them (eq 3.3): the E_l of eq 3.4 is applied to the new line and
// the removed samples rather than to the old lines. Why not Q_v = Σ E_l over the old lines: with
// 5 cm samples and ±1 cm noise those lines have ±10° direction noise, so the distance of a far
// end point from them grows with the segment and walls stall at ~30 cm pieces; the new line
// through two far apart vertices is accurate. The error is a root of a sum of squares, so a wall
// with noise σ is cut into pieces of about (r/σ)² samples.
//
// A collapse is a half-edge collapse: u is merged into n (or, if that is not allowed, into p);
// no vertex moves, so positions stay measured samples. Not collapsed (§3.3.3 doorways): vertices
// in several rooms or joined by an edge to one. Rejected: a collapse that makes a triangle
// clockwise or of area < 1e-12 m², that fails the link condition (the two vertices share a
// neighbour other than the collapsed triangle's third vertex), that closes a 3-vertex boundary
// loop, that makes a boundary vertex's fan wrap past 360°, or that grows the plan (a reflex u)
// over another boundary vertex. A vertex where the boundary touches itself is never removed.
// Greedy with a heap, smallest error first, until no collapse has error < max_error_m.
//
// Removed vertices are deleted and the remaining ones renumbered (order kept); triangles are
// compacted (order kept), rooms' areas recomputed, a room whose seed triangle was collapsed gets
// its largest remaining triangle as seed. Plain function over plain data: no files, no logging.
#pragma once

#include <cstddef>

#include "absl/status/status.h"
#include "services/floorplan/floor_plan.h"

namespace carvemap {

struct FloorPlanSimplifyOptions {
  // r of §3.3.3, m: collapses with error_m < max_error_m are made. 0 = the caller forgot to pass
  // the samples' spacing (WallSampleSet::spacing_m): rejected, as is anything not finite or ≤ 0.
  double max_error_m = 0;
  [[nodiscard]] absl::Status Validate() const;
};

struct SimplifyReport {
  size_t boundary_vertices_before = 0;
  size_t boundary_vertices_after = 0;
  size_t collapses = 0;
  size_t rejected = 0;     // candidate collapses refused by a topology or orientation check
  double max_error_m = 0;  // largest error of a collapse made
};

// Errors: InvalidArgument for bad options or a malformed plan, FailedPrecondition for a
// non-manifold triangulation (ValidateFloorPlan in room_polygons.h). On error `plan` is unchanged.
[[nodiscard]] absl::Status SimplifyFloorPlan(FloorPlan& plan,
                                             const FloorPlanSimplifyOptions& options,
                                             SimplifyReport* report = nullptr);

}  // namespace carvemap
