// Issue 5 evaluation, 2D route (seed §3.1.2 + §3.3): every real floor map of
// ../shared/data/floormaps (plain and furnished) used directly as wall samples, with the walk
// the simulator plans through it, through the whole floor-plan pipeline; the rooms are scored
// against the maps' ground-truth segmentation (SOURCES.md: room F1 at IoU > 0.5, Bormann et
// al.'s recall and precision). The floors asserted sit a little below what the pipeline reaches
// (docs/BENCHMARKS.md has the per-map numbers), so regressions fail.
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

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
  absl::StatusOr<LevelFloorPlan> plan = BuildLevelFloorPlan(*samples, 0, FloorPlanOptions{});
  if (!plan.ok()) return plan.status();
  EvalResult r;
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
          "(%zu samples, %.2f s)\n",
          name, furnished ? "furnished" : "plain", s.predicted_rooms, s.truth_rooms, s.matched,
          s.f1, s.bormann_recall, s.bormann_precision, r->samples, r->seconds_plan);
      sum_f1 += s.f1;
      sum_br += s.bormann_recall;
      sum_bp += s.bormann_precision;
      ++n;
    }
    std::printf("mean %-9s F1 %.3f  Bormann recall %.3f precision %.3f\n",
                furnished ? "furnished" : "plain", sum_f1 / n, sum_br / n, sum_bp / n);
    RecordProperty(furnished ? "mean_f1_furnished" : "mean_f1_plain",
                   std::to_string(sum_f1 / n));
    // Floors a little below the measured means (2026-11-22: plain 0.748, furnished 0.719;
    // the goal is 0.9 furnished, not reached yet).
    EXPECT_GE(sum_f1 / n, furnished ? 0.68 : 0.71) << (furnished ? "furnished" : "plain");
    EXPECT_GE(sum_br / n, furnished ? 0.87 : 0.95) << (furnished ? "furnished" : "plain");
  }
}

}  // namespace
}  // namespace carvemap
