#include "services/floorplan/samples/grid_visibility.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>

namespace carvemap {
namespace {

// A grid with every cell free; Fill blocks cells [x0, x1) × [y0, y1).
OccupancyGrid2D EmptyGrid(int w, int h, double res = 0.05) {
  OccupancyGrid2D g;
  g.width = w;
  g.height = h;
  g.resolution_m = res;
  g.cells.assign(size_t(w) * h, 0);
  return g;
}
void Fill(OccupancyGrid2D& g, int x0, int y0, int x1, int y1, uint8_t v = 1) {
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) g.cells[size_t(y) * g.width + x] = v;
}
// Box walls (one cell thick) around [x0, x1) × [y0, y1).
void Box(OccupancyGrid2D& g, int x0, int y0, int x1, int y1) {
  Fill(g, x0, y0, x1, y0 + 1);
  Fill(g, x0, y1 - 1, x1, y1);
  Fill(g, x0, y0, x0 + 1, y1);
  Fill(g, x1 - 1, y0, x1, y1);
}
Eigen::Vector2d CellCentre(const OccupancyGrid2D& g, int ix, int iy) {
  return {g.origin_x_m + (ix + 0.5) * g.resolution_m, g.origin_y_m + (iy + 0.5) * g.resolution_m};
}
// One sample per blocked cell with a free 4-neighbour; also records its cell.
WallSampleSet SamplesOf(const OccupancyGrid2D& g, std::vector<Eigen::Vector2i>* cells = nullptr) {
  WallSampleSet set;
  set.spacing_m = g.resolution_m;
  auto free = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < g.width && y < g.height && !g.Blocked(x, y);
  };
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      if (!g.Blocked(x, y)) continue;
      if (!(free(x - 1, y) || free(x + 1, y) || free(x, y - 1) || free(x, y + 1))) continue;
      WallSample s;
      s.position = CellCentre(g, x, y);
      s.ceiling_z = 2.6;
      set.samples.push_back(s);
      if (cells) cells->push_back({x, y});
    }
  return set;
}

TEST(GridVisibilityTest, ValidateNamesTheBadField) {
  OccupancyGrid2D g = EmptyGrid(4, 3);
  EXPECT_TRUE(g.Validate().ok());
  g.cells.pop_back();
  EXPECT_NE(g.Validate().message().find("cells"), std::string::npos) << g.Validate();
  g = EmptyGrid(4, 3);
  g.resolution_m = 0;
  EXPECT_NE(g.Validate().message().find("resolution_m"), std::string::npos);
  g = EmptyGrid(4, 3);
  g.origin_x_m = NAN;
  EXPECT_NE(g.Validate().message().find("origin"), std::string::npos);

  VisibilityOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.angle_step_deg = 0;
  EXPECT_NE(o.Validate().message().find("angle_step_deg"), std::string::npos);
  o = {};
  o.max_range_m = -1;
  EXPECT_NE(o.Validate().message().find("max_range_m"), std::string::npos);
  o = {};
  o.min_pose_spacing_m = NAN;
  EXPECT_NE(o.Validate().message().find("min_pose_spacing_m"), std::string::npos);
  o = {};
  o.match_distance_m = -0.1;
  EXPECT_NE(o.Validate().message().find("match_distance_m"), std::string::npos);

  WallSampleSet set = SamplesOf(EmptyGrid(4, 3));
  set.poses = {{0.1, 0.1}};
  set.path_breaks = {3};
  EXPECT_EQ(AssignVisiblePoses(EmptyGrid(4, 3), {}, set).code(),
            absl::StatusCode::kInvalidArgument);
}

// Two 3 m × 3 m rooms side by side sharing a one-cell wall, no door. A pose in the left room
// sees every inner face sample of the left room and none of the right room's.
TEST(GridVisibilityTest, WallsHideWhatIsBehindThem) {
  OccupancyGrid2D g = EmptyGrid(130, 70);
  Box(g, 2, 2, 63, 63);    // left room: interior cells 3..61
  Box(g, 62, 2, 123, 63);  // right room: shares column 62
  std::vector<Eigen::Vector2i> cells;
  WallSampleSet set = SamplesOf(g, &cells);
  set.poses = {CellCentre(g, 30, 30)};
  // Stale pose lists are replaced.
  for (WallSample& s : set.samples) s.poses = {0};
  ASSERT_TRUE(AssignVisiblePoses(g, {}, set).ok());
  int left_inner = 0, right_inner = 0, left_seen = 0;
  for (size_t i = 0; i < set.samples.size(); ++i) {
    const Eigen::Vector2i c = cells[i];
    const bool in_left_box = c.x() <= 62 && c.y() >= 2 && c.y() <= 62;
    // Faces of the left room: wall cells with a 4-neighbour inside it (corners excluded: a
    // corner cell has no free 4-neighbour inside).
    const bool left_face =
        in_left_box && c.x() >= 2 &&
        ((c.x() == 2 || c.x() == 62) ? (c.y() >= 3 && c.y() <= 61) : (c.y() == 2 || c.y() == 62));
    const bool right_interior_face =
        c.x() >= 62 && c.x() <= 122 && c.y() >= 2 && c.y() <= 62 &&
        ((c.x() == 122 && c.y() > 2 && c.y() < 62) || ((c.y() == 2 || c.y() == 62) && c.x() > 62));
    if (left_face) {
      ++left_inner;
      if (set.samples[i].poses == std::vector<uint32_t>{0}) ++left_seen;
    }
    if (right_interior_face) {
      ++right_inner;
      EXPECT_TRUE(set.samples[i].poses.empty()) << "right-room sample at " << c.transpose();
    }
    // The outside faces of the boxes are never seen either.
    if (c.x() < 2 || c.x() > 122 || c.y() < 2 || c.y() > 62) {
      ADD_FAILURE() << "sample outside the boxes " << c.transpose();
    }
  }
  EXPECT_EQ(left_inner, 4 * 59);
  EXPECT_GT(right_inner, 100);
  // At 0.25° and ≤ 2.2 m every face cell subtends > 1 ray, so all are seen.
  EXPECT_EQ(left_seen, left_inner);
}

TEST(GridVisibilityTest, RangeOutsideAndPoseSpacing) {
  OccupancyGrid2D g = EmptyGrid(200, 40);
  Box(g, 0, 0, 200, 40);  // a 10 m × 2 m corridor
  WallSampleSet set = SamplesOf(g);
  set.poses = {CellCentre(g, 10, 20),    // 0: kept
               CellCentre(g, 12, 20),    // 1: 0.1 m along: skipped
               CellCentre(g, 20, 20),    // 2: 0.5 m since pose 0: kept
               {-5, 1},                  // 3: outside the grid: kept but sees nothing
               CellCentre(g, 190, 20),   // 4: after a break: kept
               CellCentre(g, 191, 20)};  // 5: 0.05 m along: skipped
  set.path_breaks = {4};
  VisibilityOptions o;
  o.max_range_m = 3.0;
  ASSERT_TRUE(AssignVisiblePoses(g, o, set).ok());
  std::vector<int> seen_by(6, 0);
  for (const WallSample& s : set.samples) {
    for (uint32_t p : s.poses) ++seen_by[p];
    // Range: pose 0 at x = 0.525 m sees nothing beyond x = 3.6 m.
    if (s.position.x() > 3.6) {
      EXPECT_TRUE(std::find(s.poses.begin(), s.poses.end(), 0u) == s.poses.end());
    }
    EXPECT_TRUE(std::is_sorted(s.poses.begin(), s.poses.end()));
  }
  EXPECT_GT(seen_by[0], 50);
  EXPECT_EQ(seen_by[1], 0);
  EXPECT_GT(seen_by[2], 50);
  EXPECT_EQ(seen_by[3], 0);
  EXPECT_GT(seen_by[4], 50);
  EXPECT_EQ(seen_by[5], 0);

  // min_pose_spacing 0 keeps every pose.
  o.min_pose_spacing_m = 0;
  ASSERT_TRUE(AssignVisiblePoses(g, o, set).ok());
  int by1 = 0;
  for (const WallSample& s : set.samples) by1 += std::count(s.poses.begin(), s.poses.end(), 1u);
  EXPECT_GT(by1, 50);
}

// A hit point further than match distance from every sample sees nothing: samples of only the
// left wall, pose looking at the right wall too.
TEST(GridVisibilityTest, HitsMatchOnlyNearbySamples) {
  OccupancyGrid2D g = EmptyGrid(40, 40);
  Box(g, 0, 0, 40, 40);
  WallSampleSet set;
  for (int y = 1; y < 39; ++y) {
    WallSample s;
    s.position = CellCentre(g, 0, y);
    s.ceiling_z = 1;
    set.samples.push_back(s);
  }
  // A stray sample in free space, 3 cells from the right wall: never matched.
  WallSample stray;
  stray.position = CellCentre(g, 36, 20);
  stray.ceiling_z = 1;
  set.samples.push_back(stray);
  set.poses = {CellCentre(g, 20, 20)};
  ASSERT_TRUE(AssignVisiblePoses(g, {}, set).ok());
  for (size_t i = 0; i + 1 < set.samples.size(); ++i) EXPECT_EQ(set.samples[i].poses.size(), 1u);
  EXPECT_TRUE(set.samples.back().poses.empty());
}

// Speed on a map of the size of the largest floor map (office_c, 1683×965): a 1700×1000 grid
// of 4 m rooms with doors, ~1000 kept poses walking the corridors.
TEST(GridVisibilityTest, ThousandPosesOnALargeGridIsFast) {
  OccupancyGrid2D g = EmptyGrid(1700, 1000);
  Box(g, 0, 0, 1700, 1000);
  for (int x = 80; x < 1700; x += 80) Fill(g, x, 0, x + 1, 1000);  // 4 m rooms
  for (int y = 80; y < 1000; y += 80) Fill(g, 0, y, 1700, y + 1);
  for (int x = 40; x < 1700; x += 80)  // 0.9 m doors
    for (int y = 80; y < 1000; y += 80) Fill(g, x - 9, y, x + 9, y + 1, 0);
  for (int y = 40; y < 1000; y += 80)
    for (int x = 80; x < 1700; x += 80) Fill(g, x, y - 9, x + 1, y + 9, 0);
  WallSampleSet set = SamplesOf(g);
  // A serpentine walk through room centres, 0.25 m steps.
  for (int row = 0; row < 12 && set.poses.size() < 1000; ++row) {
    const double y = (row * 80 + 40) * 0.05;
    for (int k = 0; k <= 320 && set.poses.size() < 1000; ++k) {
      const double x = (row % 2 == 0) ? 2.0 + k * 0.25 : 82.0 - k * 0.25;
      set.poses.push_back({x, y});
    }
  }
  ASSERT_EQ(set.poses.size(), 1000u);
  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t c0 = std::clock();
  ASSERT_TRUE(AssignVisiblePoses(g, {}, set).ok());
  const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  size_t seen = 0, links = 0;
  for (const WallSample& s : set.samples) {
    seen += !s.poses.empty();
    links += s.poses.size();
  }
  std::printf(
      "1700x1000 grid, %zu samples, 1000 poses (1440 rays each): %.3f s wall, "
      "%.3f s CPU, %zu seen, %zu links\n",
      set.samples.size(), secs, cpu, seen, links);
  EXPECT_GT(seen, set.samples.size() / 3);
  // Target 0.5 s on one core; the bound leaves room for a loaded CI machine.
  EXPECT_LT(secs, 3.0);

  // Deterministic.
  WallSampleSet again = set;
  ASSERT_TRUE(AssignVisiblePoses(g, {}, again).ok());
  for (size_t i = 0; i < set.samples.size(); ++i)
    ASSERT_EQ(set.samples[i].poses, again.samples[i].poses);
}

}  // namespace
}  // namespace carvemap
