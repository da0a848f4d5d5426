#include "services/building/floormap_building.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <queue>
#include <random>

#include "storage/png_io.h"

namespace carvemap {
namespace {

const std::string kMaps = std::string(CARVEMAP_TEST_DATA_DIR) + "/floormaps";

struct MapCase {
  std::string name;
  int rooms;  // SOURCES.md table
};

// Pixel sizes of the ground-truth rooms, computed here independently of the library: 8-connected
// free (>= 250) regions of at least 400 px, and a few member pixels of each.
struct GtRegion {
  long pixels = 0;
  std::vector<std::pair<int, int>> samples;  // (row, col)
};

std::vector<GtRegion> GtRegions(const Image<uint8_t>& img) {
  const int W = img.width, H = img.height;
  std::vector<int> label(size_t(W) * H, 0);
  std::vector<GtRegion> out;
  std::mt19937 rng(301);
  int next = 0;
  for (int r0 = 0; r0 < H; ++r0) {
    for (int c0 = 0; c0 < W; ++c0) {
      if (img.at(r0, c0) < 250 || label[size_t(r0) * W + c0]) continue;
      ++next;
      std::vector<std::pair<int, int>> members;
      std::vector<std::pair<int, int>> stack = {{r0, c0}};
      label[size_t(r0) * W + c0] = next;
      while (!stack.empty()) {
        const auto [r, c] = stack.back();
        stack.pop_back();
        members.emplace_back(r, c);
        for (int dr = -1; dr <= 1; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            const int rr = r + dr, cc = c + dc;
            if (rr < 0 || cc < 0 || rr >= H || cc >= W || img.at(rr, cc) < 250) continue;
            if (!label[size_t(rr) * W + cc]) {
              label[size_t(rr) * W + cc] = next;
              stack.emplace_back(rr, cc);
            }
          }
        }
      }
      if (members.size() < 400) continue;
      GtRegion g;
      g.pixels = long(members.size());
      std::shuffle(members.begin(), members.end(), rng);
      members.resize(std::min<size_t>(members.size(), 50));
      g.samples = members;
      out.push_back(g);
    }
  }
  return out;
}

class FloormapTest : public ::testing::TestWithParam<MapCase> {};

TEST_P(FloormapTest, RoomsExactAllEnteredAndConnected) {
  const MapCase& mc = GetParam();
  const FloormapOptions opt = FloormapOptionsFor(kMaps, mc.name);
  FloormapReport report;
  absl::StatusOr<Building> b = MakeFloormapBuilding(opt, &report);
  ASSERT_TRUE(b.ok()) << b.status();
  const double res = opt.resolution_m;

  ASSERT_EQ(b->rooms.size(), size_t(mc.rooms));
  // Areas: each room's polygon (minus holes) is exactly its pixels, and sample pixel centres
  // (mapped per docs/DESIGN.md §4) lie inside the room they belong to.
  absl::StatusOr<Image<uint8_t>> gt = ReadPngGray8(opt.rooms_map_path);
  ASSERT_TRUE(gt.ok());
  std::vector<GtRegion> regions = GtRegions(*gt);
  ASSERT_EQ(regions.size(), b->rooms.size());
  std::vector<bool> matched(b->rooms.size(), false);
  std::vector<const GtRegion*> region_of_room(b->rooms.size(), nullptr);
  for (const GtRegion& g : regions) {
    const auto [r, c] = g.samples.front();
    const Eigen::Vector2d p((c + 0.5) * res, (gt->height - 1 - r + 0.5) * res);
    int room = -1;
    for (const RoomTruth& t : b->rooms) {
      if (RoomContains(t, p)) room = t.id;
    }
    ASSERT_GE(room, 0) << mc.name;
    ASSERT_FALSE(matched[room]);
    matched[room] = true;
    region_of_room[room] = &g;
    const RoomTruth& t = b->rooms[room];
    EXPECT_GT(SignedArea(t.polygon), 0);
    for (const auto& h : t.holes) EXPECT_LT(SignedArea(h), 0);
    const double want = g.pixels * res * res;
    EXPECT_NEAR(RoomArea(t), want, 1e-6 * want) << mc.name << " room " << room;
    for (const auto& [sr, sc] : g.samples) {
      EXPECT_TRUE(RoomContains(t, {(sc + 0.5) * res, (gt->height - 1 - sr + 0.5) * res}));
    }
  }

  // Every room entered, unless the map itself walls it in: then no free path of the plain map
  // (zero clearance, 8-connected) leads from the start to any of its pixels.
  absl::StatusOr<Image<uint8_t>> plain = ReadPngGray8(opt.map_path);
  ASSERT_TRUE(plain.ok());
  const int W = plain->width, H = plain->height;
  std::vector<uint8_t> open(size_t(W) * H, 0);
  {
    const int c0 = int(b->visit_points[0].x() / res),
              r0 = H - 1 - int(b->visit_points[0].y() / res);
    std::vector<std::pair<int, int>> stack = {{r0, c0}};
    open[size_t(r0) * W + c0] = 1;
    while (!stack.empty()) {
      const auto [r, c] = stack.back();
      stack.pop_back();
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int rr = r + dr, cc = c + dc;
          if (rr < 0 || cc < 0 || rr >= H || cc >= W || plain->at(rr, cc) < 250) continue;
          if (!open[size_t(rr) * W + cc]) {
            open[size_t(rr) * W + cc] = 1;
            stack.emplace_back(rr, cc);
          }
        }
      }
    }
  }
  for (int room : report.unentered_rooms) {
    EXPECT_FALSE(b->rooms[room].entered);
    std::printf("%s: room %d (%.2f m²) is walled in by the map itself: not entered\n",
                mc.name.c_str(), room, RoomArea(b->rooms[room]));
    for (const auto& [r, c] : region_of_room[room]->samples) {
      EXPECT_FALSE(open[size_t(r) * W + c]) << mc.name << " room " << room << " was reachable";
    }
  }
  EXPECT_LE(report.unentered_rooms.size(), 1u) << mc.name;
  const NavGrid& g = b->nav[0];
  std::vector<uint8_t> seen(g.free.size(), 0);
  std::queue<Eigen::Vector2i> q;
  const Eigen::Vector2i start = g.CellOf(b->visit_points[0]);
  ASSERT_TRUE(g.IsFree(start.x(), start.y()));
  seen[start.y() * g.width + start.x()] = 1;
  q.push(start);
  while (!q.empty()) {
    const Eigen::Vector2i u = q.front();
    q.pop();
    for (const Eigen::Vector2i& d : {Eigen::Vector2i(1, 0), Eigen::Vector2i(-1, 0),
                                     Eigen::Vector2i(0, 1), Eigen::Vector2i(0, -1)}) {
      const Eigen::Vector2i v = u + d;
      if (g.IsFree(v.x(), v.y()) && !seen[v.y() * g.width + v.x()]) {
        seen[v.y() * g.width + v.x()] = 1;
        q.push(v);
      }
    }
  }
  for (size_t i = 0; i < b->rooms.size(); ++i) {
    if (!b->rooms[i].entered) continue;
    const Eigen::Vector2i c = g.CellOf(b->visit_points[i]);
    EXPECT_TRUE(g.IsFree(c.x(), c.y()));
    EXPECT_TRUE(seen[c.y() * g.width + c.x()]) << mc.name << " room " << i;
    EXPECT_TRUE(RoomContains(b->rooms[i], b->visit_points[i]));
  }
  // Doors: each separator line joins two different rooms.
  double wmin = 1e9, wmax = 0;
  for (const DoorTruth& d : b->doors) {
    EXPECT_NE(d.room_a, d.room_b);
    EXPECT_GE(d.room_a, 0);
    EXPECT_LT(d.room_b, int(b->rooms.size()));
    EXPECT_NEAR((d.p1 - d.p0).norm(), d.width, 1e-9);
    wmin = std::min(wmin, d.width), wmax = std::max(wmax, d.width);
  }
  // Not one per room: a separator line touching three rooms gives one door (see the header).
  EXPECT_GE(b->doors.size(), b->rooms.size() / 2) << mc.name;
  std::printf("%s: %zu doors, widths %.2f–%.2f m\n", mc.name.c_str(), b->doors.size(), wmin, wmax);
  size_t tris = StructureMesh(*b).triangles.size();
  std::printf(
      "%s: %zu rooms, %d wall prisms, %d furniture objects, %zu structure triangles, "
      "%zu object triangles, clearance %.3f m\n",
      mc.name.c_str(), b->rooms.size(), report.wall_prisms, report.furniture_objects, tris,
      ObjectsMesh(*b).triangles.size(), report.clearance_used_m);
  EXPECT_LT(report.wall_prisms, 40000);
  EXPECT_GT(report.furniture_objects, 0);
  for (const ObjectTruth& o : b->objects) {
    EXPECT_NEAR(o.Aabb().max().z(), opt.furniture_height_m, 1e-12);
  }
}

INSTANTIATE_TEST_SUITE_P(Maps, FloormapTest,
                         ::testing::Values(MapCase{"Freiburg52_scan", 10},
                                           MapCase{"Freiburg101_scan", 10},
                                           MapCase{"lab_intel", 26}, MapCase{"lab_c_scan", 17},
                                           MapCase{"lab_d_scan", 15}, MapCase{"office_a", 27},
                                           MapCase{"office_b", 30}, MapCase{"office_c", 34},
                                           MapCase{"office_d", 25}),
                         [](const auto& info) { return info.param.name; });

TEST(FloormapErrorsTest, MissingFileIsNamed) {
  FloormapOptions o;
  o.map_path = "/nonexistent/map.png";
  absl::StatusOr<Building> b = MakeFloormapBuilding(o);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("/nonexistent/map.png"), std::string::npos);
  FloormapOptions f = FloormapOptionsFor(kMaps, "office_a");
  f.rooms_map_path = kMaps + "/lab_intel_gt_segmentation.png";  // different size
  b = MakeFloormapBuilding(f);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("lab_intel_gt_segmentation.png"), std::string::npos);
  o.map_path = "";
  EXPECT_EQ(MakeFloormapBuilding(o).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(FloormapNoGtTest, RoomsFromTheMapItself) {
  FloormapOptions o;
  o.map_path = kMaps + "/office_d.png";
  absl::StatusOr<Building> b = MakeFloormapBuilding(o);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_GE(b->rooms.size(), 1u);
  EXPECT_TRUE(b->objects.empty());
}

}  // namespace
}  // namespace carvemap
