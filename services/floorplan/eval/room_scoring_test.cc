#include "services/floorplan/eval/room_scoring.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>

namespace carvemap {
namespace {

LabelImage Labels(int w, int h, int32_t fill = -1) {
  LabelImage l;
  l.width = w;
  l.height = h;
  l.labels.assign(size_t(w) * h, fill);
  return l;
}
void Paint(LabelImage& l, int col0, int row0, int col1, int row1, int32_t v) {
  for (int r = row0; r < row1; ++r)
    for (int c = col0; c < col1; ++c) l.labels[size_t(r) * l.width + c] = v;
}
std::map<int32_t, int> Counts(const LabelImage& l) {
  std::map<int32_t, int> m;
  for (int32_t v : l.labels) ++m[v];
  return m;
}

TEST(RoomScoringTest, TruthAgainstItselfIsPerfect) {
  LabelImage t = Labels(30, 20);
  Paint(t, 0, 0, 10, 20, 0);
  Paint(t, 11, 0, 30, 8, 7);  // labels need not be dense
  Paint(t, 11, 9, 30, 20, 3);
  auto s = ScoreRooms(t, t);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->truth_rooms, 3);
  EXPECT_EQ(s->predicted_rooms, 3);
  EXPECT_EQ(s->matched, 3);
  EXPECT_EQ(s->precision, 1.0);
  EXPECT_EQ(s->recall, 1.0);
  EXPECT_EQ(s->f1, 1.0);
  EXPECT_EQ(s->bormann_recall, 1.0);
  EXPECT_EQ(s->bormann_precision, 1.0);
}

// Truth: A = left half (50 px), B = right half (50 px). Prediction: A split in two, B exact.
// A's best IoU is exactly 0.5, which is not > 0.5: unmatched.
TEST(RoomScoringTest, SplitRoomIsUnmatched) {
  LabelImage t = Labels(10, 10);
  Paint(t, 0, 0, 5, 10, 0);
  Paint(t, 5, 0, 10, 10, 1);
  LabelImage p = Labels(10, 10);
  Paint(p, 0, 0, 5, 5, 10);
  Paint(p, 0, 5, 5, 10, 11);
  Paint(p, 5, 0, 10, 10, 12);
  auto s = ScoreRooms(t, p);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->truth_rooms, 2);
  EXPECT_EQ(s->predicted_rooms, 3);
  EXPECT_EQ(s->matched, 1);
  EXPECT_DOUBLE_EQ(s->precision, 1.0 / 3);
  EXPECT_DOUBLE_EQ(s->recall, 0.5);
  EXPECT_DOUBLE_EQ(s->f1, 0.4);
  EXPECT_DOUBLE_EQ(s->bormann_recall, (25.0 / 50 + 1.0) / 2);
  EXPECT_DOUBLE_EQ(s->bormann_precision, 1.0);
  // Per truth room: A's best is one of its halves (the lower label of the tie), B's is exact.
  ASSERT_EQ(s->per_truth.size(), 2u);
  EXPECT_EQ(s->per_truth[0].label, 0);
  EXPECT_EQ(s->per_truth[0].pixels, 50);
  EXPECT_EQ(s->per_truth[0].best_predicted, 10);
  EXPECT_DOUBLE_EQ(s->per_truth[0].best_iou, 0.5);
  EXPECT_EQ(s->per_truth[0].best_predicted_pixels, 25);
  EXPECT_EQ(s->per_truth[1].best_predicted, 12);
  EXPECT_DOUBLE_EQ(s->per_truth[1].best_iou, 1.0);

  // One more pixel of A in room 10 (26 of 50, IoU 0.52 > 0.5): matched.
  p.labels[5 * 10 + 0] = 10;
  s = ScoreRooms(t, p);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->matched, 2);
  EXPECT_DOUBLE_EQ(s->recall, 1.0);
  EXPECT_DOUBLE_EQ(s->bormann_recall, (26.0 / 50 + 1.0) / 2);
}

// Merged rooms; and predicted pixels outside the truth rooms are outside the scoring domain.
TEST(RoomScoringTest, MergedRoomsAndTheScoringDomain) {
  // Truth: A = cols 0–3 (40 px), wall col 4 (−1), B = cols 5–9 (50 px).
  LabelImage t = Labels(10, 10);
  Paint(t, 0, 0, 4, 10, 0);
  Paint(t, 5, 0, 10, 10, 1);
  // Prediction: one room over everything (merging A, B and the wall), and a room that lies only
  // on the wall's pixels of the top row... painted after, so it owns them.
  LabelImage p = Labels(10, 10, 5);
  p.labels[4] = 6;  // row 0, col 4: a wall pixel
  auto s = ScoreRooms(t, p);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->truth_rooms, 2);
  EXPECT_EQ(s->predicted_rooms, 1);  // room 6 has no pixel in the domain
  // Room 5 in the domain: 90 px. IoU with B = 50/90, with A = 40/90.
  EXPECT_EQ(s->matched, 1);
  EXPECT_DOUBLE_EQ(s->precision, 1.0);
  EXPECT_DOUBLE_EQ(s->recall, 0.5);
  EXPECT_DOUBLE_EQ(s->bormann_recall, 1.0);
  EXPECT_DOUBLE_EQ(s->bormann_precision, 50.0 / 90);
  ASSERT_EQ(s->per_truth.size(), 2u);
  EXPECT_DOUBLE_EQ(s->per_truth[0].best_iou, 40.0 / 90);  // merged: each truth room's best is 5
  EXPECT_DOUBLE_EQ(s->per_truth[1].best_iou, 50.0 / 90);
  EXPECT_EQ(s->per_truth[0].best_predicted, 5);

  // Nothing predicted: all zero, no division by zero.
  s = ScoreRooms(t, Labels(10, 10));
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->predicted_rooms, 0);
  EXPECT_EQ(s->f1, 0);
  EXPECT_EQ(s->bormann_precision, 0);
  EXPECT_EQ(s->bormann_recall, 0);
  ASSERT_EQ(s->per_truth.size(), 2u);
  EXPECT_EQ(s->per_truth[1].best_predicted, -1);
  EXPECT_EQ(s->per_truth[1].best_iou, 0);
}

// A walk through rooms 0 and 7 (lower-left origin at (1, 2), 0.5 m pixels) keeps those two and
// drops room 3; a point on a wall pixel or off the image enters nothing. Scoring then counts
// the entered rooms only.
TEST(RoomScoringTest, KeepEnteredRooms) {
  LabelImage t = Labels(30, 20);
  Paint(t, 0, 0, 10, 20, 0);
  Paint(t, 11, 0, 30, 8, 7);
  Paint(t, 11, 9, 30, 20, 3);
  const double res = 0.5, ox = 1, oy = 2;
  auto at = [&](int row, int col) {  // a point inside pixel (row, col)
    return Eigen::Vector2d(ox + (col + 0.3) * res, oy + (t.height - 1 - row + 0.6) * res);
  };
  const LabelImage kept =
      KeepEnteredRooms(t, {at(5, 2), at(3, 20), at(8, 20), at(5, 10), {-50, 0}}, res, ox, oy);
  std::map<int32_t, int> c = Counts(kept);
  EXPECT_EQ(c[0], 200);
  EXPECT_EQ(c[7], 8 * 19);
  EXPECT_EQ(c.count(3), 0u);
  EXPECT_EQ(c[-1], 600 - 200 - 8 * 19);
  // The same walk with row 15 (room 3) as well keeps all three.
  EXPECT_EQ(Counts(KeepEnteredRooms(t, {at(5, 2), at(3, 20), at(15, 20)}, res, ox, oy)).size(), 4u);
  // Predicting the truth itself, against the entered rooms: 2 of 2, and room 3's prediction
  // lies outside the scoring domain.
  auto s = ScoreRooms(kept, t);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->truth_rooms, 2);
  EXPECT_EQ(s->predicted_rooms, 2);
  EXPECT_EQ(s->f1, 1.0);
}

TEST(RoomScoringTest, SizeMismatchIsAnError) {
  auto s = ScoreRooms(Labels(10, 10), Labels(10, 9));
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("10×9"), std::string::npos) << s.status();
  LabelImage bad = Labels(10, 10);
  bad.labels.pop_back();
  EXPECT_FALSE(ScoreRooms(Labels(10, 10), bad).ok());
}

TEST(RoomScoringTest, LabelsFromSegmentationRule) {
  // 8-connected regions: two blocks touching at a corner are one room; a region of 3 px is
  // ignored with min_pixels 4; 249 is not free.
  Image<uint8_t> im;
  im.width = 8;
  im.height = 5;
  im.pixels.assign(40, 0);
  auto set = [&](int r, int c, uint8_t v = 255) { im.at(r, c) = v; };
  set(0, 0);
  set(0, 1);
  set(1, 0);
  set(1, 1);  // block 1
  set(2, 2);
  set(3, 2);  // touches block 1 diagonally
  set(0, 6);
  set(0, 7);
  set(1, 7);  // 3 px: too small
  set(4, 5);
  set(4, 6);
  set(4, 7);
  set(3, 7);  // 4 px
  set(2, 5, 249);
  const LabelImage l = LabelsFromSegmentation(im, 250, 4);
  ASSERT_EQ(l.width, 8);
  ASSERT_EQ(l.height, 5);
  auto at = [&](int r, int c) { return l.labels[size_t(r) * 8 + c]; };
  EXPECT_EQ(at(0, 0), 0);
  EXPECT_EQ(at(3, 2), 0);
  EXPECT_EQ(at(0, 6), -1);
  EXPECT_EQ(at(1, 7), -1);
  EXPECT_EQ(at(3, 7), 1);  // ordered by first pixel, row-major
  EXPECT_EQ(at(4, 5), 1);
  EXPECT_EQ(at(2, 5), -1);
  EXPECT_EQ(Counts(l), (std::map<int32_t, int>{{-1, 40 - 10}, {0, 6}, {1, 4}}));
}

// SOURCES.md's table of ground-truth room counts, with its own rule.
TEST(RoomScoringTest, RealGroundTruthRoomCounts) {
  const std::string dir = std::string(CARVEMAP_TEST_DATA_DIR) + "/floormaps";
  const std::vector<std::pair<std::string, int>> maps = {
      {"Freiburg52_scan", 10}, {"Freiburg101_scan", 10}, {"lab_intel", 26},
      {"lab_c_scan", 17},      {"lab_d_scan", 15},       {"office_a", 27},
      {"office_b", 30},        {"office_c", 34},         {"office_d", 25}};
  for (const auto& [name, rooms] : maps) {
    auto im = ReadPngGray8(dir + "/" + name + "_gt_segmentation.png");
    ASSERT_TRUE(im.ok()) << im.status();
    const LabelImage l = LabelsFromSegmentation(*im);
    int n = 0;
    for (int32_t v : l.labels) n = std::max(n, v + 1);
    std::printf("%s: %dx%d, %d rooms\n", name.c_str(), l.width, l.height, n);
    EXPECT_EQ(n, rooms) << name;
    auto s = ScoreRooms(l, l);
    ASSERT_TRUE(s.ok());
    EXPECT_EQ(s->matched, rooms) << name;
  }
}

FloorPlan SquarePlan() {
  // [0, 2]² as two triangles split by the diagonal y = x: room 0 below it, room 1 above.
  FloorPlan plan;
  plan.vertices = {{0, 0}, {2, 0}, {2, 2}, {0, 2}};
  plan.triangles = {{0, 1, 2}, {0, 2, 3}};
  plan.triangle_room = {0, 1};
  plan.rooms.resize(2);
  return plan;
}

TEST(RoomScoringTest, RasterizeTwoTriangleSquare) {
  // 0.25 m pixels, exactly representable: 8×8 pixels in the square. Centres on the diagonal (8
  // of them) are on the left end of room 0's spans, so room 0 gets them: 28 + 8 and 28.
  LabelImage l = RasterizeFloorPlan(SquarePlan(), 8, 8, 0.25, 0, 0);
  EXPECT_EQ(Counts(l), (std::map<int32_t, int>{{0, 36}, {1, 28}}));
  // With a margin of one pixel all round, and checking orientation: row 0 is the top.
  l = RasterizeFloorPlan(SquarePlan(), 10, 10, 0.25, -0.25, -0.25);
  EXPECT_EQ(Counts(l), (std::map<int32_t, int>{{-1, 36}, {0, 36}, {1, 28}}));
  EXPECT_EQ(l.labels[1 * 10 + 1], 1);  // centre (0.125, 1.875): above the diagonal
  EXPECT_EQ(l.labels[8 * 10 + 8], 0);  // centre (1.875, 0.125)
  EXPECT_EQ(l.labels[0], -1);
  // A clockwise triangle and out-of-range indices do not break it.
  FloorPlan plan = SquarePlan();
  plan.triangles[0] = {0, 2, 1};
  plan.triangles.push_back({0, 1, 9});
  plan.triangle_room.push_back(5);
  l = RasterizeFloorPlan(plan, 8, 8, 0.25, 0, 0);
  EXPECT_EQ(Counts(l), (std::map<int32_t, int>{{0, 36}, {1, 28}}));
}

// Random triangulated fans against a brute-force point-in-triangle test: pixels whose centre is
// clearly inside a triangle get its room; clearly outside all get −1; none in the union is lost
// on a shared edge. Then the speed on a plan of ~10^5 triangles over an office_c-sized image.
TEST(RoomScoringTest, RasterizeMatchesBruteForceAndIsFast) {
  std::mt19937 rng(301);
  std::uniform_real_distribution<double> u(0, 1);
  FloorPlan plan;
  const Eigen::Vector2d centre(5.13, 4.71);
  const int n = 37;
  plan.vertices.push_back(centre);
  for (int k = 0; k < n; ++k) {
    const double a = 2 * M_PI * (k + 0.3 * u(rng)) / n;
    const double r = 1.5 + 3 * u(rng);
    plan.vertices.push_back(centre + r * Eigen::Vector2d(std::cos(a), std::sin(a)));
  }
  for (int k = 0; k < n; ++k) {
    plan.triangles.push_back({0u, uint32_t(1 + k), uint32_t(1 + (k + 1) % n)});
    plan.triangle_room.push_back(k % 5);
  }
  const int W = 230, H = 210;
  const double res = 0.047, ox = 0.07, oy = -0.11;
  const LabelImage l = RasterizeFloorPlan(plan, W, H, res, ox, oy);
  auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& p) {
    return (b - a).x() * (p - a).y() - (b - a).y() * (p - a).x();
  };
  int inside = 0, checked_out = 0;
  for (int row = 0; row < H; ++row)
    for (int col = 0; col < W; ++col) {
      const Eigen::Vector2d p(ox + (col + 0.5) * res, oy + (H - 1 - row + 0.5) * res);
      int strictly_in = -1;
      bool on_some = false;
      for (size_t t = 0; t < plan.triangles.size(); ++t) {
        const auto& tr = plan.triangles[t];
        const double c0 = cross(plan.vertices[tr[0]], plan.vertices[tr[1]], p);
        const double c1 = cross(plan.vertices[tr[1]], plan.vertices[tr[2]], p);
        const double c2 = cross(plan.vertices[tr[2]], plan.vertices[tr[0]], p);
        const double m = std::min({c0, c1, c2});
        if (m > 1e-9) strictly_in = plan.triangle_room[t];
        if (m >= -1e-9) on_some = true;
      }
      const int32_t got = l.labels[size_t(row) * W + col];
      if (strictly_in >= 0) {
        ++inside;
        ASSERT_EQ(got, strictly_in) << row << "," << col;
      } else if (!on_some) {
        ++checked_out;
        ASSERT_EQ(got, -1) << row << "," << col;
      } else {
        EXPECT_GE(got, 0) << "edge pixel lost at " << row << "," << col;
      }
    }
  EXPECT_GT(inside, 10000);
  EXPECT_GT(checked_out, 10000);

  // ~10^5 triangles: a 0.3 m triangulated lattice over 1683×965 pixels of 5 cm.
  FloorPlan big;
  const int nx = 280, ny = 160;
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) big.vertices.push_back({0.01 + 0.3 * i, 0.02 + 0.3 * j});
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const uint32_t a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
      big.triangles.push_back({a, b, d});
      big.triangles.push_back({a, d, c});
      const int room = (i / 20) + 100 * (j / 20);
      big.triangle_room.push_back(room);
      big.triangle_room.push_back(room);
    }
  const auto t0 = std::chrono::steady_clock::now();
  const LabelImage bl = RasterizeFloorPlan(big, 1683, 965, 0.05, 0, 0);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  int64_t covered = 0;
  for (int32_t v : bl.labels) covered += v >= 0;
  std::printf("rasterised %zu triangles onto 1683x965 in %.3f s, %lld pixels covered\n",
              big.triangles.size(), secs, static_cast<long long>(covered));
  // The lattice covers [0.01, 84.01] × [0.02, 48.02]: every pixel centre of the image
  // (x ≤ 84.125, y ≤ 48.225) inside it: cols with centre in [0.01, 84.01) = 0..1679 (1680),
  // rows with centre in [0.02, 48.02) = 0..959 (960).
  EXPECT_EQ(covered, int64_t(1680) * 960);
  EXPECT_LT(secs, 2.0);
}

}  // namespace
}  // namespace carvemap
