// Floor-plan evaluation, 2D route (§3.1.2 + §3.3): every real floor map of
// tests/data/floormaps (plain and furnished) used directly as wall samples, with the walk
// the simulator plans through it, through the whole floor-plan pipeline; the rooms are scored
// against the maps' ground-truth segmentation (SOURCES.md: room F1 at IoU > 0.5, Bormann et
// al.'s recall and precision). The floors asserted sit a little below what the pipeline reaches
// (docs/BENCHMARKS.md has the per-map numbers), so regressions fail.
// The same route on the simulator's preset buildings (room, office, office2), whose rooms are
// known exactly: a grid map rasterised from the building at a height band (walls only, or walls
// and furniture as a low 2D scanner sees them), the simulator's walk; every entered room must come
// out as one room, and the unentered one not at all (the room count exact).
#include <algorithm>
#include <array>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "services/building/building_presets.h"
#include "services/building/floormap_building.h"
#include "services/floorplan/eval/room_scoring.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/samples/gridmap_wall_samples.h"
#include "services/mesh/mesh_checks.h"
#include "services/sim/walk_planner.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

const std::string kMaps = std::string(CARVEMAP_TEST_DATA_DIR) + "/floormaps";

struct EvalCase {
  std::string name;
  bool furnished;
};

struct EvalResult {
  RoomScores scores;
  size_t samples = 0;
  double seconds_plan = 0;
  double cpu_seconds_plan = 0;  // std::clock: this process's CPU time, less noisy when shared
  size_t outline_vertices = 0;  // of the room polygons (outer rings)
  size_t interior_triangles = 0;  // of the rooms' triangulation, before unentered rooms go
  size_t room_pixels = 0;         // pixels of the plan's rooms
  // [1] only: pixels in a room of one method's plan and in none of the other's
  size_t pixels_differing = 0;
  EigencrustFloorPlanReport eigencrust;
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

// Both floor-plan methods on the same wall samples (the walk and the samples are most of the
// time: each method's plan takes under a second): [0] §3.3 room partitioning, [1] §3.2
// Eigencrust with §3.3.2's rooms on its interior.
absl::StatusOr<std::array<EvalResult, 2>> Evaluate(const EvalCase& c) {
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
  absl::StatusOr<Image<uint8_t>> gt = ReadPngGray8(options.rooms_map_path);
  if (!gt.ok()) return gt.status();
  const LabelImage truth = LabelsFromSegmentation(*gt);
  std::array<EvalResult, 2> out;
  std::array<LabelImage, 2> rasters;
  for (int m = 0; m < 2; ++m) {
    FloorPlanOptions plan_options;
    plan_options.method = m == 0 ? FloorPlanMethod::kRooms : FloorPlanMethod::kEigencrust;
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    absl::StatusOr<LevelFloorPlan> plan = BuildLevelFloorPlan(*samples, 0, plan_options);
    if (!plan.ok()) return plan.status();
    EvalResult& r = out[m];
    r.cpu_seconds_plan = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    r.seconds_plan =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    r.samples = samples->samples.size();
    r.eigencrust = plan->eigencrust;
    for (const RoomPolygon& room : plan->outline.rooms) r.outline_vertices += room.outer.size();
    if (!CheckMesh(plan->extruded).watertight()) {
      return absl::InternalError(c.name + ": extruded model not watertight (" +
                                 std::string(FloorPlanMethodName(plan_options.method)) + ")");
    }
    const LabelImage predicted =
        RasterizeFloorPlan(plan->plan, gt->width, gt->height, 0.05, 0.0, 0.0);
    absl::StatusOr<RoomScores> scores = ScoreRooms(truth, predicted);
    if (!scores.ok()) return scores.status();
    r.scores = *scores;
    r.interior_triangles = plan->labeling.interior_triangles;
    for (int32_t l : predicted.labels) r.room_pixels += l >= 0;
    rasters[m] = predicted;
  }
  // How far apart the two interiors are (both plans get §3.3.2's rooms, so the room scores
  // can agree while the walls differ).
  for (size_t i = 0; i < rasters[0].labels.size(); ++i) {
    out[1].pixels_differing += (rasters[0].labels[i] >= 0) != (rasters[1].labels[i] >= 0);
  }
  return out;
}

const char* const kNames[] = {"Freiburg52_scan", "Freiburg101_scan", "lab_intel",
                              "lab_c_scan",      "lab_d_scan",       "office_a",
                              "office_b",        "office_c",         "office_d"};

// One test for all maps, plain then furnished, so the means are asserted where they are made;
// both methods (§3.3, then §3.2 Eigencrust) on the same samples.
TEST(GridmapFloorplanEval, RoomsAgainstGroundTruthOnEveryRealMap) {
  for (bool furnished : {false, true}) {
    double sum_f1[2] = {0, 0}, sum_br[2] = {0, 0}, sum_bp[2] = {0, 0};
    int n = 0;
    for (const char* name : kNames) {
      absl::StatusOr<std::array<EvalResult, 2>> r = Evaluate({name, furnished});
      ASSERT_TRUE(r.ok()) << name << ": " << r.status();
      for (int m = 0; m < 2; ++m) {
        const RoomScores& s = (*r)[m].scores;
        std::printf(
            "%-17s %-9s %-10s rooms %2d/%2d matched %2d  F1 %.3f  Bormann recall %.3f precision "
            "%.3f  (%zu samples, %zu outline vertices, %zu interior triangles, %zu room "
            "pixels, %.2f s, CPU %.2f s)\n",
            name, furnished ? "furnished" : "plain", m == 0 ? "rooms" : "eigencrust",
            s.predicted_rooms, s.truth_rooms, s.matched, s.f1, s.bormann_recall,
            s.bormann_precision, (*r)[m].samples, (*r)[m].outline_vertices,
            (*r)[m].interior_triangles, (*r)[m].room_pixels, (*r)[m].seconds_plan,
            (*r)[m].cpu_seconds_plan);
        if (m == 1) {
          std::printf("    pixels in a room of one plan and not of the other: %zu (%.1f%% of the "
                      "rooms method's)\n",
                      (*r)[m].pixels_differing,
                      100.0 * (*r)[m].pixels_differing / std::max<size_t>(1, (*r)[0].room_pixels));
          const EigencrustFloorPlanReport& e = (*r)[m].eigencrust;
          std::printf("    eigencrust: %zu triangles, %zu poles, %zu sight lines, known in %zu out "
                      "%zu, solved %zu pole nodes (λ %.2g) and %zu non-pole nodes (λ %.2g), "
                      "flipped %zu + %zu, inside %zu; curves %zu lines %zu circles, %zu of %zu "
                      "assigned, %zu corners, moved %zu (put back %zu, flat %zu); s: label "
                      "%.2f (triangulation %.2f, known %.2f, poles %.2f, non-poles %.2f) rooms "
                      "%.2f curves %.2f\n",
                      e.labeling.triangles, e.labeling.poles, e.labeling.sight_lines,
                      e.labeling.known_inside, e.labeling.known_outside,
                      e.labeling.pole_nodes_solved, e.labeling.pole_eigenvalue,
                      e.labeling.nonpole_nodes, e.labeling.nonpole_eigenvalue,
                      e.labeling.flipped_unions, e.labeling.flipped_protrusions,
                      e.labeling.inside, e.curves.lines, e.curves.circles, e.curves.assigned,
                      e.curves.boundary_samples, e.curves.corners, e.moved_vertices,
                      e.refused_moves, e.dropped_flat_triangles, e.seconds_label,
                      e.labeling.seconds_triangulation, e.labeling.seconds_known,
                      e.labeling.seconds_poles, e.labeling.seconds_nonpoles, e.seconds_rooms,
                      e.seconds_curves);
        }
        // Every map: issue's goal 0.85 furnished; the lowest measured is lab_intel, 0.844
        // plain, 0.870 furnished.
        EXPECT_GE(s.f1, 0.82) << name << " " << (furnished ? "furnished" : "plain") << " "
                              << (m == 0 ? "rooms" : "eigencrust");
        sum_f1[m] += s.f1;
        sum_br[m] += s.bormann_recall;
        sum_bp[m] += s.bormann_precision;
      }
      ++n;
    }
    const char* kind = furnished ? "furnished" : "plain";
    for (int m = 0; m < 2; ++m) {
      std::printf("mean %-9s %-10s F1 %.3f  Bormann recall %.3f precision %.3f\n", kind,
                  m == 0 ? "rooms" : "eigencrust", sum_f1[m] / n, sum_br[m] / n, sum_bp[m] / n);
    }
    RecordProperty(furnished ? "mean_f1_furnished" : "mean_f1_plain",
                   std::to_string(sum_f1[0] / n));
    RecordProperty(furnished ? "mean_f1_furnished_eigencrust" : "mean_f1_plain_eigencrust",
                   std::to_string(sum_f1[1] / n));
    // Floors a little below the measured means (F1 plain 0.968, furnished 0.958; Bormann
    // recall 0.986 / 0.944, precision 0.987 / 0.988; docs/BENCHMARKS.md; the goals: F1 ≥ 0.9
    // furnished, then a mean ≥ 0.93).
    EXPECT_GE(sum_f1[0] / n, furnished ? 0.94 : 0.95) << kind;
    EXPECT_GE(sum_br[0] / n, furnished ? 0.92 : 0.96) << kind;
    EXPECT_GE(sum_bp[0] / n, furnished ? 0.96 : 0.95) << kind;
    // Eigencrust (§3.2, rooms by §3.3.2 on its interior): floors a little below its means
    // (measured: the same as §3.3's to three decimals, F1 0.968 / 0.958, Bormann recall
    // 0.986 / 0.944, precision 0.987 / 0.988: the rooms come from the same partition, and
    // the interiors differ only along the walls; docs/BENCHMARKS.md "Eigencrust floor plans").
    EXPECT_GE(sum_f1[1] / n, furnished ? 0.94 : 0.95) << kind << " eigencrust";
    EXPECT_GE(sum_br[1] / n, furnished ? 0.92 : 0.96) << kind << " eigencrust";
    EXPECT_GE(sum_bp[1] / n, furnished ? 0.96 : 0.95) << kind << " eigencrust";
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
