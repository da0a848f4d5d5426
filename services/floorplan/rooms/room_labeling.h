// Floor plan with rooms from wall samples (§3.3.1–§3.3.2; docs/DESIGN.md §6 stage 5):
//  1. 2D Delaunay triangulation of the wall samples (CGAL, inside the .cc).
//  2. Interior = triangles crossed by a scanner-to-sample segment (s, p), p seen from s, or by a
//     scanner-to-scanner segment between consecutive poses; crossings exclusive of triangle
//     edges. Occlusion check: a segment (s, p) that passes through the ball of diameter
//     occlusion_diameter_m around another sample p' is truncated at p' (§3.3.1), so a wall
//     scanned from both sides is never carved away.
//  3. Room seeds: interior triangles whose circumcircle is the largest of all interior
//     circumcircles it intersects (§3.3.2), "intersects" meaning by more than seed_min_overlap.
//  4. Partition: greedy flood fill from the seeds, longest shared edge first (§3.3.2); thin
//     walls (edges between interior triangles no longer than thin_wall_spacings × d_s) are not
//     crossed.
//  5. Refinement to convergence: two rooms sharing a border that is no door lose the seed with
//     the smaller circumradius; a room no path segment enters is removed from the interior and
//     the seeds are recomputed (§3.3.2). A border (one contiguous piece of shared edges) is no
//     door when it is longer than max_door_width_m (§3.3.2) or when the free space does not
//     narrow there (door_narrowing, an extension: a 2 m corridor's pieces share borders of its
//     width, under a double door's 2.44 m, and would stay split).
//  6. Open sides: a converged room is cut where a dead-end part of it, which holds no seed,
//     opens between two wall ends (extension).
//  7. Rooms under min_room_area_m2 join a neighbour (extension).
//
// The extensions, where the dissertation is silent or its rule fails on real maps (measured on the
// 9 real floor maps, docs/BENCHMARKS.md "Floor plans with rooms"), each with its own option so it
// can be switched off (0): door narrowing, thin walls, seed overlap, open sides, small rooms.
// Borders are counted as contiguous pieces, the dissertation's "a border": the sum of all shared
// edges would merge two rooms joined by two ordinary doors.
//
// Plain function over plain data: no files, no logging. Thread-compatible.
#pragma once

#include <functional>

#include <Eigen/Core>

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
  // Extension of §3.3.2's door test: a border piece no wider than max_door_width_m is a door
  // only if its length is at most door_narrowing × the local free-space diameter: twice the
  // largest circumradius (§3.3.2's local feature size) of the faces on either side within
  // door_context × its length of it. A door narrows the space it joins: 0.9 m into a 2 m
  // corridor is 0.45, a 1.2 m wide room's 1 m door off a hall is small against the hall, while
  // the border between two pieces of one corridor is as wide as the corridor (ratio ≈ 1).
  // 0 disables the extension (the dissertation's rule alone).
  double door_narrowing = 0.7;
  double door_context = 2.0;
  // Extension of §3.3.2, open sides: where a bay or a room opens onto a corridor over its
  // whole width (3–4 m on the lab maps, whose labels call them rooms), the largest circle sits
  // in the opening and no seed is left inside the room. Once the rooms have converged, a room
  // is cut along a segment between two wall ends (a partition's tip, a wall's end at an
  // opening, a corner: the samples between a few spacings and wall_end_radius_m from it span at
  // most wall_end_span_deg seen from it), one of them a tip (at most wall_tip_span_deg: two
  // corners bound a corridor's end as well, or furniture), up to open_side_max_m long, through
  // its own triangles, when the smaller side is a dead end (it borders no other room: a
  // corridor's branch leads on through its doors), was entered, has at least
  // open_side_min_area_m2 and is at least open_side_min_depth times as deep as the cut is long
  // (area ≥ depth × length²: no sliver between furniture and a wall). 0 for open_side_max_m
  // disables it.
  double open_side_max_m = 5.0;
  double open_side_min_area_m2 = 4.0;
  double open_side_min_depth = 0.75;
  double wall_end_radius_m = 0.6;
  double wall_end_span_deg = 135;
  double wall_tip_span_deg = 60;
  // Extension of §3.3.1–§3.3.2: an edge between two interior triangles no longer than
  // thin_wall_spacings × d_s (the samples' spacing) is a wall one sample thick, scanned from
  // both sides; the partition does not cross it and borders leave it out. 2.1: neighbours on a
  // grid (d_s, √2·d_s) and one missing sample (2·d_s), with slack for rounding. 0 disables it.
  double thin_wall_spacings = 2.1;
  // Extension of §3.3.2's seed test: two circumcircles intersect only when they overlap by more
  // than seed_min_overlap × the smaller radius, so a large room's circle bulging a few cm
  // through a doorway does not suppress the seed of the room behind it. 0 = any overlap (the
  // dissertation's literal test).
  double seed_min_overlap = 0.25;
  // Extension: once the rooms have converged, a room smaller than this (a sliver between a wall
  // and furniture that the path crosses, a pocket cut off by thin walls) joins the room it
  // shares the most edge length with. 1 m²: the floor maps' own rule for what is a room
  // (tests/data/SOURCES.md); no usable room is smaller. 0 disables it.
  double min_room_area_m2 = 1.0;
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
  size_t merged_seeds = 0;       // seeds dropped because a border is no door
  size_t narrow_merged_seeds = 0;  // of those, for door_narrowing alone (not max_door_width_m)
  size_t open_sides_split = 0;     // rooms cut off a converged room along an open side
  size_t small_merged_rooms = 0;   // rooms under min_room_area_m2 joined to a neighbour
  size_t removed_rooms = 0;      // rooms removed as never entered (thin-wall pockets included)
  double removed_area_m2 = 0;    // their area
  int rounds = 0;
  bool converged = true;
};

// Errors: InvalidArgument for bad options or samples (WallSampleSet::Validate), or fewer than
// three distinct non-collinear samples; FailedPrecondition when no triangle is interior (no
// pose sees any sample and the path crosses no triangle), naming the counts.
[[nodiscard]] absl::StatusOr<FloorPlan> LabelRooms(const WallSampleSet& samples,
                                                   const RoomLabelingOptions& options,
                                                   RoomLabelingReport* report = nullptr);

// Steps 1 and 3–6 on an interior decided elsewhere: `interior_test` is asked, for each Delaunay
// triangle (its corners, counter-clockwise), whether it is interior, and replaces the carving of
// step 2 (the Eigencrust floor plan, §3.2, eigencrust_floorplan.h, gets its rooms this way). The
// path still decides which rooms were entered. Errors as LabelRooms'.
using InteriorTest = std::function<bool(const Eigen::Vector2d&, const Eigen::Vector2d&,
                                        const Eigen::Vector2d&)>;
[[nodiscard]] absl::StatusOr<FloorPlan> LabelRoomsOfInterior(const WallSampleSet& samples,
                                                             const InteriorTest& interior_test,
                                                             const RoomLabelingOptions& options,
                                                             RoomLabelingReport* report = nullptr);

}  // namespace carvemap
