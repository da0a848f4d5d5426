// The top-down open-height map (§5.4, docs/DESIGN.md §6.9): for each xy column of leaves, the sum
// over the octree nodes it crosses of p(interior) × the node's height, i.e. the expected height
// of open (interior) space in metres. Only observed leaves contribute: unobserved space
// (p = 0.5 by convention, §4.3.2) would otherwise add half the height of every unscanned chunk
// above and below the building.
//
// One pixel per leaf column at the octree resolution over the xy footprint of the chunks with
// tiles. By default the map covers the whole height of the octree; a z range (a level's
// [split_z_low, split_z_high) from services/levels, §5.2) makes the map of one level, leaves
// cut by the range adding only the height of their part inside it.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "storage/png_io.h"
#include "storage/tile_store.h"

namespace carvemap {

// Where a topdown map sits: pixel (row, col) of the H-row image is the column with
// x = origin_x_m + (col + 0.5)·resolution_m, y = origin_y_m + (H − 1 − row + 0.5)·resolution_m
// at its centre (lower-left origin, as docs/DESIGN.md §4 floor maps).
struct TopdownGeometry {
  double origin_x_m = 0, origin_y_m = 0;
  double resolution_m = 0;
  int width = 0, height = 0;
};

// The elevations a map integrates: [z_lo_m, z_hi_m), m. The default is all of them; an empty
// range (z_lo_m ≥ z_hi_m, or NaN) gives a map of zeros.
struct TopdownZRange {
  double z_lo_m = -std::numeric_limits<double>::infinity();
  double z_hi_m = std::numeric_limits<double>::infinity();
  [[nodiscard]] bool all() const {
    return z_lo_m == -std::numeric_limits<double>::infinity() &&
           z_hi_m == std::numeric_limits<double>::infinity();
  }
};

// The map as a robot's navigation stack reads a 2D occupancy grid (ROS map_server's trinary
// map): for a band of heights above a level's floor (the body of a robot or a person), a
// column is occupied when it holds at least `occupied_min_m` of observed solid space (leaves
// with p ≤ 0.5: walls, furniture, a desk's top), free when it holds none and at least
// `free_min_fraction` of the band is observed open space, and unknown otherwise (never seen,
// or the inside of a wall behind its observed skin).
struct OccupancyThresholds {
  double occupied_min_m = 0;  // 0: one leaf's height
  double free_min_fraction = 0.5;
};

// Pixel values of ToOccupancy, as ROS's map_saver writes them: with `negate: 0` and the
// thresholds WriteRosMap puts in the YAML, map_server reads them as occupied, free, unknown.
inline constexpr uint8_t kOccupiedPixel = 0, kFreePixel = 254, kUnknownPixel = 205;

class TopdownMap {
 public:
  // Covers the xy footprint of `chunks` (an empty list gives a 0×0 map) and the elevations of
  // `z_range`. With `occupancy`, the map also sums each column's observed and solid heights in
  // the range (ToOccupancy, WriteRosMap; 8 more bytes per pixel).
  TopdownMap(const OctreeGrid& grid, const std::vector<ChunkKey>& chunks,
             const TopdownZRange& z_range = {}, bool occupancy = false);

  // Adds a tile's observed leaves (any order, each tile once). Tiles outside the footprint
  // given to the constructor are an error (InvalidArgument naming the chunk).
  absl::Status AddTile(const TileData& tile);

  [[nodiscard]] const TopdownGeometry& geometry() const { return geometry_; }
  [[nodiscard]] const TopdownZRange& z_range() const { return z_range_; }
  // Expected open height (m) of pixel (row, col).
  [[nodiscard]] float open_height_m(int row, int col) const {
    return height_m_[size_t(row) * geometry_.width + col];
  }
  [[nodiscard]] float max_open_height_m() const;

  // 8-bit gray: round(255 · min(h, max_height_m) / max_height_m); 0 = no open space.
  [[nodiscard]] Image<uint8_t> ToGray8(double max_height_m) const;

  // Writes the PNG (ToGray8) and a JSON sidecar with the geometry, the scale and what the map
  // covers ("z_range": "all", or [z_lo, z_hi] with null for an open end), both through
  // "<name>.partial" and a rename.
  absl::Status Write(const std::string& png_path, const std::string& json_path,
                     double max_height_m, int level) const;

  // Only for a map made with `occupancy` (else FailedPrecondition from WriteRosMap, an image of
  // unknowns from ToOccupancy): kOccupiedPixel, kFreePixel or kUnknownPixel per pixel.
  [[nodiscard]] Image<uint8_t> ToOccupancy(const OccupancyThresholds& thresholds) const;
  // The ROS map_server pair: a binary PGM (P5) of ToOccupancy and its YAML (image, mode
  // trinary, resolution, origin [x, y, 0] of the lower-left corner, negate 0, occupied_thresh
  // 0.65, free_thresh 0.196), both through "<name>.partial" and a rename. `about` goes into the
  // YAML as comment lines.
  absl::Status WriteRosMap(const std::string& pgm_path, const std::string& yaml_path,
                           const OccupancyThresholds& thresholds, const std::string& about) const;

 private:
  OctreeGrid grid_;
  TopdownZRange z_range_;
  int64_t min_leaf_x_ = 0, min_leaf_y_ = 0;  // leaf keys of column (col 0, bottom row)
  TopdownGeometry geometry_;
  std::vector<float> height_m_;  // row-major, row 0 = top (largest y)
  // With `occupancy`: observed height and observed solid (p ≤ 0.5) height, as height_m_.
  std::vector<float> observed_m_, solid_m_;
};

}  // namespace carvemap
