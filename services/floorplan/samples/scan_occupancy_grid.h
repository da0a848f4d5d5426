// A 2D occupancy grid from horizontal line scans: the grid map §3.1.2 starts from ("a SLAM
// grid map"), built here from the rays of a scan.h5 instead of read from a PNG, so a 2D laser
// log goes to rooms in one step (gridmap_wall_samples.h takes the grid from there).
//
// Model: the usual log-odds occupancy grid of laser SLAM. Each ray marks the cells it crosses
// free (a miss) and the cell of its return occupied (a hit). The update values, the clamping
// and the threshold are OctoMap's defaults (Hornung et al., "OctoMap", Autonomous Robots 2013,
// §III-B and §V: P(hit) 0.7, P(miss) 0.4, clamped to [0.12, 0.97], occupied above 0.5; in its
// AbstractOccupancyOcTree: log-odds 0.85, −0.4, [−2, 3.5], threshold 0): a wall needs about one
// hit per two misses to stay occupied, so people walking by and grazing rays fade out while
// walls seen over and over stay. As OctoMap's insertPointCloud does, every cell is updated at
// most once per scan, and a cell both hit and crossed by that scan counts as hit: the many
// rays of one scan that graze a wall near their neighbour's return do not erase it.
//
// Rays with no return carve nothing: the scan format keeps no direction for them (docs/DESIGN.md
// §3: a no-return ray is a row of NaN and "carves nothing", as in the 3D carving), and a SICK or
// Hokuyo reports "no echo" for glass and black surfaces as well as for open space, so carving
// along a guessed direction would also erase real walls. Returns further than max_range_m
// carve free space up to that range and mark no hit (gmapping's maxUrange): a long grazing
// return's endpoint is the least certain part of a ray.
//
// Plain functions over plain data: no files, no logging.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <span>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/png_io.h"

namespace carvemap {

struct ScanOccupancyOptions {
  double resolution_m = 0.05;  // the floor maps' resolution (tests/data/SOURCES.md)
  // Log-odds updates, clamping and threshold: OctoMap's defaults (see the file comment).
  float hit_log_odds = 0.85f;      // P(hit) 0.7
  float miss_log_odds = -0.4f;     // P(miss) 0.4
  float min_log_odds = -2.0f;      // clamped at P 0.12
  float max_log_odds = 3.5f;       // clamped at P 0.97
  float occupied_log_odds = 0.0f;  // occupied above P 0.5, free at or below (once observed)
  // Returns beyond this range carve free space up to it and mark no hit; 0 = no limit.
  double max_range_m = 0;
  // InvalidArgument naming the first bad field.
  [[nodiscard]] absl::Status Validate() const;
};

// One frame of a horizontal line scanner, in the world's x-y plane: the scanner's position and
// the returns of its rays (no-return rays left out).
struct LineScan2D {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  std::vector<Eigen::Vector2d> hits;
};

enum class CellState : uint8_t { kUnknown = 0, kFree = 1, kOccupied = 2 };

// Cell (ix, iy) covers [origin_x + ix·res, origin_x + (ix+1)·res) × [origin_y + iy·res, …),
// row-major from the lower-left corner (as OccupancyGrid2D, grid_visibility.h).
struct ScanOccupancyGrid {
  double origin_x_m = 0, origin_y_m = 0, resolution_m = 0.05;
  int width = 0, height = 0;
  std::vector<float> log_odds;    // width·height, 0 where never observed
  std::vector<uint8_t> observed;  // 1 where some ray crossed or ended in the cell
  // Per-cell number of the last scan that updated it (the once-per-scan rule); internal.
  std::vector<uint32_t> last_scan;
  uint32_t scans = 0;  // scans integrated so far

  [[nodiscard]] CellState State(int ix, int iy, const ScanOccupancyOptions& options) const;
};

// An empty grid (all unknown) covering `bounds` (x-y, metres) with one cell to spare on every
// side, its origin a multiple of the resolution. InvalidArgument for bad options, an empty or
// non-finite box, or a grid over 2^31 cells.
[[nodiscard]] absl::StatusOr<ScanOccupancyGrid> EmptyScanOccupancyGrid(
    const Eigen::AlignedBox2d& bounds, const ScanOccupancyOptions& options);

// The box ScanOccupancyGrid must cover for `scan`: its origin and its returns, cut at
// options.max_range_m. Extends `box`.
void ExtendScanBounds(const LineScan2D& scan, const ScanOccupancyOptions& options,
                      Eigen::AlignedBox2d& box);

// Adds one scan (see the file comment). InvalidArgument when the origin or a return is not
// finite or lies outside the grid (the grid is made from bounds that hold the scan).
[[nodiscard]] absl::Status IntegrateLineScan(const LineScan2D& scan,
                                             const ScanOccupancyOptions& options,
                                             ScanOccupancyGrid& grid);

// EmptyScanOccupancyGrid over every scan's bounds, then IntegrateLineScan of each in order.
// InvalidArgument as those, or when there is no scan.
[[nodiscard]] absl::StatusOr<ScanOccupancyGrid> BuildScanOccupancyGrid(
    std::span<const LineScan2D> scans, const ScanOccupancyOptions& options);

// Gray values of the image, the ROS map_server convention for SLAM maps.
inline constexpr uint8_t kGrayOccupied = 0, kGrayUnknown = 205, kGrayFree = 254;

// The grid as an 8-bit map image, row 0 at the top (cell (ix, iy) is pixel (H−1−iy, ix)).
// GridMapWallSamples reads it with occupied_below 250, so unknown counts as blocked there: the
// edge of the observed free space bounds the rooms (§3.1.2 takes walls where free meets
// anything else).
[[nodiscard]] Image<uint8_t> OccupancyGridImage(const ScanOccupancyGrid& grid,
                                                const ScanOccupancyOptions& options);

}  // namespace carvemap
