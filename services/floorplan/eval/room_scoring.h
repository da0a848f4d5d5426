// Room segmentation scored against real room labels (docs/DESIGN.md §6 stage 5 evaluation;
// tests/data/SOURCES.md): ground-truth rooms from the *_gt_segmentation.png maps, a floor
// plan rasterised onto the same pixels, and two usual metrics: room F1 at IoU > 0.5 and Bormann
// et al.'s (ICRA 2016) overlap recall / precision.
//
// Plain functions over plain data: no files, no logging.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"
#include "storage/png_io.h"

namespace carvemap {

// One room label per pixel, row-major, row 0 = top (like Image); −1 = no room. Labels are any
// non-negative ints (they need not be dense).
struct LabelImage {
  int width = 0, height = 0;
  std::vector<int32_t> labels;
};

// SOURCES.md rule: pixels ≥ free_at_least are free; each 8-connected free region is one room;
// regions under min_pixels pixels are not rooms (−1), nor is anything not free. Labels 0..n−1 in
// the order of each room's first pixel in row-major order (top row first). An image whose
// pixels.size() ≠ width·height gives all −1.
[[nodiscard]] LabelImage LabelsFromSegmentation(const Image<uint8_t>& gt, int free_at_least = 250,
                                                int min_pixels = 400);

// The truth rooms that hold at least one of `points` (world x-y; pixel (row, col) covers
// [origin_x + col·res, …) × [origin_y + (H − 1 − row)·res, …), docs/DESIGN.md §4) keep their
// label; every other pixel becomes −1. For a survey that did not visit the whole building: §3.3.2
// removes the rooms the walk never entered from the plan, so those are scored against the
// entered rooms alone. Points off the image are ignored. Labels are not renumbered.
[[nodiscard]] LabelImage KeepEnteredRooms(const LabelImage& truth,
                                          const std::vector<Eigen::Vector2d>& points,
                                          double resolution_m, double origin_x_m,
                                          double origin_y_m);

// Pixel (row, col) has centre x = origin_x + (col + 0.5)·res, y = origin_y + (H − 1 − row +
// 0.5)·res (docs/DESIGN.md §4); its label is plan.triangle_room of the triangle holding the centre,
// −1 outside every triangle. Half-open per scanline (a centre on the left edge of a triangle's span
// is in, on the right edge out; rows likewise by y), so a centre on an edge shared by two
// triangles goes to exactly one. Triangles with an out-of-range vertex index are skipped.
// Cost: O(pixels covered + rows per triangle).
[[nodiscard]] LabelImage RasterizeFloorPlan(const FloorPlan& plan, int width, int height,
                                            double resolution_m, double origin_x_m,
                                            double origin_y_m);

// One truth room's best match: what a failed match was short of (a room cut in two, merged
// with its neighbour, or partly unseen all show here before they show in the F1).
struct TruthRoomScore {
  int32_t label = 0;
  int64_t pixels = 0;                 // its area in the scoring domain
  int32_t best_predicted = -1;        // the predicted room of highest IoU with it; −1 none
  double best_iou = 0;                // IoU with that room, in the scoring domain
  int64_t best_predicted_pixels = 0;  // that room's area in the domain
};

struct RoomScores {
  int truth_rooms = 0, predicted_rooms = 0, matched = 0;
  double precision = 0, recall = 0, f1 = 0;
  double bormann_recall = 0, bormann_precision = 0;
  std::vector<TruthRoomScore> per_truth;  // in label order
};

// Scoring domain: the pixels inside some truth room (truth label ≥ 0). Predicted pixels outside
// it (walls, the doorway lines of the truth maps, outside the building) are ignored everywhere,
// the same for every map: a plan's rooms reach half a cell into the walls they are built on, and
// that is no error of segmentation. So a predicted room's area is its pixels in the domain, and a
// predicted room with none there does not count (not in predicted_rooms either).
//  - Room F1: a truth room is matched when one predicted room has IoU > 0.5 with it;
//    precision = matched / predicted_rooms, recall = matched / truth_rooms, f1 their harmonic
//    mean (0 when both are 0).
//  - Bormann et al.: recall = mean over truth rooms of (largest overlap with one predicted room)
//    / (truth room area); precision = mean over predicted rooms of (largest overlap with one
//    truth room) / (predicted room area in the domain).
// A value whose denominator is empty (no truth rooms, no predicted rooms) is 0.
// Errors: InvalidArgument when the two images differ in size or labels.size() ≠ width·height.
[[nodiscard]] absl::StatusOr<RoomScores> ScoreRooms(const LabelImage& truth,
                                                    const LabelImage& predicted);

}  // namespace carvemap
