#include "services/floorplan/samples/scan_occupancy_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// Visits the cells a segment crosses, from the cell of `a` to the cell of `b` inclusive, in
// order (Amanatides & Woo's traversal, in cell units). Written here: OctoMap's ray keys are
// 3D octree keys, and none of our libraries walks a 2D grid. Exactly |Δix| + |Δiy| steps, so the
// last cell visited is b's even when floating point rounds a crossing the other way.
template <typename Visit>
void TraverseCells(const Eigen::Vector2d& a, const Eigen::Vector2d& b, Visit&& visit) {
  int ix = static_cast<int>(std::floor(a.x())), iy = static_cast<int>(std::floor(a.y()));
  const int ex = static_cast<int>(std::floor(b.x())), ey = static_cast<int>(std::floor(b.y()));
  const double dx = b.x() - a.x(), dy = b.y() - a.y();
  const int sx = ex > ix ? 1 : (ex < ix ? -1 : 0), sy = ey > iy ? 1 : (ey < iy ? -1 : 0);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const double tdx = sx != 0 ? 1.0 / std::abs(dx) : kInf;
  const double tdy = sy != 0 ? 1.0 / std::abs(dy) : kInf;
  double tmx = sx > 0 ? (ix + 1 - a.x()) * tdx : (sx < 0 ? (a.x() - ix) * tdx : kInf);
  double tmy = sy > 0 ? (iy + 1 - a.y()) * tdy : (sy < 0 ? (a.y() - iy) * tdy : kInf);
  const int steps = std::abs(ex - ix) + std::abs(ey - iy);
  visit(ix, iy);
  for (int k = 0; k < steps; ++k) {
    // Step along x while x still has steps left and its boundary comes first.
    if (ix != ex && (iy == ey || tmx < tmy)) {
      ix += sx;
      tmx += tdx;
    } else {
      iy += sy;
      tmy += tdy;
    }
    visit(ix, iy);
  }
}

}  // namespace

absl::Status ScanOccupancyOptions::Validate() const {
  if (!std::isfinite(resolution_m) || resolution_m <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: resolution_m must be finite and > 0, got ", resolution_m));
  }
  if (!std::isfinite(hit_log_odds) || hit_log_odds <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: hit_log_odds must be > 0, got ", hit_log_odds));
  }
  if (!std::isfinite(miss_log_odds) || miss_log_odds >= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: miss_log_odds must be < 0, got ", miss_log_odds));
  }
  if (!std::isfinite(min_log_odds) || !std::isfinite(max_log_odds) ||
      !(min_log_odds <= occupied_log_odds && occupied_log_odds < max_log_odds)) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: need min_log_odds ≤ occupied_log_odds < max_log_odds, got ",
                     min_log_odds, ", ", occupied_log_odds, ", ", max_log_odds));
  }
  if (!std::isfinite(max_range_m) || max_range_m < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: max_range_m must be finite and ≥ 0, got ", max_range_m));
  }
  return absl::OkStatus();
}

CellState ScanOccupancyGrid::State(int ix, int iy, const ScanOccupancyOptions& options) const {
  if (ix < 0 || iy < 0 || ix >= width || iy >= height) return CellState::kUnknown;
  const size_t i = static_cast<size_t>(iy) * width + ix;
  if (!observed[i]) return CellState::kUnknown;
  return log_odds[i] > options.occupied_log_odds ? CellState::kOccupied : CellState::kFree;
}

absl::StatusOr<ScanOccupancyGrid> EmptyScanOccupancyGrid(const Eigen::AlignedBox2d& bounds,
                                                         const ScanOccupancyOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (bounds.isEmpty() || !bounds.min().allFinite() || !bounds.max().allFinite()) {
    return absl::InvalidArgumentError("occupancy grid: empty or non-finite bounds");
  }
  const double res = options.resolution_m;
  ScanOccupancyGrid grid;
  grid.resolution_m = res;
  const double ix0 = std::floor(bounds.min().x() / res) - 1;
  const double iy0 = std::floor(bounds.min().y() / res) - 1;
  const double ix1 = std::floor(bounds.max().x() / res) + 1;
  const double iy1 = std::floor(bounds.max().y() / res) + 1;
  const double w = ix1 - ix0 + 1, h = iy1 - iy0 + 1;
  if (w * h > static_cast<double>(std::numeric_limits<int32_t>::max())) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: ", w, "×", h, " cells at ", res, " m is too large"));
  }
  grid.origin_x_m = ix0 * res;
  grid.origin_y_m = iy0 * res;
  grid.width = static_cast<int>(w);
  grid.height = static_cast<int>(h);
  const size_t n = static_cast<size_t>(grid.width) * grid.height;
  grid.log_odds.assign(n, 0.0f);
  grid.observed.assign(n, 0);
  grid.last_scan.assign(n, 0);
  return grid;
}

void ExtendScanBounds(const LineScan2D& scan, const ScanOccupancyOptions& options,
                      Eigen::AlignedBox2d& box) {
  box.extend(scan.origin);
  for (const Eigen::Vector2d& hit : scan.hits) {
    const Eigen::Vector2d d = hit - scan.origin;
    const double r = d.norm();
    box.extend(options.max_range_m > 0 && r > options.max_range_m
                   ? Eigen::Vector2d(scan.origin + d * (options.max_range_m / r))
                   : hit);
  }
}

absl::Status IntegrateLineScan(const LineScan2D& scan, const ScanOccupancyOptions& options,
                               ScanOccupancyGrid& grid) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const double res = grid.resolution_m;
  const Eigen::Vector2d o(grid.origin_x_m, grid.origin_y_m);
  auto inside = [&](const Eigen::Vector2d& c) {  // c in cell units
    return c.allFinite() && c.x() >= 0 && c.y() >= 0 && c.x() < grid.width && c.y() < grid.height;
  };
  const Eigen::Vector2d start = (scan.origin - o) / res;
  if (!inside(start)) {
    return absl::InvalidArgumentError(absl::StrCat("occupancy grid: scan origin (", scan.origin.x(),
                                                   ", ", scan.origin.y(),
                                                   ") is not finite or outside the grid"));
  }
  // Clipped ends first (so a bad return leaves the grid untouched).
  std::vector<Eigen::Vector2d> ends(scan.hits.size());
  std::vector<uint8_t> is_hit(scan.hits.size(), 1);
  for (size_t i = 0; i < scan.hits.size(); ++i) {
    Eigen::Vector2d d = scan.hits[i] - scan.origin;
    const double r = d.norm();
    if (options.max_range_m > 0 && r > options.max_range_m) {
      d *= options.max_range_m / r;
      is_hit[i] = 0;
    }
    ends[i] = start + d / res;
    if (!inside(ends[i])) {
      return absl::InvalidArgumentError(absl::StrCat("occupancy grid: return ", i, " (",
                                                     scan.hits[i].x(), ", ", scan.hits[i].y(),
                                                     ") is not finite or outside the grid"));
    }
  }
  const uint32_t stamp = ++grid.scans;
  auto index = [&](int ix, int iy) { return static_cast<size_t>(iy) * grid.width + ix; };
  auto update = [&](size_t c, float delta) {
    grid.last_scan[c] = stamp;
    grid.observed[c] = 1;
    grid.log_odds[c] =
        std::clamp(grid.log_odds[c] + delta, options.min_log_odds, options.max_log_odds);
  };
  // Hits before misses: a cell this scan hits is not also missed by it (OctoMap's rule).
  for (size_t i = 0; i < ends.size(); ++i) {
    if (!is_hit[i]) continue;
    const size_t c =
        index(static_cast<int>(std::floor(ends[i].x())), static_cast<int>(std::floor(ends[i].y())));
    if (grid.last_scan[c] != stamp) update(c, options.hit_log_odds);
  }
  for (size_t i = 0; i < ends.size(); ++i) {
    const int ex = static_cast<int>(std::floor(ends[i].x()));
    const int ey = static_cast<int>(std::floor(ends[i].y()));
    TraverseCells(start, ends[i], [&](int ix, int iy) {
      // A hit's own cell is the hit; a cut ray's last cell is free space like the rest.
      if (is_hit[i] && ix == ex && iy == ey) return;
      const size_t c = index(ix, iy);
      if (grid.last_scan[c] != stamp) update(c, options.miss_log_odds);
    });
  }
  return absl::OkStatus();
}

absl::StatusOr<ScanOccupancyGrid> BuildScanOccupancyGrid(std::span<const LineScan2D> scans,
                                                         const ScanOccupancyOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (scans.empty()) return absl::InvalidArgumentError("occupancy grid: no scans");
  Eigen::AlignedBox2d box;  // empty
  for (const LineScan2D& scan : scans) {
    if (!scan.origin.allFinite()) {
      return absl::InvalidArgumentError("occupancy grid: a scan origin is not finite");
    }
    for (const Eigen::Vector2d& hit : scan.hits) {
      if (!hit.allFinite())
        return absl::InvalidArgumentError("occupancy grid: a return is not finite");
    }
    ExtendScanBounds(scan, options, box);
  }
  absl::StatusOr<ScanOccupancyGrid> grid = EmptyScanOccupancyGrid(box, options);
  if (!grid.ok()) return grid.status();
  for (const LineScan2D& scan : scans) {
    if (absl::Status s = IntegrateLineScan(scan, options, *grid); !s.ok()) return s;
  }
  return grid;
}

Image<uint8_t> OccupancyGridImage(const ScanOccupancyGrid& grid,
                                  const ScanOccupancyOptions& options) {
  Image<uint8_t> image;
  image.width = grid.width;
  image.height = grid.height;
  image.pixels.assign(static_cast<size_t>(grid.width) * grid.height, kGrayUnknown);
  for (int iy = 0; iy < grid.height; ++iy) {
    for (int ix = 0; ix < grid.width; ++ix) {
      const CellState s = grid.State(ix, iy, options);
      if (s == CellState::kUnknown) continue;
      image.at(grid.height - 1 - iy, ix) = s == CellState::kOccupied ? kGrayOccupied : kGrayFree;
    }
  }
  return image;
}

}  // namespace carvemap
