#include "services/building/building_presets.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <queue>
#include <random>
#include <set>

namespace carvemap {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// Entry distance of a ray into a convex prism (slab clipping against its side planes and
// its z range); +inf when it misses. Our own, independent of the walker's ray caster.
double RayPrism(const Vector3d& o, const Vector3d& d, const Prism& p) {
  double t0 = 0, t1 = std::numeric_limits<double>::infinity();
  const auto clip = [&](double num, double den) {  // keep t with num + den·t <= 0
    if (std::abs(den) < 1e-15) return num <= 0;
    const double t = -num / den;
    if (den > 0) {
      t1 = std::min(t1, t);
    } else {
      t0 = std::max(t0, t);
    }
    return t0 <= t1;
  };
  if (!clip(p.z0 - o.z(), -d.z()) || !clip(o.z() - p.z1, d.z())) return INFINITY;
  const size_t n = p.footprint.size();
  for (size_t i = 0; i < n; ++i) {
    const Vector2d a = p.footprint[i], b = p.footprint[(i + 1) % n];
    const Vector2d out(b.y() - a.y(), a.x() - b.x());  // outward for CCW
    if (!clip(out.dot(o.head<2>() - a), out.dot(d.head<2>()))) return INFINITY;
  }
  return t0;
}

double CastRay(const Building& b, const Vector3d& o, const Vector3d& d) {
  double best = INFINITY;
  for (const Prism& p : b.structure) best = std::min(best, RayPrism(o, d, p));
  for (const ObjectTruth& ob : b.objects) {
    for (const Prism& p : ob.parts) best = std::min(best, RayPrism(o, d, p));
  }
  return best;
}

Building Make(const std::string& name, uint64_t seed = 1) {
  absl::StatusOr<Building> b = MakePresetBuilding(name, seed);
  EXPECT_TRUE(b.ok()) << b.status();
  return b.ok() ? *std::move(b) : Building{};
}

Eigen::AlignedBox2d LevelExtent(const Building& b, int level) {
  Eigen::AlignedBox2d box;
  const double z = b.levels[level].floor_z;
  for (const Prism& p : b.structure) {
    if (p.z0 < z + 1.0 && p.z1 > z + 0.5) {
      for (const auto& v : p.footprint) box.extend(v);
    }
  }
  return box;
}

// BFS over the nav grids from rooms[0]'s visit point, crossing levels at stair landings.
std::vector<std::vector<uint8_t>> Reachable(const Building& b) {
  std::vector<std::vector<uint8_t>> seen;
  for (const NavGrid& g : b.nav) seen.emplace_back(g.free.size(), 0);
  const auto flood = [&](int level, const Vector2d& p) {
    const NavGrid& g = b.nav[level];
    const Eigen::Vector2i c = g.CellOf(p);
    if (!g.IsFree(c.x(), c.y()) || seen[level][c.y() * g.width + c.x()]) return;
    std::queue<Eigen::Vector2i> q;
    q.push(c);
    seen[level][c.y() * g.width + c.x()] = 1;
    while (!q.empty()) {
      const Eigen::Vector2i u = q.front();
      q.pop();
      for (const Eigen::Vector2i& dv : {Eigen::Vector2i(1, 0), Eigen::Vector2i(-1, 0),
                                        Eigen::Vector2i(0, 1), Eigen::Vector2i(0, -1)}) {
        const Eigen::Vector2i v = u + dv;
        if (g.IsFree(v.x(), v.y()) && !seen[level][v.y() * g.width + v.x()]) {
          seen[level][v.y() * g.width + v.x()] = 1;
          q.push(v);
        }
      }
    }
  };
  flood(b.rooms[0].level, b.visit_points[0]);
  for (int pass = 0; pass < 2; ++pass) {
    for (const StairTruth& s : b.stairs) {
      flood(s.to_level, s.centerline.back().head<2>());
      flood(s.from_level, s.centerline.front().head<2>());
    }
  }
  return seen;
}

class PresetTest : public ::testing::TestWithParam<std::string> {};

TEST_P(PresetTest, RoomsAreValidAndDisjoint) {
  const Building b = Make(GetParam());
  ASSERT_EQ(b.visit_points.size(), b.rooms.size());
  ASSERT_EQ(b.nav.size(), b.levels.size());
  for (const RoomTruth& r : b.rooms) {
    EXPECT_GT(SignedArea(r.polygon), 0.5) << r.id;  // CCW, not degenerate
    for (const auto& h : r.holes) EXPECT_LT(SignedArea(h), 0) << r.id;
    EXPECT_GT(r.ceiling_z - r.floor_z, 2.4);
    EXPECT_LE(r.ceiling_z, b.levels[r.level].ceiling_z + 1e-9);
    EXPECT_NEAR(r.floor_z, b.levels[r.level].floor_z, 1e-9);
    const Eigen::AlignedBox2d ext = LevelExtent(b, r.level);
    for (const auto& v : r.polygon) EXPECT_TRUE(ext.contains(v)) << r.id;
  }
  for (size_t level = 0; level < b.levels.size(); ++level) {
    const Eigen::AlignedBox2d ext = LevelExtent(b, int(level));
    for (double x = ext.min().x(); x < ext.max().x(); x += 0.07) {
      for (double y = ext.min().y(); y < ext.max().y(); y += 0.07) {
        int inside = 0;
        for (const RoomTruth& r : b.rooms)
          inside += r.level == int(level) && RoomContains(r, {x, y});
        ASSERT_LE(inside, 1) << x << "," << y;
      }
    }
  }
}

TEST_P(PresetTest, VisitPointsWalkableInsideAndConnected) {
  const Building b = Make(GetParam());
  const auto seen = Reachable(b);
  for (size_t i = 0; i < b.rooms.size(); ++i) {
    const RoomTruth& r = b.rooms[i];
    if (!r.entered) {
      EXPECT_TRUE(std::isnan(b.visit_points[i].x()));
      continue;
    }
    const Vector2d p = b.visit_points[i];
    const NavGrid& g = b.nav[r.level];
    const Eigen::Vector2i c = g.CellOf(p);
    EXPECT_TRUE(g.IsFree(c.x(), c.y())) << i;
    EXPECT_TRUE(RoomContains(r, p)) << i;
    EXPECT_TRUE(seen[r.level][c.y() * g.width + c.x()]) << "room " << i << " unreachable";
  }
}

TEST_P(PresetTest, FurnitureEverywhereAndClearOfWalls) {
  const Building b = Make(GetParam());
  std::set<std::string> kinds;
  for (const ObjectTruth& o : b.objects) kinds.insert(o.kind);
  for (const char* k : {"desk", "chair", "shelf", "cabinet", "table", "ceiling_light"}) {
    EXPECT_TRUE(kinds.count(k)) << k;
  }
  for (const RoomTruth& r : b.rooms) {
    int n = 0;
    for (const ObjectTruth& o : b.objects) {
      n += o.level == r.level && RoomContains(r, o.Aabb().center().head<2>());
    }
    EXPECT_GT(n, 0) << "room " << r.id << " has no furniture";
  }
  // No furniture part inside a solid of the building (bounding boxes, with a 1 mm margin;
  // round and curved solids are tested by their boxes too, which is stricter).
  for (const ObjectTruth& o : b.objects) {
    if (o.kind == "chair") {
      EXPECT_EQ(o.parts.size(), 6u);  // seat, 4 legs, back
    }
    for (const Prism& part : o.parts) {
      Eigen::AlignedBox3d pb;
      for (const auto& v : part.footprint) {
        pb.extend(Vector3d(v.x(), v.y(), part.z0)), pb.extend(Vector3d(v.x(), v.y(), part.z1));
      }
      for (const Prism& s : b.structure) {
        Eigen::AlignedBox3d sb;
        for (const auto& v : s.footprint) {
          sb.extend(Vector3d(v.x(), v.y(), s.z0)), sb.extend(Vector3d(v.x(), v.y(), s.z1));
        }
        sb.min().array() += 1e-3;
        sb.max().array() -= 1e-3;
        EXPECT_FALSE(pb.intersects(sb)) << o.kind << " " << o.id << " hits the structure";
      }
    }
  }
}

// The building is closed except for its windows: random rays from every visit point either hit
// a solid or leave the level's extent between sill (0.9 m) and head (2.1 m) height.
TEST_P(PresetTest, RaysEscapeOnlyThroughWindows) {
  const Building b = Make(GetParam());
  // Origins: every visit point and every third point of the stairs' centre lines, 1.5 m up.
  std::vector<Vector3d> origins;
  for (size_t i = 0; i < b.rooms.size(); ++i) {
    if (!b.rooms[i].entered) continue;
    origins.emplace_back(b.visit_points[i].x(), b.visit_points[i].y(),
                         b.levels[b.rooms[i].level].floor_z + 1.5);
  }
  for (const StairTruth& s : b.stairs) {
    for (size_t k = 0; k < s.centerline.size(); k += 3) {
      origins.push_back(s.centerline[k] + Vector3d(0, 0, 1.5));
    }
  }
  Eigen::AlignedBox2d ext;
  for (size_t level = 0; level < b.levels.size(); ++level) ext.extend(LevelExtent(b, level));
  std::mt19937 rng(301);
  std::normal_distribution<double> n01;
  int escaped = 0;
  for (const Vector3d& o : origins) {
    for (int k = 0; k < 300; ++k) {
      const Vector3d d = Vector3d(n01(rng), n01(rng), n01(rng)).normalized();
      if (CastRay(b, o, d) < INFINITY) continue;
      ++escaped;
      // Where the ray leaves the building's 2D extent: inside some level's window band.
      double t_exit = INFINITY;
      for (int a = 0; a < 2; ++a) {
        if (d[a] > 0) t_exit = std::min(t_exit, (ext.max()[a] - o[a]) / d[a]);
        if (d[a] < 0) t_exit = std::min(t_exit, (ext.min()[a] - o[a]) / d[a]);
      }
      const double z = o.z() + t_exit * d.z();
      bool in_band = false;
      for (const LevelTruth& l : b.levels) {
        // 1 cm slack: the curved wall's ends reach ~1 cm past the straight walls' outer faces.
        in_band |= z >= l.floor_z + 0.9 - 0.01 && z <= l.floor_z + 2.1 + 0.01;
      }
      EXPECT_TRUE(in_band) << "from " << o.transpose() << " along " << d.transpose();
    }
  }
  std::printf("%s: %d rays escaped through windows\n", GetParam().c_str(), escaped);
}

TEST_P(PresetTest, SameLayoutForEverySeed) {
  const Building a = Make(GetParam(), 1), b = Make(GetParam(), 99);
  EXPECT_EQ(a.structure.size(), b.structure.size());
  EXPECT_EQ(a.rooms.size(), b.rooms.size());
  EXPECT_EQ(a.objects.size(), b.objects.size());
  std::printf("%s: %zu rooms, %zu doors, %zu objects, %zu structure prisms, %zu + %zu triangles\n",
              GetParam().c_str(), a.rooms.size(), a.doors.size(), a.objects.size(),
              a.structure.size(), StructureMesh(a).triangles.size(),
              ObjectsMesh(a).triangles.size());
}

INSTANTIATE_TEST_SUITE_P(All, PresetTest,
                         ::testing::Values("room", "office", "office2", "office4"));

TEST(PresetsTest, UnknownNameIsNotFound) {
  EXPECT_EQ(MakePresetBuilding("castle", 1).status().code(), absl::StatusCode::kNotFound);
}

TEST(PresetsTest, OfficeHasItsFeatures) {
  const Building b = Make("office");
  EXPECT_EQ(b.levels.size(), 1u);
  EXPECT_GE(b.rooms.size(), 10u);
  // Doors: widths 0.8–1.8 m, several different.
  std::set<double> widths;
  for (const DoorTruth& d : b.doors) {
    EXPECT_GE(d.width, 0.8);
    EXPECT_LE(d.width, 1.8);
    EXPECT_NEAR((d.p1 - d.p0).norm(), d.width, 1e-9);
    widths.insert(d.width);
  }
  EXPECT_GE(widths.size(), 4u);
  // Exactly one room never entered; its door is open and its cells are not walkable.
  int unentered = 0;
  for (const RoomTruth& r : b.rooms) {
    if (r.entered) continue;
    ++unentered;
    bool has_door = false;
    for (const DoorTruth& d : b.doors) has_door |= d.room_a == r.id || d.room_b == r.id;
    EXPECT_TRUE(has_door);
    const NavGrid& g = b.nav[r.level];
    for (int iy = 0; iy < g.height; ++iy) {
      for (int ix = 0; ix < g.width; ++ix) {
        if (RoomContains(r, g.CellCenter(ix, iy))) {
          EXPECT_FALSE(g.IsFree(ix, iy));
        }
      }
    }
  }
  EXPECT_EQ(unentered, 1);
  EXPECT_TRUE(b.rooms[0].entered);
  // Columns: holes in a room, each backed by a solid.
  int holes = 0;
  for (const RoomTruth& r : b.rooms) holes += int(r.holes.size());
  EXPECT_GE(holes, 2);
  // A curved wall: many short wall prisms whose faces are not axis-aligned, all at the same
  // distance from one centre.
  std::vector<Vector2d> arc_mids;
  for (const Prism& p : b.structure) {
    if (p.footprint.size() != 4 || p.z1 - p.z0 < 2.0) continue;
    const Vector2d e = p.footprint[1] - p.footprint[0];
    if (std::abs(e.x()) > 1e-6 && std::abs(e.y()) > 1e-6) {
      arc_mids.push_back(0.25 *
                         (p.footprint[0] + p.footprint[1] + p.footprint[2] + p.footprint[3]));
    }
  }
  ASSERT_GE(arc_mids.size(), 16u);
  // Centre from three points on the arc.
  const Vector2d a = arc_mids.front(), c = arc_mids[arc_mids.size() / 2], d = arc_mids.back();
  Eigen::Matrix2d m;
  m << 2 * (c - a).transpose(), 2 * (d - a).transpose();
  const Vector2d centre =
      m.inverse() * Vector2d(c.squaredNorm() - a.squaredNorm(), d.squaredNorm() - a.squaredNorm());
  for (const Vector2d& p : arc_mids) EXPECT_NEAR((p - centre).norm(), (a - centre).norm(), 0.01);
  // Several ceiling heights.
  std::set<double> ceilings;
  for (const RoomTruth& r : b.rooms) ceilings.insert(r.ceiling_z);
  EXPECT_GE(ceilings.size(), 3u);
}

TEST(PresetsTest, OfficeWindowLetsRaysOut) {
  const Building b = Make("office");
  // The window in the south wall of rooms[1] (x 1.4–2.6, sill 0.9 m, head 2.1 m).
  EXPECT_EQ(CastRay(b, {2.0, 2.5, 1.5}, {0, -1, 0}), INFINITY);
  EXPECT_LT(CastRay(b, {2.0, 2.5, 0.5}, {0, -1, 0}), 3.0);  // below the sill
  EXPECT_LT(CastRay(b, {2.0, 2.5, 2.3}, {0, -1, 0}), 3.0);  // above the head
  EXPECT_LT(CastRay(b, {3.3, 2.5, 1.5}, {0, -1, 0}), 3.0);  // beside it
  // Slanted through the window: still escapes.
  EXPECT_EQ(CastRay(b, {2.0, 2.5, 1.5}, Vector3d(0.1, -1, 0.1).normalized()), INFINITY);
  // Everywhere else the building is closed: rays from the hallway hit something.
  for (int k = 0; k < 64; ++k) {
    const double a = 2 * M_PI * k / 64;
    EXPECT_LT(CastRay(b, {15.0, 6.7, 1.5}, {std::cos(a), std::sin(a), 0.3}), 60.0) << k;
  }
}

TEST(PresetsTest, Office2HasTwoLevelsAndStairs) {
  const Building b = Make("office2");
  ASSERT_EQ(b.levels.size(), 2u);
  EXPECT_GE(b.rooms.size(), 20u);
  std::set<double> ceilings;
  int on_level[2] = {0, 0};
  for (const RoomTruth& r : b.rooms) {
    ++on_level[r.level];
    ceilings.insert(std::round((r.ceiling_z - r.floor_z) * 100));
  }
  EXPECT_GE(on_level[0], 10);
  EXPECT_GE(on_level[1], 10);
  EXPECT_GE(ceilings.size(), 5u);
  for (const DoorTruth& d : b.doors) {
    EXPECT_GE(d.width, 0.8);
    EXPECT_LE(d.width, 1.8);
  }
  ASSERT_EQ(b.stairs.size(), 1u);
  const StairTruth& s = b.stairs[0];
  EXPECT_NEAR(s.centerline.front().z(), b.levels[0].floor_z, 1e-9);
  EXPECT_NEAR(s.centerline.back().z(), b.levels[1].floor_z, 1e-9);
  for (size_t i = 1; i < s.centerline.size(); ++i) {
    EXPECT_GT(s.centerline[i].z(), s.centerline[i - 1].z());
  }
  // Steps: riser 0.17–0.18 m, tread 0.28 m; a vertical ray lands on each step's top through
  // the stairwell opening.
  for (size_t i = 1; i + 2 < s.centerline.size(); ++i) {
    const Vector3d step = s.centerline[i], next = s.centerline[i + 1];
    EXPECT_NEAR(next.x() - step.x(), 0.28, 1e-9);
    EXPECT_GE(next.z() - step.z(), 0.17);
    EXPECT_LE(next.z() - step.z(), 0.18);
    const Vector3d above(step.x(), step.y(), b.levels[1].floor_z + 1.5);
    EXPECT_NEAR(CastRay(b, above, {0, 0, -1}), above.z() - step.z(), 1e-6) << i;
  }
  // Landings walkable on their levels.
  for (const auto& [level, p] : {std::pair{s.from_level, s.centerline.front()},
                                 std::pair{s.to_level, s.centerline.back()}}) {
    const Eigen::Vector2i c = b.nav[level].CellOf(p.head<2>());
    EXPECT_TRUE(b.nav[level].IsFree(c.x(), c.y())) << level;
  }
  // A window and a column.
  int holes = 0;
  for (const RoomTruth& r : b.rooms) holes += int(r.holes.size());
  EXPECT_GE(holes, 1);
  EXPECT_EQ(CastRay(b, {2.0, 2.5, 1.5}, {0, -1, 0}), INFINITY);
}

TEST(PresetsTest, Office4IsALargeBuildingOfFourLevelsAndThreeWings) {
  const Building b = Make("office4");
  ASSERT_EQ(b.levels.size(), 4u);
  double floor_area = 0;
  std::vector<int> on_level(4, 0);
  for (const RoomTruth& r : b.rooms) {
    ++on_level[r.level];
    floor_area += std::abs(SignedArea(r.polygon));
    for (const auto& hole : r.holes) floor_area -= std::abs(SignedArea(hole));
  }
  EXPECT_GE(floor_area, 5000.0);
  for (int level = 0; level < 4; ++level) {
    EXPECT_GE(on_level[level], 40) << level;
    EXPECT_NEAR(b.levels[level].floor_z, 3.5 * level, 1e-9);
    // Three wings side by side: the level spans their depth.
    const Eigen::AlignedBox2d e = LevelExtent(b, level);
    EXPECT_GE(e.sizes().y(), 3 * 13.0) << level;
  }
  // A flight from each level to the next, each in its own wing; every entered room reachable
  // (PresetTest checks the visit points).
  ASSERT_EQ(b.stairs.size(), 3u);
  std::set<double> wings;
  for (int k = 0; k < 3; ++k) {
    const StairTruth& s = b.stairs[k];
    EXPECT_EQ(s.from_level, k);
    EXPECT_EQ(s.to_level, k + 1);
    EXPECT_NEAR(s.centerline.front().z(), b.levels[k].floor_z, 1e-9);
    EXPECT_NEAR(s.centerline.back().z(), b.levels[k + 1].floor_z, 1e-9);
    wings.insert(std::floor(s.centerline.front().y() / 13.0));
  }
  EXPECT_EQ(wings.size(), 3u);
  // The lobbies of neighbouring wings open into each other on every level.
  int lobby_doors = 0;
  for (const DoorTruth& d : b.doors) {
    const RoomTruth &a = b.rooms[d.room_a], &c = b.rooms[d.room_b];
    if (std::abs(d.p0.y() - d.p1.y()) < 1e-9 && a.polygon[0].x() > 31 && c.polygon[0].x() > 31) {
      ++lobby_doors;
    }
  }
  EXPECT_EQ(lobby_doors, 4 * 2);
  int objects = 0;
  for (const ObjectTruth& o : b.objects) objects += o.parts.empty() ? 0 : 1;
  EXPECT_GE(objects, 300);
}

}  // namespace
}  // namespace carvemap
