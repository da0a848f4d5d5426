#include "services/floorplan/samples/scan_occupancy_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace carvemap {
namespace {

constexpr double kRes = 0.05;

// A closed rectangular room [x0, x1] × [y0, y1] (walls of no thickness, at cell centres so no
// return falls on a cell border) scanned by a 360° line scanner at `step_deg` from `poses`:
// each ray ends where it leaves the rectangle.
struct RectRoom {
  double x0 = 1.025, y0 = 1.025, x1 = 7.025, y1 = 5.025;
  std::vector<LineScan2D> Scan(const std::vector<Eigen::Vector2d>& poses, double step_deg) const {
    std::vector<LineScan2D> scans;
    for (const Eigen::Vector2d& p : poses) {
      LineScan2D s;
      s.origin = p;
      for (double a = 0; a < 360; a += step_deg) {
        const Eigen::Vector2d d(std::cos(a * M_PI / 180), std::sin(a * M_PI / 180));
        double t = INFINITY;
        if (d.x() > 1e-12) t = std::min(t, (x1 - p.x()) / d.x());
        if (d.x() < -1e-12) t = std::min(t, (x0 - p.x()) / d.x());
        if (d.y() > 1e-12) t = std::min(t, (y1 - p.y()) / d.y());
        if (d.y() < -1e-12) t = std::min(t, (y0 - p.y()) / d.y());
        s.hits.push_back(p + t * d);
      }
      scans.push_back(std::move(s));
    }
    return scans;
  }
};

int CellOf(double v, double origin) { return static_cast<int>(std::floor((v - origin) / kRes)); }

TEST(ScanOccupancyGridTest, RectangularRoomWallsOccupiedInteriorFreeOutsideUnknown) {
  const RectRoom room;
  const std::vector<LineScan2D> scans =
      room.Scan({{2.5, 2.0}, {4.0, 3.0}, {5.5, 4.2}, {3.0, 4.5}}, 0.25);
  const ScanOccupancyOptions options;
  absl::StatusOr<ScanOccupancyGrid> grid = BuildScanOccupancyGrid(scans, options);
  ASSERT_TRUE(grid.ok()) << grid.status();
  // The grid covers the room with one cell to spare, origin on the resolution's lattice.
  EXPECT_NEAR(grid->origin_x_m, 0.95, 1e-9);
  EXPECT_NEAR(grid->origin_y_m, 0.95, 1e-9);
  const int wx0 = CellOf(room.x0, grid->origin_x_m), wx1 = CellOf(room.x1, grid->origin_x_m);
  const int wy0 = CellOf(room.y0, grid->origin_y_m), wy1 = CellOf(room.y1, grid->origin_y_m);
  ASSERT_EQ(wx0, 1);
  ASSERT_EQ(wy0, 1);
  int occupied = 0, free = 0, unknown = 0;
  for (int iy = 0; iy < grid->height; ++iy) {
    for (int ix = 0; ix < grid->width; ++ix) {
      const CellState s = grid->State(ix, iy, options);
      const bool outside = ix < wx0 || ix > wx1 || iy < wy0 || iy > wy1;
      const bool wall = !outside && (ix == wx0 || ix == wx1 || iy == wy0 || iy == wy1);
      if (outside) {
        EXPECT_EQ(s, CellState::kUnknown) << ix << "," << iy;
        unknown += s == CellState::kUnknown;
      } else if (wall) {
        EXPECT_EQ(s, CellState::kOccupied) << ix << "," << iy;
        occupied += s == CellState::kOccupied;
      } else {
        EXPECT_EQ(s, CellState::kFree) << ix << "," << iy;
        free += s == CellState::kFree;
      }
    }
  }
  EXPECT_EQ(occupied, 2 * (wx1 - wx0 + 1) + 2 * (wy1 - wy0 - 1));
  EXPECT_EQ(free, (wx1 - wx0 - 1) * (wy1 - wy0 - 1));
  EXPECT_GT(unknown, 0);
  // Walls seen from four poses are at least four hits up, clamped at 3.5.
  const size_t corner = static_cast<size_t>(wy0) * grid->width + (wx0 + wx1) / 2;
  EXPECT_GE(grid->log_odds[corner], 4 * options.hit_log_odds - 1e-5);

  // The image: map_server's gray values, row 0 at the top.
  const Image<uint8_t> image = OccupancyGridImage(*grid, options);
  ASSERT_EQ(image.width, grid->width);
  ASSERT_EQ(image.height, grid->height);
  EXPECT_EQ(image.at(grid->height - 1 - wy0, (wx0 + wx1) / 2), kGrayOccupied);
  EXPECT_EQ(image.at(grid->height - 1 - (wy0 + wy1) / 2, (wx0 + wx1) / 2), kGrayFree);
  EXPECT_EQ(image.at(0, 0), kGrayUnknown);
}

// One scan hits a cell (a person standing there); later scans see through it: its log-odds is
// the hit plus the misses, and three misses (3 × −0.4) outweigh one hit (0.85).
TEST(ScanOccupancyGridTest, TransientObstacleFadesWithMisses) {
  const ScanOccupancyOptions options;
  absl::StatusOr<ScanOccupancyGrid> grid = EmptyScanOccupancyGrid(
      Eigen::AlignedBox2d(Eigen::Vector2d(0, 0), Eigen::Vector2d(5, 1)), options);
  ASSERT_TRUE(grid.ok()) << grid.status();
  const Eigen::Vector2d origin(0.525, 0.525), person(2.025, 0.525), wall(4.025, 0.525);
  const int px = CellOf(person.x(), grid->origin_x_m), py = CellOf(person.y(), grid->origin_y_m);
  ASSERT_TRUE(IntegrateLineScan({origin, {person}}, options, *grid).ok());
  EXPECT_EQ(grid->State(px, py, options), CellState::kOccupied);
  for (int k = 0; k < 2; ++k) ASSERT_TRUE(IntegrateLineScan({origin, {wall}}, options, *grid).ok());
  EXPECT_EQ(grid->State(px, py, options), CellState::kOccupied);  // 0.85 − 0.8 > 0
  ASSERT_TRUE(IntegrateLineScan({origin, {wall}}, options, *grid).ok());
  EXPECT_EQ(grid->State(px, py, options), CellState::kFree);  // 0.85 − 1.2 < 0
  EXPECT_NEAR(grid->log_odds[static_cast<size_t>(py) * grid->width + px], 0.85 - 1.2, 1e-5);
  // Misses clamp at −2: many more scans leave the cell at the floor.
  for (int k = 0; k < 10; ++k)
    ASSERT_TRUE(IntegrateLineScan({origin, {wall}}, options, *grid).ok());
  EXPECT_FLOAT_EQ(grid->log_odds[static_cast<size_t>(py) * grid->width + px], -2.0f);
}

// Within one scan a cell is updated once, and a hit wins over a neighbouring ray crossing it:
// a ray grazing past the return of another ray of the same scan does not erase it.
TEST(ScanOccupancyGridTest, OneUpdatePerCellPerScanHitWins) {
  const ScanOccupancyOptions options;
  absl::StatusOr<ScanOccupancyGrid> grid = EmptyScanOccupancyGrid(
      Eigen::AlignedBox2d(Eigen::Vector2d(0, 0), Eigen::Vector2d(5, 1)), options);
  ASSERT_TRUE(grid.ok()) << grid.status();
  const Eigen::Vector2d origin(0.525, 0.525);
  // Ray 1 ends at x = 2.025; ray 2 passes through the same cell on its way to x = 4.025; ray 3
  // repeats ray 2 (its cells must still get one miss only).
  LineScan2D scan{origin, {{2.025, 0.525}, {4.025, 0.53}, {4.025, 0.52}}};
  ASSERT_TRUE(IntegrateLineScan(scan, options, *grid).ok());
  auto at = [&](double x, double y) {
    return grid->log_odds[static_cast<size_t>(CellOf(y, grid->origin_y_m)) * grid->width +
                          CellOf(x, grid->origin_x_m)];
  };
  EXPECT_FLOAT_EQ(at(2.025, 0.525), 0.85f);
  EXPECT_FLOAT_EQ(at(1.025, 0.525), -0.4f);
  EXPECT_FLOAT_EQ(at(3.025, 0.525), -0.4f);
  EXPECT_FLOAT_EQ(at(4.025, 0.525), 0.85f);
  EXPECT_EQ(grid->scans, 1u);
}

// Returns beyond max_range_m carve free space up to the range and mark no hit; the bounds stop
// there too.
TEST(ScanOccupancyGridTest, MaxRangeCutsLongReturns) {
  ScanOccupancyOptions options;
  options.max_range_m = 2.0;
  const std::vector<LineScan2D> scans = {{{0.525, 0.525}, {{10.025, 0.525}, {1.525, 0.525}}}};
  absl::StatusOr<ScanOccupancyGrid> grid = BuildScanOccupancyGrid(scans, options);
  ASSERT_TRUE(grid.ok()) << grid.status();
  EXPECT_LT(grid->origin_x_m + grid->width * kRes, 2.525 + 3 * kRes);  // not out to x = 10
  const int iy = CellOf(0.525, grid->origin_y_m);
  EXPECT_EQ(grid->State(CellOf(1.525, grid->origin_x_m), iy, options), CellState::kOccupied);
  // The long ray: free out to 2 m (x = 2.525) and nothing marked occupied at its cut end.
  EXPECT_EQ(grid->State(CellOf(2.4, grid->origin_x_m), iy, options), CellState::kFree);
  EXPECT_EQ(grid->State(CellOf(2.51, grid->origin_x_m), iy, options), CellState::kFree);
  EXPECT_EQ(grid->State(CellOf(2.6, grid->origin_x_m), iy, options), CellState::kUnknown);
}

// Diagonal rays visit a 4-connected chain of cells from the origin's cell to the return's.
TEST(ScanOccupancyGridTest, DiagonalRaysCarveConnectedChains) {
  const ScanOccupancyOptions options;
  const Eigen::Vector2d origin(0.51, 0.52);
  LineScan2D scan{origin, {}};
  for (int k = 0; k < 16; ++k) {
    const double a = k * 2 * M_PI / 16 + 0.1;
    scan.hits.push_back(origin + 3.0 * Eigen::Vector2d(std::cos(a), std::sin(a)));
  }
  absl::StatusOr<ScanOccupancyGrid> grid = BuildScanOccupancyGrid({&scan, 1}, options);
  ASSERT_TRUE(grid.ok()) << grid.status();
  for (const Eigen::Vector2d& hit : scan.hits) {
    const int hx = CellOf(hit.x(), grid->origin_x_m), hy = CellOf(hit.y(), grid->origin_y_m);
    EXPECT_EQ(grid->State(hx, hy, options), CellState::kOccupied);
    // Every cell centre within 0.02 m of the segment (well inside the traversed cells) is
    // observed, the hit's cell excepted free.
    const Eigen::Vector2d d = (hit - origin).normalized();
    for (double t = 0; t < (hit - origin).norm() - kRes; t += 0.01) {
      const Eigen::Vector2d p = origin + t * d;
      const int ix = CellOf(p.x(), grid->origin_x_m), iy = CellOf(p.y(), grid->origin_y_m);
      if (ix == hx && iy == hy) continue;
      EXPECT_NE(grid->State(ix, iy, options), CellState::kUnknown) << t;
    }
  }
}

TEST(ScanOccupancyGridTest, Errors) {
  ScanOccupancyOptions bad;
  bad.resolution_m = 0;
  EXPECT_EQ(BuildScanOccupancyGrid({}, ScanOccupancyOptions{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  const std::vector<LineScan2D> scans = {{{0, 0}, {{1, 0}}}};
  EXPECT_EQ(BuildScanOccupancyGrid(scans, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = {};
  bad.miss_log_odds = 0.1f;
  EXPECT_EQ(BuildScanOccupancyGrid(scans, bad).status().code(), absl::StatusCode::kInvalidArgument);
  const std::vector<LineScan2D> nan = {{{0, 0}, {{NAN, 0}}}};
  EXPECT_EQ(BuildScanOccupancyGrid(nan, {}).status().code(), absl::StatusCode::kInvalidArgument);
  absl::StatusOr<ScanOccupancyGrid> grid = BuildScanOccupancyGrid(scans, {});
  ASSERT_TRUE(grid.ok());
  const std::vector<float> before = grid->log_odds;
  // A return outside the grid is refused and leaves the grid as it was.
  absl::Status s = IntegrateLineScan({{0, 0}, {{0.5, 0}, {50, 0}}}, {}, *grid);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("return 1"), std::string::npos) << s;
  EXPECT_EQ(grid->log_odds, before);
  EXPECT_EQ(IntegrateLineScan({{-9, 0}, {}}, {}, *grid).code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap
