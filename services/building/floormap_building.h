// A building extruded from a 2D floor map (docs/DESIGN.md §4; the maps and their ground truth are
// described in tests/data/SOURCES.md): occupied pixels become walls from floor to ceiling,
// furniture drawn into the furnished map becomes 0.75 m blocks, and the ground-truth rooms are
// traced exactly from the *_gt_segmentation.png regions.
#pragma once

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/building/building.h"

namespace carvemap {

struct FloormapOptions {
  std::string map_path;            // <map>.png, required
  std::string furniture_map_path;  // <map>_furnitures.png, optional ("" = none)
  std::string rooms_map_path;      // <map>_gt_segmentation.png, optional ("" = rooms of the map)
  double resolution_m = 0.05;      // per pixel (the maps' own resolution)
  double ceiling_height_m = 2.6;
  double furniture_height_m = 0.75;
  double clearance_m = 0.25;      // walker half-width on the nav grid
  double min_clearance_m = 0.15;  // relaxed down to this if some room is otherwise unreachable
  int min_room_pixels = 400;      // smaller free regions are not rooms (SOURCES.md)
  [[nodiscard]] absl::Status Validate() const;
};

// The three files of map `name` (e.g. "office_a") in folder `dir`.
[[nodiscard]] FloormapOptions FloormapOptionsFor(const std::string& dir, const std::string& name);

// What the extrusion had to decide, for logs and tests.
struct FloormapReport {
  double clearance_used_m = 0;       // the nav grid's clearance after any relaxation
  std::vector<int> unentered_rooms;  // room ids no walk can reach (entered = false)
  int wall_prisms = 0, furniture_objects = 0;
};

// Builds the building: one level (floor 0, ceiling `ceiling_height_m`), rooms ordered largest
// first (rooms[0], where the walk starts, is usually the corridor), doors where a ground-truth
// separator line joins two rooms (one door, between the two it touches most, when a line touches
// more; none without a rooms map), one nav grid with one cell per map pixel. Room rings follow
// pixel edges: where a room's pixels touch only at a corner the ring touches itself there. Errors
// name the file that could not be read or does not match.
absl::StatusOr<Building> MakeFloormapBuilding(const FloormapOptions& options,
                                              FloormapReport* report = nullptr);

}  // namespace carvemap
