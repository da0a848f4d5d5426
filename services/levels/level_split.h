// Level splitting (§5.2, fallback §2.5; docs/DESIGN.md §6 stage 3, §7 levels.json): the floor and
// ceiling elevations of each building level and the heights that split the model between
// levels.
//
// §5.2: keep the planar regions (§4.2.4) within 5° of horizontal and above an area threshold;
// histogram their area over elevation, floors (normal up) and ceilings (normal down) apart;
// the peaks are the floor and ceiling heights; pair each floor with the ceilings above it.
// §2.5 (fallback, when there are no horizontal regions): the same on histograms of point
// heights, points seen from above counting as floor and points seen from below as ceiling.
//
// Plain functions over plain data: no files, no logging. Thread-compatible.
#pragma once

#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/mesh/planar_regions.h"

namespace carvemap {

struct LevelSplitOptions {
  // §5.2: regions whose normal is more than this from vertical are not horizontal.
  double max_tilt_deg = 5.0;
  // §5.2: smaller horizontal regions are dropped (table tops, stair treads, light fixtures).
  double min_region_area_m2 = 2.0;
  // Histogram bin and the half-width of the triangular kernel that smooths it, m.
  double bin_m = 0.02;
  double smoothing_m = 0.02;
  // Peaks closer than this are one peak (the larger one); samples within half of it of a
  // peak refine its elevation (weighted mean), m. Small, because rooms of one level have
  // ceilings 10 cm apart (carved, they can come out 7 cm apart) and the highest one must not
  // be averaged with or suppressed by the others.
  double peak_window_m = 0.05;
  // A peak must weigh at least this fraction of its histogram's largest peak.
  double min_peak_fraction = 0.05;
  // Floor peaks less than this above a level's floor belong to that level (tables, landings,
  // raised platforms); the next level's floor is at least this high above, m.
  double min_level_height_m = 2.0;
  // A level's ceiling is at least this above its floor (lower down-facing surfaces are
  // stair undersides, shelves, fixtures), m.
  double min_ceiling_height_m = 1.8;
  // The lowest level starts this far below its floor; the top level ends this far above its
  // ceiling (the model has nothing beyond; a finite number keeps levels.json plain), m.
  double end_margin_m = 0.5;
  // When a level has no ceiling peak: its ceiling is the next level's floor, or for the top
  // level its floor plus this, m.
  double default_ceiling_height_m = 2.5;

  // InvalidArgument naming the first bad field (non-finite, non-positive bins, angles outside
  // [0, 90], fractions outside [0, 1], negative heights).
  [[nodiscard]] absl::Status Validate() const;
};

// One level. It covers elevations [split_z_low, split_z_high); consecutive levels share the
// split between them, halfway between the lower level's ceiling and the upper level's floor
// (§5.2).
struct Level {
  int index = 0;           // 0 = lowest
  double floor_z = 0;      // m
  double ceiling_z = 0;    // m: the highest ceiling peak of the level (rooms' ceilings differ)
  double split_z_low = 0;  // m
  double split_z_high = 0; // m
  // §2.5's choice: the most populated ceiling peak of the level, m.
  double dominant_ceiling_z = 0;
  bool ceiling_found = true;  // false: ceiling_z is the fallback (default_ceiling_height_m)
  double floor_weight = 0;    // area (m²) or point count under the floor peak
  double ceiling_weight = 0;  // same for the ceiling peak
};

// The position in `levels` of the level whose [split_z_low, split_z_high) holds `z`, or −1.
[[nodiscard]] inline int LevelContaining(std::span<const Level> levels, double z) {
  for (size_t k = 0; k < levels.size(); ++k) {
    if (z >= levels[k].split_z_low && z < levels[k].split_z_high) return static_cast<int>(k);
  }
  return -1;
}

// A weighted elevation: a horizontal region (centroid z, area) or a histogram bin (centre,
// count).
struct HeightSample {
  double z = 0;       // m
  double weight = 0;  // > 0
};

// Histograms of point heights (§2.5): bin i covers [z0_m + i·bin_m, z0_m + (i+1)·bin_m).
// `floor` counts points seen from above (the ray goes down to them), `ceiling` points seen
// from below. Both have the same length.
struct HeightHistogram {
  double z0_m = 0;
  double bin_m = 0.02;
  std::vector<double> floor;
  std::vector<double> ceiling;
};

// The core: levels from floor and ceiling samples (§5.2 pairing). No floor sample → no level.
// A level without a ceiling peak falls back (next floor, or floor + default_ceiling_height_m),
// unless the level below found its ceiling: then that floor is carved space over a ceiling and
// joins the level below.
// Errors: InvalidArgument for bad options, non-finite samples or negative weights, or a
// height range of more than 10^7 bins.
[[nodiscard]] absl::StatusOr<std::vector<Level>> SplitLevelsFromSamples(
    std::span<const HeightSample> floors, std::span<const HeightSample> ceilings,
    const LevelSplitOptions& options = {});

// §5.2: from planar regions (normals into free space: floors up, ceilings down).
[[nodiscard]] absl::StatusOr<std::vector<Level>> SplitLevelsFromRegions(
    std::span<const PlanarRegion> regions, const LevelSplitOptions& options = {});

// §2.5: the point-height histograms. Errors as above, and InvalidArgument for a histogram with
// bin_m ≤ 0 or floor and ceiling of different lengths.
[[nodiscard]] absl::StatusOr<HeightHistogram> BuildHeightHistogram(
    std::span<const double> floor_points_z, std::span<const double> ceiling_points_z,
    double bin_m);
[[nodiscard]] absl::StatusOr<std::vector<Level>> SplitLevelsFromHistogram(
    const HeightHistogram& histogram, const LevelSplitOptions& options = {});

// Regions first; the point histogram (may be null) when the regions give no level.
struct LevelSplit {
  std::vector<Level> levels;
  std::string source;  // "regions", "points" or "none"
};
[[nodiscard]] absl::StatusOr<LevelSplit> SplitLevels(std::span<const PlanarRegion> regions,
                                                     const HeightHistogram* point_heights,
                                                     const LevelSplitOptions& options = {});

// docs/DESIGN.md §7 levels.json: [{index, floor_z, ceiling_z, split_z}, …] with split_z the level's
// lower split (split_z_low: the level covers [split_z, next level's split_z)), plus the
// optional fields split_z_high, dominant_ceiling_z and ceiling_found.
[[nodiscard]] nlohmann::json LevelsToJson(std::span<const Level> levels);

}  // namespace carvemap
