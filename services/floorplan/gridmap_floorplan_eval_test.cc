// Issue 5 evaluation, 2D route (seed §3.1.2 + §3.3): every real floor map of
// ../shared/data/floormaps (plain and furnished) used directly as wall samples, with the walk
// the simulator plans through it, through the whole floor-plan pipeline; the rooms are scored
// against the maps' ground-truth segmentation (SOURCES.md: room F1 at IoU > 0.5, Bormann et
// al.'s recall and precision). The floors asserted sit a little below what the pipeline reaches
// (docs/BENCHMARKS.md has the per-map numbers), so regressions fail.
// The same route on the simulator's preset buildings (room, office, office2), whose rooms are
// known exactly: a grid map rasterised from the building at a height band (walls only, or walls
// and furniture as a low 2D scanner sees them), the simulator's walk; every entered room must come
// out as one room, and the unentered one not at all (issue 5: room count exact).
#include <chrono>
#include <ctime>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "services/building/building_presets.h"
#include "services/building/floormap_building.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/gridmap_wall_samples.h"
#include "services/floorplan/room_scoring.h"
#include "services/mesh/mesh_checks.h"
#include "services/sim/walk_planner.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

const std::string kMaps = std::string(CARVEMAP_SHARED_DIR) + "/data/floormaps";

struct EvalCase {
  std::string name;
  bool furnished;
};

struct EvalResult {
  RoomScores scores;
  size_t samples = 0;
  double seconds_plan = 0;
  double cpu_seconds_plan = 0;  // std::clock: this process's CPU time, less noisy when shared
};

// The walk the simulator would take through the map (its building, with furniture when
// furnished), as x, y positions every 0.1 m or so (the path is sampled at 200 Hz, 1 m/s).
absl::StatusOr<std::vector<Eigen::Vector2d>> WalkOf(const FloormapOptions& options) {
  absl::StatusOr<Building> building = MakeFloormapBuilding(options);
  if (!building.ok()) return building.status();
  absl::StatusOr<Walk> walk = PlanWalk(*building, WalkOptions{});
  if (!walk.ok()) return walk.status();
  std::vector<Eigen::Vector2d> xy;
  for (size_t i = 0; i < walk->path.size(); i += 20) {
    xy.emplace_back(walk->path[i].pose.translation.x(), walk->path[i].pose.translation.y());
  }
  return xy;
}

absl::StatusOr<EvalResult> Evaluate(const EvalCase& c) {
  FloormapOptions options = FloormapOptionsFor(kMaps, c.name);
  if (!c.furnished) options.furniture_map_path.clear();
  absl::StatusOr<std::vector<Eigen::Vector2d>> path = WalkOf(options);
  if (!path.ok()) return path.status();
  absl::StatusOr<Image<uint8_t>> map =
      ReadPngGray8(c.furnished ? FloormapOptionsFor(kMaps, c.name).furniture_map_path
                               : options.map_path);
  if (!map.ok()) return map.status();
  absl::StatusOr<WallSampleSet> samples = GridMapWallSamples(*map, *path, GridMapOptions{});
  if (!samples.ok()) return samples.status();
  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t c0 = std::clock();
  absl::StatusOr<LevelFloorPlan> plan = BuildLevelFloorPlan(*samples, 0, FloorPlanOptions{});
  if (!plan.ok()) return plan.status();
  EvalResult r;
  r.cpu_seconds_plan = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
  r.seconds_plan =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.samples = samples->samples.size();
  if (!CheckMesh(plan->extruded).watertight()) {
    return absl::InternalError(c.name + ": extruded model not watertight");
  }
  absl::StatusOr<Image<uint8_t>> gt = ReadPngGray8(options.rooms_map_path);
  if (!gt.ok()) return gt.status();
  const LabelImage truth = LabelsFromSegmentation(*gt);
  const LabelImage predicted =
      RasterizeFloorPlan(plan->plan, gt->width, gt->height, 0.05, 0.0, 0.0);
  absl::StatusOr<RoomScores> scores = ScoreRooms(truth, predicted);
  if (!scores.ok()) return scores.status();
  r.scores = *scores;
  return r;
}

const char* const kNames[] = {"Freiburg52_scan", "Freiburg101_scan", "lab_intel",
                              "lab_c_scan",      "lab_d_scan",       "office_a",
                              "office_b",        "office_c",         "office_d"};

// One test for all maps, plain then furnished, so the means are asserted where they are made.
TEST(GridmapFloorplanEval, RoomsAgainstGroundTruthOnEveryRealMap) {
  for (bool furnished : {false, true}) {
    double sum_f1 = 0, sum_br = 0, sum_bp = 0;
    int n = 0;
    for (const char* name : kNames) {
      absl::StatusOr<EvalResult> r = Evaluate({name, furnished});
      ASSERT_TRUE(r.ok()) << name << ": " << r.status();
      const RoomScores& s = r->scores;
      std::printf(
          "%-17s %-9s rooms %2d/%2d matched %2d  F1 %.3f  Bormann recall %.3f precision %.3f  "
          "(%zu samples, %.2f s, CPU %.2f s)\n",
          name, furnished ? "furnished" : "plain", s.predicted_rooms, s.truth_rooms, s.matched,
          s.f1, s.bormann_recall, s.bormann_precision, r->samples, r->seconds_plan,
          r->cpu_seconds_plan);
      sum_f1 += s.f1;
      sum_br += s.bormann_recall;
      sum_bp += s.bormann_precision;
      ++n;
    }
    std::printf("mean %-9s F1 %.3f  Bormann recall %.3f precision %.3f\n",
                furnished ? "furnished" : "plain", sum_f1 / n, sum_br / n, sum_bp / n);
    RecordProperty(furnished ? "mean_f1_furnished" : "mean_f1_plain",
                   std::to_string(sum_f1 / n));
    // Floors a little below the measured means (2026-11-26: F1 plain 0.935, furnished 0.927;
    // Bormann recall 0.986 / 0.944, precision 0.977 / 0.985; issue 5's goal: F1 ≥ 0.9
    // furnished).
    EXPECT_GE(sum_f1 / n, furnished ? 0.91 : 0.92) << (furnished ? "furnished" : "plain");
    EXPECT_GE(sum_br / n, furnished ? 0.92 : 0.96) << (furnished ? "furnished" : "plain");
    EXPECT_GE(sum_bp / n, furnished ? 0.96 : 0.95) << (furnished ? "furnished" : "plain");
  }
}

struct PresetResult {
  int level = 0;
  RoomScores scores;
  int entered_rooms = 0;
  size_t unentered_pixels_in_plan = 0;
};

// The preset's levels as grid maps: cells blocked by any solid (structure or furniture) that
// overlaps [floor + z_lo, floor + z_hi], 5 cm cells, 1 m margin; the walk's poses on that level.
absl::StatusOr<std::vector<PresetResult>> EvaluatePreset(const std::string& name, double z_lo,
                                                         double z_hi) {
  absl::StatusOr<Building> b = MakePresetBuilding(name, 1);
  if (!b.ok()) return b.status();
  absl::StatusOr<Walk> walk = PlanWalk(*b, WalkOptions{});
  if (!walk.ok()) return walk.status();
  constexpr double kRes = 0.05;
  std::vector<PresetResult> results;
  for (size_t level = 0; level < b->levels.size(); ++level) {
    const NavGrid& nav = b->nav[level];
    NavGrid frame;
    frame.resolution_m = kRes;
    frame.origin = nav.origin - Eigen::Vector2d(1, 1);
    frame.width = static_cast<int>((nav.width * nav.resolution_m + 2) / kRes);
    frame.height = static_cast<int>((nav.height * nav.resolution_m + 2) / kRes);
    const double floor_z = b->levels[level].floor_z;
    const std::vector<uint8_t> blocked =
        BlockedCells(frame, *b, floor_z + z_lo, floor_z + z_hi);
    Image<uint8_t> map;
    map.width = frame.width;
    map.height = frame.height;
    map.pixels.assign(blocked.size(), 255);
    for (int iy = 0; iy < frame.height; ++iy) {
      for (int ix = 0; ix < frame.width; ++ix) {
        if (blocked[size_t(iy) * frame.width + ix]) map.at(frame.height - 1 - iy, ix) = 0;
      }
    }
    std::vector<Eigen::Vector2d> path;  // this level's poses (system 1.7 m above its floor)
    for (size_t i = 0; i < walk->path.size(); i += 20) {
      const Eigen::Vector3d& t = walk->path[i].pose.translation;
      if (std::abs(t.z() - WalkOptions{}.system_height_m - floor_z) < 0.3) {
        path.emplace_back(t.x(), t.y());
      }
    }
    GridMapOptions grid;
    grid.origin_x_m = frame.origin.x();
    grid.origin_y_m = frame.origin.y();
    absl::StatusOr<WallSampleSet> samples = GridMapWallSamples(map, path, grid);
    if (!samples.ok()) return samples.status();
    absl::StatusOr<LevelFloorPlan> plan =
        BuildLevelFloorPlan(*samples, static_cast<int>(level), FloorPlanOptions{});
    if (!plan.ok()) return plan.status();
    const LabelImage predicted = RasterizeFloorPlan(plan->plan, map.width, map.height, kRes,
                                                    frame.origin.x(), frame.origin.y());
    PresetResult r;
    r.level = static_cast<int>(level);
    LabelImage truth;
    truth.width = map.width;
    truth.height = map.height;
    truth.labels.assign(map.pixels.size(), -1);
    for (size_t id = 0; id < b->rooms.size(); ++id) {
      const RoomTruth& room = b->rooms[id];
      if (room.level != static_cast<int>(level)) continue;
      r.entered_rooms += room.entered ? 1 : 0;
      for (int row = 0; row < map.height; ++row) {
        for (int col = 0; col < map.width; ++col) {
          const Eigen::Vector2d c =
              frame.origin + Eigen::Vector2d((col + 0.5) * kRes, (map.height - 1 - row + 0.5) * kRes);
          if (!RoomContains(room, c)) continue;
          const size_t i = size_t(row) * map.width + col;
          if (room.entered) {
            truth.labels[i] = static_cast<int>(id);
          } else if (predicted.labels[i] >= 0) {
            ++r.unentered_pixels_in_plan;
          }
        }
      }
    }
    absl::StatusOr<RoomScores> scores = ScoreRooms(truth, predicted);
    if (!scores.ok()) return scores.status();
    r.scores = *scores;
    results.push_back(r);
  }
  return results;
}

TEST(GridmapFloorplanEval, PresetRoomCountsAreExact) {
  // Walls only (a scanner above the furniture), then walls and furniture (a scanner at 0.3–0.6 m:
  // desks, shelves, cabinets, chairs all in the map).
  for (const auto& [z_lo, z_hi] : {std::pair{1.0, 1.2}, std::pair{0.3, 0.6}}) {
    for (const char* name : {"room", "office", "office2"}) {
      absl::StatusOr<std::vector<PresetResult>> results = EvaluatePreset(name, z_lo, z_hi);
      ASSERT_TRUE(results.ok()) << name << ": " << results.status();
      for (const PresetResult& r : *results) {
        std::printf("%-8s level %d band [%.1f, %.1f] m: rooms %2d/%2d matched %2d  F1 %.3f  "
                    "Bormann recall %.3f precision %.3f; unentered room pixels in the plan %zu\n",
                    name, r.level, z_lo, z_hi, r.scores.predicted_rooms, r.entered_rooms,
                    r.scores.matched, r.scores.f1, r.scores.bormann_recall,
                    r.scores.bormann_precision, r.unentered_pixels_in_plan);
        EXPECT_EQ(r.scores.truth_rooms, r.entered_rooms) << name << " level " << r.level;
        EXPECT_EQ(r.scores.predicted_rooms, r.entered_rooms) << name << " level " << r.level;
        EXPECT_EQ(r.scores.matched, r.entered_rooms) << name << " level " << r.level;
        EXPECT_EQ(r.unentered_pixels_in_plan, 0u) << name << " level " << r.level;
      }
    }
  }
}

}  // namespace
}  // namespace carvemap
