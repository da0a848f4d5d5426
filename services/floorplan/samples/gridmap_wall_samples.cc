#include "services/floorplan/samples/gridmap_wall_samples.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"

namespace carvemap {

absl::Status GridMapOptions::Validate() const {
  if (!std::isfinite(resolution_m) || resolution_m <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("grid map: resolution_m must be finite and > 0, got ", resolution_m));
  }
  if (!std::isfinite(origin_x_m) || !std::isfinite(origin_y_m)) {
    return absl::InvalidArgumentError("grid map: origin is not finite");
  }
  if (!std::isfinite(clutter_max_extent_m) || clutter_max_extent_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "grid map: clutter_max_extent_m must be finite and ≥ 0, got ", clutter_max_extent_m));
  }
  if (occupied_below < 1 || occupied_below > 256) {
    return absl::InvalidArgumentError(
        absl::StrCat("grid map: occupied_below must be in [1, 256], got ", occupied_below));
  }
  if (!std::isfinite(floor_z) || !std::isfinite(ceiling_z) || floor_z >= ceiling_z) {
    return absl::InvalidArgumentError(absl::StrCat(
        "grid map: need finite floor_z < ceiling_z, got ", floor_z, " and ", ceiling_z));
  }
  return visibility.Validate();
}

OccupancyGrid2D GridFromImage(const Image<uint8_t>& gray, const GridMapOptions& options) {
  OccupancyGrid2D grid;
  grid.origin_x_m = options.origin_x_m;
  grid.origin_y_m = options.origin_y_m;
  grid.resolution_m = options.resolution_m;
  grid.width = gray.width;
  grid.height = gray.height;
  grid.cells.assign(static_cast<size_t>(gray.width) * gray.height, 0);
  // docs/DESIGN.md §4: image row 0 is the top, the grid's row 0 the bottom.
  for (int iy = 0; iy < gray.height; ++iy) {
    for (int ix = 0; ix < gray.width; ++ix) {
      grid.cells[static_cast<size_t>(iy) * gray.width + ix] =
          gray.at(gray.height - 1 - iy, ix) < options.occupied_below ? 1 : 0;
    }
  }
  return grid;
}

absl::StatusOr<WallSampleSet> GridMapWallSamples(const Image<uint8_t>& gray,
                                                 const std::vector<Eigen::Vector2d>& path,
                                                 const GridMapOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (gray.width <= 0 || gray.height <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("grid map: empty map (", gray.width, "×", gray.height, " pixels)"));
  }
  if (gray.pixels.size() != static_cast<size_t>(gray.width) * gray.height) {
    return absl::InvalidArgumentError(absl::StrCat("grid map: ", gray.pixels.size(),
                                                   " pixels for a ", gray.width, "×", gray.height,
                                                   " image"));
  }
  if (path.empty()) {
    return absl::InvalidArgumentError(
        "grid map: empty path (the samples' lines of sight need scanner poses)");
  }
  const double res = options.resolution_m;
  const double w_m = gray.width * res, h_m = gray.height * res;
  for (size_t i = 0; i < path.size(); ++i) {
    const double x = path[i].x() - options.origin_x_m, y = path[i].y() - options.origin_y_m;
    if (!std::isfinite(x) || !std::isfinite(y) || x < 0 || y < 0 || x >= w_m || y >= h_m) {
      return absl::InvalidArgumentError(
          absl::StrCat("grid map: path point ", i, " (", path[i].x(), ", ", path[i].y(),
                       ") is outside the map [", options.origin_x_m, ", ", options.origin_x_m + w_m,
                       ") × [", options.origin_y_m, ", ", options.origin_y_m + h_m, ")"));
    }
  }

  const OccupancyGrid2D grid = GridFromImage(gray, options);
  const int w = grid.width, h = grid.height;
  // Outside the image is unknown, not free: a map's border is no wall face.
  auto free = [&](int ix, int iy) {
    return ix >= 0 && iy >= 0 && ix < w && iy < h &&
           grid.cells[static_cast<size_t>(iy) * w + ix] == 0;
  };

  // Clutter (see the header): occupied 8-connected components whose bounding box has a diagonal
  // under clutter_max_extent_m. A component touching the image border is the outside mass of a
  // map (or cut off by it), never clutter.
  std::vector<uint8_t> clutter(static_cast<size_t>(w) * h, 0);
  if (options.clutter_max_extent_m > 0) {
    std::vector<uint8_t> seen(static_cast<size_t>(w) * h, 0);
    std::vector<int> stack, members;
    for (int start = 0; start < w * h; ++start) {
      if (grid.cells[start] == 0 || seen[start]) continue;
      seen[start] = 1;
      stack.assign(1, start);
      members.clear();
      int x0 = w, x1 = -1, y0 = h, y1 = -1;
      while (!stack.empty()) {
        const int c = stack.back();
        stack.pop_back();
        members.push_back(c);
        const int cx = c % w, cy = c / w;
        x0 = std::min(x0, cx);
        x1 = std::max(x1, cx);
        y0 = std::min(y0, cy);
        y1 = std::max(y1, cy);
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int nx = cx + dx, ny = cy + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
            const int n = ny * w + nx;
            if (grid.cells[n] == 0 || seen[n]) continue;
            seen[n] = 1;
            stack.push_back(n);
          }
        }
      }
      const bool on_border = x0 == 0 || y0 == 0 || x1 == w - 1 || y1 == h - 1;
      const double extent = std::hypot(x1 - x0 + 1, y1 - y0 + 1) * res;
      if (!on_border && extent < options.clutter_max_extent_m) {
        for (int c : members) clutter[c] = 1;
      }
    }
  }

  WallSampleSet set;
  set.spacing_m = res;
  set.poses = path;
  for (int iy = 0; iy < h; ++iy) {
    for (int ix = 0; ix < w; ++ix) {
      if (clutter[static_cast<size_t>(iy) * w + ix]) continue;
      if (free(ix, iy) ||
          !(free(ix - 1, iy) || free(ix + 1, iy) || free(ix, iy - 1) || free(ix, iy + 1))) {
        continue;
      }
      WallSample s;
      s.position = Eigen::Vector2d(options.origin_x_m + (ix + 0.5) * res,
                                   options.origin_y_m + (iy + 0.5) * res);
      // Normal by a vote of the free cells around (5×5) rather than a PCA of boundary cells
      // (§3.1.1): PCA gives only the wall's line, and its sign would have to come from the free
      // side anyway; the vote gives the side directly, smooths the 45° steps of rasterised
      // diagonal walls, and cancels to zero on a one-cell wall with free space on both sides.
      // Only free cells 4-connected (inside the window) to this cell's free 4-neighbours vote,
      // so the room behind a two-cell wall does not pull the normal towards itself.
      uint8_t state[5][5] = {};  // 1 = free, 2 = free and reached
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) state[dy + 2][dx + 2] = free(ix + dx, iy + dy) ? 1 : 0;
      int stack[25][2];
      int top = 0;
      for (const auto& [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
        if (state[dy + 2][dx + 2] == 1) {
          state[dy + 2][dx + 2] = 2;
          stack[top][0] = dx;
          stack[top++][1] = dy;
        }
      }
      Eigen::Vector2d sum = Eigen::Vector2d::Zero();
      while (top > 0) {
        --top;
        const int cx = stack[top][0], cy = stack[top][1];
        sum += Eigen::Vector2d(cx, cy).normalized();
        for (const auto& [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
          const int nx = cx + dx, ny = cy + dy;
          if (nx < -2 || nx > 2 || ny < -2 || ny > 2 || state[ny + 2][nx + 2] != 1) continue;
          state[ny + 2][nx + 2] = 2;
          stack[top][0] = nx;
          stack[top++][1] = ny;
        }
      }
      // Less than one cell's worth of net direction: the free side is ambiguous.
      if (sum.norm() >= 1.0) s.normal = sum.normalized();
      s.floor_z = options.floor_z;
      s.ceiling_z = options.ceiling_z;
      set.samples.push_back(std::move(s));
    }
  }
  if (set.samples.empty()) {
    return absl::FailedPreconditionError(
        absl::StrCat("grid map: no occupied cell next to a free one in the ", w, "×", h,
                     " map (occupied_below = ", options.occupied_below, ")"));
  }
  if (absl::Status s = AssignVisiblePoses(grid, options.visibility, set); !s.ok()) return s;
  return set;
}

}  // namespace carvemap
