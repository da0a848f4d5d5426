// Floor plan with rooms from wall samples (seed §3.3.1–§3.3.2; DESIGN §6 stage 5):
//  1. 2D Delaunay triangulation of the wall samples (CGAL, inside the .cc).
//  2. Interior = triangles crossed by a scanner-to-sample segment (s, p), p seen from s, or by a
//     scanner-to-scanner segment between consecutive poses; crossings exclusive of triangle
//     edges. Occlusion check: a segment (s, p) that passes through the ball of diameter
//     occlusion_diameter_m around another sample p' is truncated at p' (§3.3.1), so a wall
//     scanned from both sides is never carved away.
//  3. Room seeds: interior triangles whose circumcircle is the largest of all interior
//     circumcircles it intersects (§3.3.2).
//  4. Partition: greedy flood fill from the seeds, longest shared edge first (§3.3.2).
//  5. Refinement to convergence: two rooms sharing a border longer than max_door_width_m lose
//     the seed with the smaller circumradius; a room no path segment enters is removed from the
//     interior and the seeds are recomputed (§3.3.2).
//
// Plain function over plain data: no files, no logging. Thread-compatible.
#pragma once

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"
#include "services/floorplan/wall_samples.h"

namespace carvemap {

struct RoomLabelingOptions {
  // §3.3.1: diameter of the ball around a sample that truncates a line of sight; 0 = the
  // samples' spacing d_s.
  double occlusion_diameter_m = 0;
  // §3.3.2: ADA double door, 96 in.
  double max_door_width_m = 2.44;
  // §3.3.2: remove rooms the scanner's path never entered.
  bool remove_unentered_rooms = true;
  // Bound on refinement rounds (each round partitions, then merges or removes); reaching it is
  // not an error (the last partition is kept, RoomLabelingReport::converged = false).
  int max_rounds = 1000;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

// What the labelling did, for job.json and tests.
struct RoomLabelingReport {
  size_t samples = 0;            // distinct sample positions triangulated
  size_t triangles = 0;          // finite Delaunay triangles
  size_t interior_triangles = 0; // after carving, before unentered rooms are removed
  size_t sight_segments = 0;     // scanner-to-sample segments carved
  size_t truncated_segments = 0; // of those, shortened by the occlusion check
  size_t initial_seeds = 0;      // seeds of the first round
  size_t merged_seeds = 0;       // seeds dropped by the door-width rule
  size_t removed_rooms = 0;      // rooms removed as never entered
  int rounds = 0;
  bool converged = true;
};

// Errors: InvalidArgument for bad options or samples (WallSampleSet::Validate), or fewer than
// three distinct non-collinear samples; FailedPrecondition when no triangle is interior (no
// pose sees any sample and the path crosses no triangle), naming the counts.
[[nodiscard]] absl::StatusOr<FloorPlan> LabelRooms(const WallSampleSet& samples,
                                                   const RoomLabelingOptions& options,
                                                   RoomLabelingReport* report = nullptr);

}  // namespace carvemap
