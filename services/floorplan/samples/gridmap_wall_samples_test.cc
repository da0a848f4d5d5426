#include "services/floorplan/samples/gridmap_wall_samples.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <string>

#include "services/building/floormap_building.h"
#include "services/sim/walk_planner.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

constexpr double kRes = 0.05;

// Pixel helpers on an Image (row 0 = top).
void FillPx(Image<uint8_t>& im, int col0, int row0, int col1, int row1, uint8_t v) {
  for (int r = row0; r < row1; ++r)
    for (int c = col0; c < col1; ++c) im.at(r, c) = v;
}
// World point → (row, col) of an H-row image with lower-left origin (docs/DESIGN.md §4).
Eigen::Vector2i PixelOf(const Image<uint8_t>& im, const Eigen::Vector2d& p) {
  const int col = static_cast<int>(std::floor(p.x() / kRes));
  const int iy = static_cast<int>(std::floor(p.y() / kRes));
  return {im.height - 1 - iy, col};
}
Eigen::Vector2d CentreOf(const Image<uint8_t>& im, int row, int col) {
  return {(col + 0.5) * kRes, (im.height - 1 - row + 0.5) * kRes};
}

// Two rooms, all else occupied (0): left room cols [10, 80) × rows [10, 70), right room cols
// [82, 150) × rows [10, 70); the wall between is cols 80–81 (0.1 m), with a 0.9 m door at rows
// [31, 49). Path: left room centre → door → right room centre, every 5 cm.
struct TwoRooms {
  Image<uint8_t> im;
  std::vector<Eigen::Vector2d> path;
  size_t first_right_pose = 0;  // poses from here on are in the right room
  TwoRooms() {
    im.width = 160;
    im.height = 80;
    im.pixels.assign(size_t(im.width) * im.height, 0);
    FillPx(im, 10, 10, 80, 70, 255);
    FillPx(im, 82, 10, 150, 70, 255);
    FillPx(im, 80, 31, 82, 49, 255);
    const Eigen::Vector2d a = CentreOf(im, 40, 45), b = CentreOf(im, 40, 116);
    for (double x = a.x(); x <= b.x() + 1e-9; x += kRes) {
      if (x > 82 * kRes && first_right_pose == 0) first_right_pose = path.size();
      path.push_back({x, a.y()});
    }
  }
  [[nodiscard]] bool Free(int row, int col) const {
    return row >= 0 && col >= 0 && row < im.height && col < im.width && im.at(row, col) >= 250;
  }
};

TEST(GridMapWallSamplesTest, GridFromImageFlipsRows) {
  Image<uint8_t> im;
  im.width = 3;
  im.height = 2;
  im.pixels = {0,   255, 255,   // top row
               255, 255, 249};  // bottom row
  GridMapOptions o;
  o.origin_x_m = 1;
  const OccupancyGrid2D g = GridFromImage(im, o);
  EXPECT_EQ(g.width, 3);
  EXPECT_EQ(g.height, 2);
  EXPECT_EQ(g.origin_x_m, 1);
  EXPECT_TRUE(g.Blocked(0, 1));  // top-left pixel = cell (0, 1)
  EXPECT_TRUE(g.Blocked(2, 0));  // 249 < 250
  EXPECT_FALSE(g.Blocked(0, 0));
  EXPECT_FALSE(g.Blocked(2, 1));
  EXPECT_TRUE(g.Validate().ok());
}

TEST(GridMapWallSamplesTest, ErrorsNameWhatIsWrong) {
  TwoRooms t;
  GridMapOptions o;
  Image<uint8_t> empty;
  auto r = GridMapWallSamples(empty, t.path, o);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("empty map"), std::string::npos) << r.status();
  r = GridMapWallSamples(t.im, {}, o);
  EXPECT_NE(r.status().message().find("empty path"), std::string::npos) << r.status();
  std::vector<Eigen::Vector2d> bad = t.path;
  bad[7] = {-0.5, 1.0};
  r = GridMapWallSamples(t.im, bad, o);
  EXPECT_NE(r.status().message().find("path point 7"), std::string::npos) << r.status();
  bad[7] = {1.0, 4.0};  // y = 4.0 m = the top edge of the 80-row map: outside (half-open)
  r = GridMapWallSamples(t.im, bad, o);
  EXPECT_NE(r.status().message().find("path point 7"), std::string::npos) << r.status();
  GridMapOptions bo;
  bo.ceiling_z = bo.floor_z;
  r = GridMapWallSamples(t.im, t.path, bo);
  EXPECT_NE(r.status().message().find("ceiling_z"), std::string::npos) << r.status();
  bo = {};
  bo.visibility.angle_step_deg = -1;
  r = GridMapWallSamples(t.im, t.path, bo);
  EXPECT_NE(r.status().message().find("angle_step_deg"), std::string::npos) << r.status();
  Image<uint8_t> all_free = t.im;
  std::fill(all_free.pixels.begin(), all_free.pixels.end(), 255);
  r = GridMapWallSamples(all_free, t.path, o);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition) << r.status();
}

TEST(GridMapWallSamplesTest, TwoRoomsWithADoor) {
  TwoRooms t;
  GridMapOptions o;
  o.floor_z = 0.1;
  o.ceiling_z = 2.9;
  auto r = GridMapWallSamples(t.im, t.path, o);
  ASSERT_TRUE(r.ok()) << r.status();
  const WallSampleSet& set = *r;
  ASSERT_TRUE(set.Validate().ok()) << set.Validate();
  EXPECT_EQ(set.spacing_m, kRes);
  EXPECT_EQ(set.poses, t.path);
  EXPECT_TRUE(set.path_breaks.empty());

  // Expected count: room perimeters' face cells (corners excluded: an inner corner cell has no
  // free 4-neighbour) minus the door gap. Left room 70×60: 2·70 + 2·60 = 260 face cells; right
  // 68×60: 256; the door removes 18 cells from each face of the dividing wall (the jamb cells
  // beside it are face cells of the rooms already).
  EXPECT_EQ(set.samples.size(), 260u + 256u - 36u);

  int far_side = 0, facing = 0, facing_seen = 0, axis_normals = 0, jambs = 0, jambs_seen = 0;
  for (const WallSample& s : set.samples) {
    const Eigen::Vector2i px = PixelOf(t.im, s.position);
    const int row = px.x(), col = px.y();
    // Every sample is at the centre of a wall cell next to free space.
    ASSERT_FALSE(t.Free(row, col)) << row << "," << col;
    ASSERT_TRUE((s.position - CentreOf(t.im, row, col)).norm() < 1e-9);
    ASSERT_TRUE(t.Free(row - 1, col) || t.Free(row + 1, col) || t.Free(row, col - 1) ||
                t.Free(row, col + 1));
    EXPECT_EQ(s.floor_z, 0.1);
    EXPECT_EQ(s.ceiling_z, 2.9);

    // Normals point into the room the cell borders: towards the free 4-neighbour(s).
    ASSERT_GT(s.normal.norm(), 0.5) << "no normal at " << row << "," << col;
    Eigen::Vector2d to_free = Eigen::Vector2d::Zero();
    if (t.Free(row - 1, col)) to_free += Eigen::Vector2d(0, 1);
    if (t.Free(row + 1, col)) to_free += Eigen::Vector2d(0, -1);
    if (t.Free(row, col - 1)) to_free += Eigen::Vector2d(-1, 0);
    if (t.Free(row, col + 1)) to_free += Eigen::Vector2d(1, 0);
    EXPECT_GT(s.normal.dot(to_free), 0.5) << row << "," << col << " n=" << s.normal.transpose();
    // Straight walls (3+ cells from a corner or the door): exactly the axis.
    const bool mid_vertical = row >= 13 && row < 67 && (row < 28 || row >= 52);
    const bool mid_horizontal = (col >= 13 && col < 77) || (col >= 85 && col < 147);
    if ((col == 9 || col == 80 || col == 81 || col == 150) && mid_vertical) {
      EXPECT_LT((s.normal - to_free).norm(), 1e-12) << row << "," << col;
      ++axis_normals;
    }
    if ((row == 9 || row == 70) && mid_horizontal) {
      EXPECT_LT((s.normal - to_free).norm(), 1e-12) << row << "," << col;
      ++axis_normals;
    }

    // Line of sight. The dividing wall's left face (col 80) away from the door faces only the
    // left room: no right-room pose may see it; and vice versa for col 81.
    const bool jamb = (col == 80 || col == 81) && (row == 30 || row == 49);
    if (jamb) {
      ++jambs;
      jambs_seen += !s.poses.empty();
      continue;
    }
    if (col == 80 || col == 81) {
      ++far_side;
      for (uint32_t p : s.poses) {
        const bool right_pose = p >= t.first_right_pose;
        EXPECT_EQ(right_pose, col == 81)
            << "pose " << p << " sees the far side of the wall at " << row << "," << col;
      }
    }
    // Every wall face of both rooms faces the path, which stands in the middle of each room.
    ++facing;
    facing_seen += !s.poses.empty();
  }
  EXPECT_EQ(jambs, 4);
  EXPECT_EQ(far_side, 2 * (60 - 18 - 2));
  EXPECT_EQ(axis_normals, 4 * 30 + 2 * (64 + 62));
  EXPECT_EQ(facing_seen, facing);
  std::printf("two rooms: %zu samples, %d/%d faces seen, %d/4 door jambs seen\n",
              set.samples.size(), facing_seen, facing, jambs_seen);
}

// A one-cell wall with free space on both sides has no free side: zero normal.
TEST(GridMapWallSamplesTest, ThinWallSeenFromBothSidesHasNoNormal) {
  Image<uint8_t> im;
  im.width = 40;
  im.height = 40;
  im.pixels.assign(1600, 0);
  FillPx(im, 2, 2, 38, 38, 255);
  FillPx(im, 20, 2, 21, 38, 0);  // col 20, full height: two closed rooms
  const std::vector<Eigen::Vector2d> path = {CentreOf(im, 20, 10), CentreOf(im, 20, 30)};
  GridMapOptions o;
  o.visibility.min_pose_spacing_m = 0;
  auto r = GridMapWallSamples(im, path, o);
  ASSERT_TRUE(r.ok()) << r.status();
  int thin = 0;
  for (const WallSample& s : r->samples) {
    const Eigen::Vector2i px = PixelOf(im, s.position);
    if (px.y() == 20 && px.x() >= 5 && px.x() < 35) {
      ++thin;
      EXPECT_EQ(s.normal.norm(), 0) << px.transpose();
      EXPECT_EQ(s.poses, (std::vector<uint32_t>{0, 1}));  // seen from both sides
    }
  }
  EXPECT_EQ(thin, 30);
}

// Clutter (§3.1.1's height rule has no 2D counterpart, so free-standing pieces smaller than
// clutter_max_extent_m across are furniture): a room 10 m × 6 m (cols [10, 210) × rows [10, 130))
// with a chair (0.3 m square) and a table (1.0 m × 0.6 m) standing free, a free-standing wall
// stub 1.5 m long, and a cabinet against the top wall. The chair and the table give no samples
// but still hide the wall behind them; the stub and the cabinet stay.
TEST(GridMapWallSamplesTest, FreeStandingClutterGivesNoSamplesButStillBlocks) {
  Image<uint8_t> im;
  im.width = 220;
  im.height = 140;
  im.pixels.assign(size_t(im.width) * im.height, 0);
  FillPx(im, 10, 10, 210, 130, 255);
  FillPx(im, 60, 60, 66, 66, 0);     // chair
  FillPx(im, 105, 44, 125, 56, 0);   // table, x ∈ [5.25, 6.25), y ∈ (4.2, 4.8]
  FillPx(im, 40, 100, 70, 102, 0);   // wall stub
  FillPx(im, 150, 10, 170, 20, 0);   // cabinet, touching the wall above
  const Eigen::Vector2d below_table(5.775, 3.0);
  const std::vector<Eigen::Vector2d> path = {
      {1, 1}, {10, 1}, {10, 5.5}, {1, 5.5}, {1, 3}, below_table, {9, 3}};
  GridMapOptions o;
  o.visibility.min_pose_spacing_m = 0;
  auto r = GridMapWallSamples(im, path, o);
  ASSERT_TRUE(r.ok()) << r.status();
  auto in = [](const Eigen::Vector2i& px, int col0, int row0, int col1, int row1) {
    return px.y() >= col0 && px.y() < col1 && px.x() >= row0 && px.x() < row1;
  };
  int chair = 0, table = 0, stub = 0, cabinet = 0, behind_table = 0;
  for (const WallSample& s : r->samples) {
    const Eigen::Vector2i px = PixelOf(im, s.position);
    chair += in(px, 60, 60, 66, 66);
    table += in(px, 105, 44, 125, 56);
    stub += in(px, 40, 100, 70, 102);
    cabinet += in(px, 150, 10, 170, 20);
    if (px.x() == 9 && px.y() == 115) {  // the top wall, straight above the pose below the table
      ++behind_table;
      EXPECT_FALSE(s.poses.empty());  // seen from elsewhere
      EXPECT_TRUE(std::find(s.poses.begin(), s.poses.end(), 5u) == s.poses.end())
          << "seen through the table";
    }
  }
  EXPECT_EQ(chair, 0);
  EXPECT_EQ(table, 0);
  EXPECT_EQ(stub, 2 * 30);  // two cells thick: every cell faces free space
  EXPECT_EQ(cabinet, 2 * 10 + 20 - 2);  // its three faces, the corners at the wall excluded
  EXPECT_EQ(behind_table, 1);

  o.clutter_max_extent_m = 0;  // every occupied cell
  auto all = GridMapWallSamples(im, path, o);
  ASSERT_TRUE(all.ok()) << all.status();
  EXPECT_EQ(all->samples.size(), r->samples.size() + (4 * 6 - 4) + (2 * 20 + 2 * 12 - 4));

  o.clutter_max_extent_m = -1;
  EXPECT_EQ(GridMapWallSamples(im, path, o).status().code(), absl::StatusCode::kInvalidArgument);
}

// The real map Freiburg52_scan (SOURCES.md) with the walk the simulator would take.
TEST(GridMapWallSamplesTest, Freiburg52RealMap) {
  const std::string dir = std::string(CARVEMAP_TEST_DATA_DIR) + "/floormaps";
  auto im = ReadPngGray8(dir + "/Freiburg52_scan.png");
  ASSERT_TRUE(im.ok()) << im.status();
  auto building = MakeFloormapBuilding(FloormapOptionsFor(dir, "Freiburg52_scan"));
  ASSERT_TRUE(building.ok()) << building.status();
  auto walk = PlanWalk(*building, WalkOptions{});
  ASSERT_TRUE(walk.ok()) << walk.status();
  std::vector<Eigen::Vector2d> path;
  for (const TimedPose& tp : walk->path) path.push_back(tp.pose.translation.head<2>());

  GridMapOptions o;
  o.clutter_max_extent_m = 0;  // every wall cell, as counted below (clutter: its own test)
  const auto t0 = std::chrono::steady_clock::now();
  auto r = GridMapWallSamples(*im, path, o);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(r.ok()) << r.status();
  const WallSampleSet& set = *r;
  ASSERT_TRUE(set.Validate().ok());

  // Independent count of wall cells next to free space, and the walked free space: free cells
  // within 20 steps (8-connected, through free cells only, i.e. ≤ 1–1.4 m around walls, never
  // through them) of a path point.
  const int W = im->width, H = im->height;
  auto free = [&](int row, int col) {
    return row >= 0 && col >= 0 && row < H && col < W && im->at(row, col) >= 250;
  };
  std::vector<int> depth(size_t(W) * H, -1);
  std::deque<int> queue;
  for (const Eigen::Vector2d& p : path) {
    const Eigen::Vector2i px = PixelOf(*im, p);
    const int k = px.x() * W + px.y();
    ASSERT_TRUE(free(px.x(), px.y())) << "path point in a wall at " << p.transpose();
    if (depth[k] < 0) {
      depth[k] = 0;
      queue.push_back(k);
    }
  }
  while (!queue.empty()) {
    const int k = queue.front();
    queue.pop_front();
    if (depth[k] == 20) continue;
    for (int dr = -1; dr <= 1; ++dr)
      for (int dc = -1; dc <= 1; ++dc) {
        const int rr = k / W + dr, cc = k % W + dc;
        if (!free(rr, cc) || depth[rr * W + cc] >= 0) continue;
        depth[rr * W + cc] = depth[k] + 1;
        queue.push_back(rr * W + cc);
      }
  }
  auto walked = [&](int row, int col) { return free(row, col) && depth[row * W + col] >= 0; };

  size_t wall_cells = 0;
  for (int row = 0; row < H; ++row)
    for (int col = 0; col < W; ++col)
      wall_cells += !free(row, col) && (free(row - 1, col) || free(row + 1, col) ||
                                        free(row, col - 1) || free(row, col + 1));
  EXPECT_EQ(set.samples.size(), wall_cells);

  size_t adjacent = 0, adjacent_seen = 0, seen = 0, with_normal = 0;
  for (const WallSample& s : set.samples) {
    seen += !s.poses.empty();
    with_normal += s.normal.norm() > 0;
    const Eigen::Vector2i px = PixelOf(*im, s.position);
    const int row = px.x(), col = px.y();
    // On a wall pixel of the map next to free space (catches a flipped row order).
    ASSERT_TRUE(!free(row, col) && (free(row - 1, col) || free(row + 1, col) ||
                                    free(row, col - 1) || free(row, col + 1)))
        << "sample at " << s.position.transpose() << " is not on a wall face pixel";
    if (walked(row - 1, col) || walked(row + 1, col) || walked(row, col - 1) ||
        walked(row, col + 1)) {
      ++adjacent;
      adjacent_seen += !s.poses.empty();
    }
  }
  std::vector<bool> pose_used(path.size(), false);
  for (const WallSample& s : set.samples)
    for (uint32_t p : s.poses) pose_used[p] = true;
  const size_t poses_used = std::count(pose_used.begin(), pose_used.end(), true);
  const double coverage = double(adjacent_seen) / adjacent;
  std::printf(
      "Freiburg52_scan %dx%d: %zu path points (%.0f m), %zu samples, %zu with normal, "
      "%zu seen by %zu poses; %zu next to walked space, %.1f %% of them seen; %.3f s\n",
      W, H, path.size(), walk->length_m, set.samples.size(), with_normal, seen, poses_used,
      adjacent, 100 * coverage, secs);
  // Sane counts: walls are a thin part of the map; most samples face the walk.
  EXPECT_GT(set.samples.size(), 2000u);
  EXPECT_LT(set.samples.size(), size_t(W) * H / 10);
  EXPECT_GT(adjacent, set.samples.size() / 3);
  EXPECT_GE(coverage, 0.90);
  EXPECT_LT(secs, 10.0);
}

}  // namespace
}  // namespace carvemap
