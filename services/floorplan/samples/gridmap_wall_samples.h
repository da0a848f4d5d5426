// Wall samples straight from a 2D occupancy grid map (§3.1.2; docs/DESIGN.md §6 stage 4): a SLAM
// grid map already is "a set of 2D positions of walls", so every occupied cell that borders free
// space becomes one sample at its centre, and the recorded path gives the scanner poses. A 2D map
// has no heights, so every sample gets the same floor and ceiling (§3.1.2 takes them from the
// scanners' estimates; here they are options).
//
// Clutter: §3.1.1 keeps furniture out of the wall samples with its height rule (a wall reaches
// H = 2 m; "clutter such as furniture or plants do not affect position of wall samples"), and
// §3.4.2 calls it desirable that cubicle walls and counters are left out of the floor plan. A 2D
// map has no heights, so the rule here is by size: an occupied component (8-connected) that
// stands free (touches no wall, nor the map's border) and is smaller than clutter_max_extent_m
// across is furniture (a chair, a small table, a plant, a bin) or map noise, and gives no
// samples. It still blocks the lines of sight (the scanner saw it). Furniture touching a wall is
// part of the wall's component and stays; so do larger free-standing pieces, since a wall stub
// standing free between two doors is one of them, and dropping a wall merges rooms for good while
// a desk left in only splits one (which room_labeling's rules mostly repair).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/floorplan/samples/grid_visibility.h"
#include "services/floorplan/wall_samples.h"
#include "storage/png_io.h"

namespace carvemap {

struct GridMapOptions {
  double resolution_m = 0.05;  // per pixel (the floor maps' own, tests/data/SOURCES.md)
  // World x, y of the image's lower-left corner (docs/DESIGN.md §4: lower-left origin).
  double origin_x_m = 0;
  double origin_y_m = 0;
  int occupied_below = 250;  // gray < this is occupied (SOURCES.md: upstream's threshold)
  // Heights put on every sample, m (floor_z < ceiling_z).
  double floor_z = 0;
  double ceiling_z = 2.6;
  // Free-standing occupied components whose bounding-box diagonal is below this are clutter: no
  // samples (see the file comment). 0 keeps every occupied cell. On the real floor maps
  // (tests/data/floormaps) every free-standing piece of furniture is ≤ 1.17 m across and
  // every free-standing piece of wall (stubs between doors, in the plain maps too) ≥ 1.45 m.
  double clutter_max_extent_m = 1.3;
  VisibilityOptions visibility;
  // InvalidArgument naming the first bad field (including visibility's).
  [[nodiscard]] absl::Status Validate() const;
};

// The map as a grid: image row 0 is the top, so cell (ix, iy) is pixel (row H−1−iy, col ix);
// blocked (1) where gray < occupied_below. Only the geometric options are used.
[[nodiscard]] OccupancyGrid2D GridFromImage(const Image<uint8_t>& gray,
                                            const GridMapOptions& options);

// One sample per occupied cell with a free 4-neighbour (cells outside the image are not free) and
// not in a clutter component (clutter_max_extent_m), at the cell centre, in row-major cell order (iy, then ix). spacing_m = resolution. normal =
// unit vector towards the free side: the normalised sum of the unit directions to the free cells
// of the 5×5 window around the cell that are 4-connected in the window to its free 4-neighbours;
// zero where they cancel (a one-cell wall with free space on both sides). poses = path, in
// order, path_breaks empty; then AssignVisiblePoses with options.visibility. A path point on an
// occupied cell is accepted (a SLAM path may graze a wall); its rays stop at once, so it sees at
// most the sample nearest it.
// Errors: InvalidArgument for bad options, an empty or inconsistent image, an empty path, or a
// path point that is not finite or outside the map (naming its index); FailedPrecondition when
// the map has no occupied cell next to a free one.
[[nodiscard]] absl::StatusOr<WallSampleSet> GridMapWallSamples(
    const Image<uint8_t>& gray, const std::vector<Eigen::Vector2d>& path,
    const GridMapOptions& options);

}  // namespace carvemap
