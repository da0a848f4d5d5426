#include "services/sim/walk_planner.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "services/building/building_presets.h"
#include "services/sim/sim_test_util.h"

namespace carvemap {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Level grid: two rooms [0,5]×[0,4] and [6,11]×[0,4] (interior, 0.3 m clearance), a wall
// between with a 1 m door at y ∈ [1.5, 2.5] (free after clearance: 0.4 m).
NavGrid TwoRoomGrid(bool door = true) {
  NavGrid g;
  g.resolution_m = 0.1;
  g.width = 110;
  g.height = 40;
  g.free.assign(g.width * g.height, 0);
  for (int iy = 0; iy < g.height; ++iy) {
    for (int ix = 0; ix < g.width; ++ix) {
      const double x = (ix + 0.5) * 0.1, y = (iy + 0.5) * 0.1;
      bool ok = y > 0.3 && y < 3.7 && ((x > 0.3 && x < 4.7) || (x > 6.3 && x < 10.7));
      if (door && y > 1.8 && y < 2.2 && x >= 4.7 && x <= 6.3) ok = true;
      g.free[iy * g.width + ix] = ok;
    }
  }
  return g;
}

Building TwoRooms(bool door = true) {
  Building b;
  b.name = "two_rooms";
  b.levels = {LevelTruth{0, 0.0, 2.6}};
  RoomTruth a, c;
  a.id = 10;
  c.id = 11;
  b.rooms = {a, c};
  b.nav = {TwoRoomGrid(door)};
  b.visit_points = {{2.5, 2.0}, {8.5, 1.5}};
  return b;
}

double MinDistanceXY(const std::vector<TimedPose>& path, const Eigen::Vector2d& p) {
  double best = 1e9;
  for (const TimedPose& tp : path) best = std::min(best, (tp.pose.translation.head<2>() - p).norm());
  return best;
}

TEST(GridSearch, AStarAndLineOfSight) {
  const NavGrid g = TwoRoomGrid();
  const auto path = GridAStar(g, {10, 10}, {100, 30});
  ASSERT_FALSE(path.empty());
  EXPECT_EQ(path.front(), Eigen::Vector2i(10, 10));
  EXPECT_EQ(path.back(), Eigen::Vector2i(100, 30));
  for (const auto& c : path) EXPECT_TRUE(g.IsFree(c.x(), c.y()));
  const std::vector<double> dist = GridDistances(g, {10, 10});
  EXPECT_GT(dist[30 * g.width + 100], 9.0);
  EXPECT_LT(dist[30 * g.width + 100], 11.0);
  EXPECT_TRUE(LineOfSight(g, {1, 1}, {4, 3}));
  EXPECT_FALSE(LineOfSight(g, {1, 1}, {8, 1}));  // through the wall
  EXPECT_TRUE(GridAStar(TwoRoomGrid(false), {10, 10}, {100, 30}).empty());
}

TEST(PlanWalk, VisitsEveryRoomAndReturns) {
  const Building b = TwoRooms();
  WalkOptions o;
  auto walk = PlanWalk(b, o);
  ASSERT_TRUE(walk.ok()) << walk.status();
  EXPECT_EQ(walk->route.rooms_visited, (std::vector<int>{0, 1}));
  const auto& path = walk->path;
  ASSERT_GT(path.size(), 100u);
  for (size_t r = 0; r < b.rooms.size(); ++r) {
    EXPECT_LT(MinDistanceXY(path, b.visit_points[r]), 0.3) << "room " << r;
  }
  // Loop closure: ends where it started.
  EXPECT_LT((path.back().pose.translation - path.front().pose.translation).norm(), 0.1);
  // Stays on walkable cells (corner cutting may move it a few cm into the clearance margin).
  for (const TimedPose& tp : path) {
    const Eigen::Vector2d p = tp.pose.translation.head<2>();
    EXPECT_TRUE(p.x() > 0.15 && p.y() > 0.15 && p.y() < 3.85 &&
                (p.x() < 4.85 || p.x() > 6.15 || (p.y() > 1.65 && p.y() < 2.35)))
        << p.transpose();
  }
}

// --laps: the tour again from where it ended; the same rooms, each lap as long as the first,
// and the yaw-rate and speed limits hold across the join too.
TEST(PlanWalk, LapsRepeatTheTour) {
  const Building b = TwoRooms();
  WalkOptions o;
  auto one = PlanWalk(b, o);
  ASSERT_TRUE(one.ok()) << one.status();
  o.laps = 3;
  auto three = PlanWalk(b, o);
  ASSERT_TRUE(three.ok()) << three.status();
  EXPECT_EQ(three->route.rooms_visited, one->route.rooms_visited);
  EXPECT_NEAR(three->length_m, 3 * one->length_m, 0.05 * one->length_m);
  EXPECT_NEAR(three->path.back().t, 3 * one->path.back().t, 0.1 * one->path.back().t);
  // Each room is passed once per lap: near its visit point in each third of the walk.
  const double lap_s = three->path.back().t / 3;
  for (int lap = 0; lap < 3; ++lap) {
    std::vector<TimedPose> part;
    for (const TimedPose& tp : three->path) {
      if (tp.t >= lap * lap_s - 5 && tp.t <= (lap + 1) * lap_s + 5) part.push_back(tp);
    }
    for (size_t r = 0; r < b.rooms.size(); ++r) {
      EXPECT_LT(MinDistanceXY(part, b.visit_points[r]), 0.3) << "lap " << lap << " room " << r;
    }
  }
  double max_yaw_rate = 0;
  for (size_t i = 1; i < three->path.size(); ++i) {
    const auto& a = three->path[i - 1];
    const auto& c = three->path[i];
    const Eigen::Vector3d x0 = a.pose.rotation * Eigen::Vector3d::UnitX();
    const Eigen::Vector3d x1 = c.pose.rotation * Eigen::Vector3d::UnitX();
    const double dyaw =
        std::remainder(std::atan2(x1.y(), x1.x()) - std::atan2(x0.y(), x0.x()), 2 * kPi);
    max_yaw_rate = std::max(max_yaw_rate, std::abs(dyaw) / (c.t - a.t));
    ASSERT_LT((c.pose.translation - a.pose.translation).norm(), 0.05);  // no jump at a join
  }
  EXPECT_LT(max_yaw_rate, (o.max_yaw_rate_dps + 10) * kPi / 180);
  o.laps = 0;
  EXPECT_FALSE(PlanWalk(b, o).ok());
}

TEST(PlanWalk, GaitSpeedAndYawRate) {
  const Building b = testing::MakeBoxRoom();
  WalkOptions o;
  auto walk = PlanWalk(TwoRooms(), o);
  ASSERT_TRUE(walk.ok()) << walk.status();
  const auto& path = walk->path;
  const double dt = 1.0 / o.sample_rate_hz;
  double max_yaw_rate = 0, max_tilt = 0;
  for (size_t i = 0; i < path.size(); ++i) {
    if (i > 0) {
      ASSERT_GT(path[i].t, path[i - 1].t);
      EXPECT_NEAR(path[i].t - path[i - 1].t, dt, 1e-9 + (i + 1 == path.size() ? dt : 0));
      const Eigen::Vector3d x0 = path[i - 1].pose.rotation * Eigen::Vector3d::UnitX();
      const Eigen::Vector3d x1 = path[i].pose.rotation * Eigen::Vector3d::UnitX();
      const double dyaw = std::remainder(std::atan2(x1.y(), x1.x()) - std::atan2(x0.y(), x0.x()),
                                         2 * kPi);
      max_yaw_rate = std::max(max_yaw_rate, std::abs(dyaw) / (path[i].t - path[i - 1].t));
    }
    const Eigen::Vector3d up = path[i].pose.rotation * Eigen::Vector3d::UnitZ();
    max_tilt = std::max(max_tilt, std::acos(std::clamp(up.z(), -1.0, 1.0)));
    EXPECT_NEAR(path[i].pose.translation.z(), o.system_height_m, o.bob_amplitude_m + 1e-9);
  }
  const double mean_speed = walk->length_m / path.back().t;
  EXPECT_GT(mean_speed, 0.7);
  EXPECT_LT(mean_speed, 1.3);
  EXPECT_LT(max_yaw_rate, (o.max_yaw_rate_dps + 10) * kPi / 180);
  EXPECT_GT(max_tilt, 0.5 * kPi / 180);  // the gait sways
  EXPECT_LT(max_tilt, 2.5 * kPi / 180);
  // The heading follows the walking direction while walking.
  int aligned = 0, moving = 0;
  for (size_t i = 20; i + 20 < path.size(); i += 20) {
    const Eigen::Vector2d v = path[i + 1].pose.translation.head<2>() - path[i - 1].pose.translation.head<2>();
    if (v.norm() / (2 * dt) < 0.5) continue;
    ++moving;
    const Eigen::Vector2d fwd = (path[i].pose.rotation * Eigen::Vector3d::UnitX()).head<2>();
    if (fwd.normalized().dot(v.normalized()) > std::cos(20 * kPi / 180)) ++aligned;
  }
  EXPECT_GT(aligned, 0.9 * moving);
}

TEST(PlanWalk, UnreachableRoomIsAnError) {
  auto walk = PlanWalk(TwoRooms(/*door=*/false), WalkOptions{});
  ASSERT_FALSE(walk.ok());
  EXPECT_EQ(walk.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(walk.status().message().find("room 11"), std::string::npos) << walk.status();
}

TEST(PlanWalk, TakesTheStairsBetweenLevels) {
  // Two stacked box levels 3 m apart; stairs along y = 1 from x = 1 to x = 4.
  Building b = testing::MakeBoxRoom(Eigen::Vector3d(6, 4, 2.6), false);
  b.levels.push_back(LevelTruth{1, 3.0, 5.6});
  RoomTruth r1 = b.rooms[0];
  r1.id = 1;
  r1.level = 1;
  r1.floor_z = 3.0;
  b.rooms.push_back(r1);
  b.nav.push_back(b.nav[0]);
  b.visit_points.push_back({4.5, 3.0});
  StairTruth st;
  for (int i = 0; i <= 10; ++i) st.centerline.push_back({1.0 + 0.3 * i, 1.0, 0.3 * i});
  b.stairs = {st};
  auto walk = PlanWalk(b, WalkOptions{});
  ASSERT_TRUE(walk.ok()) << walk.status();
  EXPECT_EQ(walk->route.rooms_visited, (std::vector<int>{0, 1}));
  double zmax = 0;
  bool visited_upper = false;
  for (const TimedPose& tp : walk->path) {
    zmax = std::max(zmax, tp.pose.translation.z());
    if (tp.pose.translation.z() > 4.6 &&
        (tp.pose.translation.head<2>() - b.visit_points[1]).norm() < 0.3) {
      visited_upper = true;
    }
  }
  EXPECT_NEAR(zmax, 3.0 + 1.7, 0.03);
  EXPECT_TRUE(visited_upper);
  EXPECT_NEAR(walk->path.back().pose.translation.z(), 1.7, 0.03);
}

}  // namespace
}  // namespace carvemap

namespace carvemap {
namespace {

TEST(PlanWalk, PresetsVisitEveryEnteredRoom) {
  for (const char* name : {"office", "office2"}) {
    auto b = MakePresetBuilding(name, 1);
    ASSERT_TRUE(b.ok()) << b.status();
    auto walk = PlanWalk(*b, WalkOptions{});
    ASSERT_TRUE(walk.ok()) << name << ": " << walk.status();
    int entered = 0;
    for (size_t r = 0; r < b->rooms.size(); ++r) {
      if (!b->rooms[r].entered) continue;
      ++entered;
      EXPECT_LT(MinDistanceXY(walk->path, b->visit_points[r]), 0.3) << name << " room " << r;
    }
    EXPECT_EQ(static_cast<int>(walk->route.rooms_visited.size()), entered) << name;
    const double speed = walk->length_m / walk->path.back().t;
    EXPECT_GT(speed, 0.7) << name;
    EXPECT_LT(speed, 1.3) << name;
    EXPECT_LT((walk->path.back().pose.translation - walk->path.front().pose.translation).norm(),
              0.1);
  }
}

}  // namespace
}  // namespace carvemap
