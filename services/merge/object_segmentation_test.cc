// The segmentation evaluation on simulated buildings (§5.5, §5.6): a preset carved in this process
// and merged with its scan's path, so the floor plans and the segmentation run as in a job; the
// objects of job.json are compared with the simulator's objects (gt/building.json), the
// building mesh with the true walls (gt/surfaces.ply), and the meshes inside the rooms the walk
// never entered with what trimming (§5.5) must leave there: nothing.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "geometry/union_find.h"
#include "services/merge/merge_job.h"
#include "services/merge/merge_test_util.h"
#include "services/mesh/mesh_checks.h"
#include "storage/ply_io.h"
#include "tests/support/carved_preset.h"
#include "tests/support/truth_distance.h"

namespace carvemap {
namespace {

using Box = Eigen::AlignedBox3d;

Box BoxFromJson(const nlohmann::json& aabb) {
  return Box(Eigen::Vector3d(aabb[0][0], aabb[0][1], aabb[0][2]),
             Eigen::Vector3d(aabb[1][0], aabb[1][1], aabb[1][2]));
}

double Iou(const Box& a, const Box& b) {
  const Box i = a.intersection(b);
  if (i.isEmpty()) return 0;
  const double vi = i.volume();
  return vi / (a.volume() + b.volume() - vi);
}

// Signed distance from `p` (2D) to the simple polygon `ring`: positive inside.
double SignedDistanceToRing(const std::vector<Eigen::Vector2d>& ring, const Eigen::Vector2d& p) {
  double d = std::numeric_limits<double>::infinity();
  bool inside = false;
  for (size_t i = 0, j = ring.size() - 1; i < ring.size(); j = i++) {
    const Eigen::Vector2d a = ring[j], b = ring[i];
    const double t = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
    d = std::min(d, (a + t * (b - a) - p).norm());
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < a.x() + (p.y() - a.y()) / (b.y() - a.y()) * (b.x() - a.x())) {
      inside = !inside;
    }
  }
  return inside ? d : -d;
}

double EnvOr(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::atof(v) : fallback;
}

struct PresetCase {
  const char* name;
  const char* preset;
  double walk_s;           // 0 = the whole walk
  double rate_hz;          // the line scanners' rate (the simulator's default: 40 Hz)
  double object_resolution_m;  // §5.6.1 re-carving of the object chunks (0 = none)
  double min_found;        // fraction of true objects (all sides ≥ 0.3 m) found at IoU ≥ 0.5
  double max_false;        // fraction of reported objects overlapping no true object
  double min_wall_cover;   // fraction of true wall area within 10 cm of building.ply
  double min_hidden_cover; // the same for the wall behind furniture
  bool trimmed_points;     // also write and check points.ply (§5.5)
};

void PrintTo(const PresetCase& c, std::ostream* os) { *os << c.name; }

class ObjectSegmentation : public ::testing::TestWithParam<PresetCase> {};

TEST_P(ObjectSegmentation, FindsTheFurnitureAndKeepsTheWalls) {
  const PresetCase& pc = GetParam();
  testing::CarvedPresetOptions o;
  o.preset = pc.preset;
  o.walk_s = EnvOr("CARVEMAP_SEG_WALK_S", pc.walk_s);
  // Exploring only: CARVEMAP_SEG_RATE_HZ / CARVEMAP_SEG_BEAM_DEG (the simulator's defaults are
  // 40 Hz / 0.25°; 1° here keeps the carve short).
  o.rate_hz = EnvOr("CARVEMAP_SEG_RATE_HZ", pc.rate_hz);
  o.beam_step_deg = EnvOr("CARVEMAP_SEG_BEAM_DEG", 1.0);
  // Exploring only: CARVEMAP_SEG_DRIFT=1 (the simulator's localization drift on the path).
  o.drift = EnvOr("CARVEMAP_SEG_DRIFT", 0) != 0;
  o.threads = 2;
  const std::string root = testing::FreshDir();
  const auto t0 = std::chrono::steady_clock::now();
  // Exploring only: CARVEMAP_SEG_REUSE_ROOT=<a kept run's …/carve> (CARVEMAP_KEEP_TEST_TMPDIR=1)
  // merges that carve again instead of carving anew (pick the case of that carve with
  // --gtest_filter: its rate is the carve's).
  absl::StatusOr<testing::CarvedPreset> carved;
  if (const char* reuse = std::getenv("CARVEMAP_SEG_REUSE_ROOT"); reuse && *reuse) {
    testing::CarvedPreset p;
    p.scan_path = std::string(reuse) + "/sim/scan.h5";
    p.gt_dir = std::string(reuse) + "/sim/gt";
    p.tiles_dir = std::string(reuse) + "/tiles";
    p.grid = *OctreeGrid::FromResolution(o.resolution_m);
    carved = p;
  } else {
    carved = testing::CarvePreset(o, root + "/carve");
  }
  ASSERT_TRUE(carved.ok()) << carved.status();
  const auto t1 = std::chrono::steady_clock::now();
  MergeOptions m;
  m.tiles_dir = carved->tiles_dir;
  m.output_dir = root + "/out";
  m.scan_path = carved->scan_path;
  m.object_resolution_m = EnvOr("CARVEMAP_SEG_OBJECT_RES", pc.object_resolution_m);
  m.recarve = testing::InProcessRecarve(carved->scan_path, root + "/object_tiles", o.threads);
  m.trimmed_points = pc.trimmed_points;  // §5.5 for the point cloud too (checked below)
  // Exploring only: CARVEMAP_SEG_FILL_POCKETS=0 merges the tiles as carved.
  m.fill_pockets = EnvOr("CARVEMAP_SEG_FILL_POCKETS", 1) != 0;
  // The stages after the objects' dense mesh, and the objects counted as they are written.
  std::vector<std::string> late_stages;
  std::vector<uint64_t> files_done;
  uint64_t files_total = 0;
  absl::StatusOr<MergeSummary> merged = RunMerge(m, [&](const MergeProgress& p) {
    const bool late = p.stage == "object_split" || p.stage == "object_files";
    if (late && (late_stages.empty() || late_stages.back() != p.stage)) {
      late_stages.push_back(p.stage);
    }
    if (p.stage == "object_files") {
      files_done.push_back(p.done);
      files_total = p.total;
    }
    return true;
  });
  ASSERT_TRUE(merged.ok()) << merged.status();
  const auto t2 = std::chrono::steady_clock::now();
  const nlohmann::json& job = merged->job;
  EXPECT_EQ(late_stages,
            (std::vector<std::string>{"object_split", "object_files"}));
  // Counted from 0, a batch of objects at a time.
  EXPECT_EQ(files_total, job.at("objects").size());
  ASSERT_FALSE(files_done.empty());
  EXPECT_EQ(files_done.front(), 0u);
  EXPECT_LE(files_done.size(), files_total);
  EXPECT_LT(files_done.back(), files_total);
  EXPECT_TRUE(std::is_sorted(files_done.begin(), files_done.end()));
  for (const auto& w : job.value("warnings", nlohmann::json::array())) {
    std::printf("[%s] warning: %s\n", pc.name, w.get<std::string>().c_str());
  }
  ASSERT_TRUE(job.contains("objects")) << job.dump(1);

  std::ifstream in(carved->gt_dir + "/building.json");
  const nlohmann::json truth = nlohmann::json::parse(in);
  std::vector<Box> true_boxes, big_true;
  for (const auto& t : truth.at("objects")) {
    if (!t.contains("aabb")) continue;
    true_boxes.push_back(BoxFromJson(t["aabb"]));
    if (true_boxes.back().sizes().minCoeff() >= 0.3) big_true.push_back(true_boxes.back());
  }
  std::vector<Box> found;
  for (const auto& obj : job["objects"]) found.push_back(BoxFromJson(obj["aabb"]));
  ASSERT_FALSE(big_true.empty());

  // Found: a reported object with IoU ≥ 0.5 (one-to-one, greedy by IoU).
  std::vector<std::tuple<double, size_t, size_t>> pairs;
  for (size_t t = 0; t < big_true.size(); ++t)
    for (size_t f = 0; f < found.size(); ++f)
      if (double iou = Iou(big_true[t], found[f]); iou >= 0.5) pairs.emplace_back(iou, t, f);
  std::sort(pairs.rbegin(), pairs.rend());
  std::vector<bool> t_used(big_true.size()), f_used(found.size());
  size_t matched = 0;
  for (const auto& [iou, t, f] : pairs) {
    if (t_used[t] || f_used[f]) continue;
    t_used[t] = f_used[f] = true;
    ++matched;
  }
  // False: a reported object that overlaps no true object (any size) by ≥ 10 % of its box:
  // a piece of wall, floor or ceiling, or an artefact.
  size_t false_objects = 0;
  for (size_t f = 0; f < found.size(); ++f) {
    double best = 0;
    for (const Box& t : true_boxes) {
      const Box i = t.intersection(found[f]);
      if (!i.isEmpty()) best = std::max(best, i.volume() / found[f].volume());
    }
    if (best < 0.1) {
      ++false_objects;
      std::printf("[%s] false object %zu: [%.2f %.2f %.2f]..[%.2f %.2f %.2f]\n", pc.name, f,
                  found[f].min().x(), found[f].min().y(), found[f].min().z(),
                  found[f].max().x(), found[f].max().y(), found[f].max().z());
    }
  }
  for (size_t t = 0; t < big_true.size(); ++t) {
    if (t_used[t]) continue;
    double best = 0;
    for (const Box& f : found) best = std::max(best, Iou(big_true[t], f));
    std::printf("[%s] missed object [%.2f %.2f %.2f]..[%.2f %.2f %.2f], best IoU %.2f\n",
                pc.name, big_true[t].min().x(), big_true[t].min().y(), big_true[t].min().z(),
                big_true[t].max().x(), big_true[t].max().y(), big_true[t].max().z(), best);
  }

  const double found_frac = double(matched) / big_true.size();
  const double false_frac = found.empty() ? 0 : double(false_objects) / found.size();
  std::printf("[%s] rooms %llu, objects %zu (true %zu, of them %zu with all sides ≥ 0.3 m); found "
              "%zu (%.0f %%), false %zu (%.0f %%)\n",
              pc.name, (unsigned long long)merged->num_rooms, found.size(), true_boxes.size(),
              big_true.size(), matched, 100 * found_frac, false_objects, 100 * false_frac);
  EXPECT_GE(found_frac, pc.min_found);
  EXPECT_LE(false_frac, pc.max_false);
  // Floor plans through the 3D route: one room per true room the walk entered (§3.3.2 removes the
  // unentered storage room), whatever the walk's length when it covers the whole building.
  if (o.walk_s == 0) {
    size_t entered = 0;
    for (const auto& room : truth.at("rooms")) entered += room.value("entered", true) ? 1 : 0;
    EXPECT_EQ(merged->num_rooms, entered);
  }

  // Meshes: each object and the building watertight; combined = building + objects.
  const std::string out = m.output_dir;
  absl::StatusOr<PlyMesh> building = ReadPly(out + "/mesh/building.ply");
  ASSERT_TRUE(building.ok()) << building.status();
  const MeshCheck bcheck = CheckMesh(building->mesh);
  EXPECT_TRUE(bcheck.watertight()) << bcheck.ToString();
  size_t object_triangles = 0, leaky = 0, shells = 0;
  for (const auto& obj : job["objects"]) {
    absl::StatusOr<PlyMesh> mesh = ReadPly(out + "/" + obj["mesh"].get<std::string>());
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    leaky += !CheckMesh(mesh->mesh).watertight();
    object_triangles += mesh->mesh.triangles.size();
    // Closed components: triangles joined through shared vertices.
    UnionFind<int> parts(mesh->mesh.vertices.size());
    for (const Eigen::Vector3i& t : mesh->mesh.triangles)
      parts.Union(t[0], t[1]), parts.Union(t[0], t[2]);
    std::vector<int> roots;
    for (const Eigen::Vector3i& t : mesh->mesh.triangles) roots.push_back(parts.Find(t[0]));
    std::sort(roots.begin(), roots.end());
    shells += std::unique(roots.begin(), roots.end()) - roots.begin();
  }
  EXPECT_EQ(leaky, 0u);
  // An object is one closed surface, or a few where it has separate parts (stacked boards), not
  // a cloud of specks: at most 3 per object on average; and the objects, meshed finer than the
  // building, still take fewer triangles than the dense mesh of the whole building.
  std::printf("[%s] objects' closed surfaces %zu, %.2f per object\n", pc.name, shells,
              double(shells) / std::max<size_t>(1, job["objects"].size()));
  EXPECT_LE(double(shells), 3.0 * double(job["objects"].size()));
  EXPECT_LT(object_triangles, merged->dense_triangles);
  // The planar building mesh uses ≤ 10 % of the dense mesh's triangles (measured
  // 2.6 %; 25 % while the carve was a speckle between rays).
  EXPECT_LE(double(building->mesh.triangles.size()), 0.10 * double(merged->dense_triangles));
  absl::StatusOr<PlyMesh> combined = ReadPly(out + "/mesh/combined.ply");
  ASSERT_TRUE(combined.ok()) << combined.status();
  EXPECT_EQ(combined->mesh.triangles.size(), building->mesh.triangles.size() + object_triangles);

  // Wall cover: points on the true walls (vertical truth triangles, ~10 cm apart) that the
  // scans saw (within 5 cm of the dense mesh), and the share of them within 5 cm and 10 cm of
  // building.ply. Not 20 cm: the walls are 15 cm thick, and the outer faces of the outside
  // walls, which no scan inside reaches, lie that far from the dense mesh (they were 28 % of
  // the points, 12–19 cm from both meshes). `hidden`: wall points within 20 cm of the dense
  // mesh with a true object within 10 cm (behind furniture, where the dense mesh is the
  // furniture).
  const testing::TruthDistance to_building(
      testing::ReadPlyTriangles(out + "/mesh/building.ply"), 0.25, 0.2);
  const testing::TruthDistance to_dense(testing::ReadPlyTriangles(out + "/mesh/dense.ply"), 0.25,
                                        0.2);
  size_t wall_points = 0, covered5 = 0, covered10 = 0, hidden = 0, hidden_covered = 0;
  // Seen or hidden: the goal's "true wall area, including the parts hidden behind shelves".
  size_t either = 0, either_covered = 0;
  for (const Eigen::Vector3d& p :
       testing::WallPoints(testing::ReadPlyTriangles(carved->gt_dir + "/surfaces.ply"), 0.1)) {
    const double dd = to_dense(p);
    if (dd >= 0.2) continue;
    bool behind = false;
    for (const Box& o : true_boxes) behind = behind || o.exteriorDistance(p) <= 0.1;
    if (dd >= 0.05 && !behind) continue;
    const double db = to_building(p);
    ++either;
    either_covered += db <= 0.10;
    if (dd < 0.05) {
      ++wall_points;
      covered5 += db <= 0.05;
      covered10 += db <= 0.10;
    }
    if (behind) {
      ++hidden;
      hidden_covered += db <= 0.10;
    }
  }
  ASSERT_GT(wall_points, 1000u);
  const double cover = double(covered10) / wall_points;
  auto s = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
  std::printf(
      "[%s] building %zu triangles, objects %zu, dense %llu; wall cover within 5 cm %.1f %%, "
      "within 10 cm %.1f %% of %zu points (behind furniture %zu, within 10 cm %.1f %%; seen or "
      "behind furniture, within 10 cm %.1f %%); carve %.0f s, merge %.0f s "
      "(segmentation %.1f s, planar %.1f s, re-carve %.1f s of %d chunks, re-segmentation "
      "%.1f s, objects %.1f s)\n",
      pc.name, building->mesh.triangles.size(), object_triangles,
      (unsigned long long)merged->dense_triangles, 100.0 * covered5 / wall_points, 100 * cover,
      wall_points, hidden,
      hidden ? 100.0 * hidden_covered / hidden : 0.0, 100.0 * either_covered / either,
      s(t0, t1), s(t1, t2),
      job["timings_s"].value("merge.segmentation", 0.0),
      job["timings_s"].value("merge.planar_mesh", 0.0),
      job["timings_s"].value("merge.recarve", 0.0), job["counts"].value("recarved_chunks", 0),
      job["timings_s"].value("merge.recarve_segmentation", 0.0),
      job["timings_s"].value("merge.object_mesh", 0.0));
  EXPECT_GE(cover, pc.min_wall_cover);
  EXPECT_GE(double(either_covered) / either, pc.min_wall_cover);
  ASSERT_GT(hidden, 100u);
  EXPECT_GE(double(hidden_covered) / hidden, pc.min_hidden_cover);

  // §5.5 trimming: the rooms the walk never entered (gt "entered": false) were seen through
  // their doors. The plan leaves them out, so their inside is trimmed: the dense mesh has it,
  // building.ply and objects.ply have nothing deeper than the trim distance (1 m) plus a
  // margin inside them, while their walls shared with entered rooms stay (wall cover above).
  std::vector<std::vector<Eigen::Vector2d>> unentered;
  for (const auto& room : truth.at("rooms")) {
    if (room.value("entered", true)) continue;
    std::vector<Eigen::Vector2d>& ring = unentered.emplace_back();
    for (const auto& v : room.at("polygon")) ring.emplace_back(v[0], v[1]);
  }
  auto deep_inside = [&](const std::string& name) {
    absl::StatusOr<PlyMesh> mesh = ReadPly(out + "/" + name);
    EXPECT_TRUE(mesh.ok()) << mesh.status();
    size_t n = 0;
    if (!mesh.ok()) return n;
    for (const Eigen::Vector3f& v : mesh->mesh.vertices) {
      const Eigen::Vector2d p = v.head<2>().cast<double>();
      for (const auto& ring : unentered) n += SignedDistanceToRing(ring, p) > 1.2;
    }
    return n;
  };
  if (!unentered.empty()) {
    const size_t dense_deep = deep_inside("mesh/dense.ply");
    const size_t building_deep = deep_inside("mesh/building.ply");
    const size_t objects_deep = deep_inside("mesh/objects.ply");
    const size_t points_deep = pc.trimmed_points ? deep_inside("points.ply") : 0;
    std::printf("[%s] vertices > 1.2 m inside the %zu unentered room(s): dense %zu, building %zu, "
                "objects %zu, points.ply %zu; trimmed cells %llu\n",
                pc.name, unentered.size(), dense_deep, building_deep, objects_deep, points_deep,
                (unsigned long long)job["counts"].value("trimmed_cells", uint64_t{0}));
    EXPECT_GT(dense_deep, 1000u);  // the scans did see into them
    EXPECT_EQ(building_deep, 0u);
    EXPECT_EQ(objects_deep, 0u);
    if (pc.trimmed_points) {
      EXPECT_EQ(points_deep, 0u);
      const uint64_t kept = job["counts"].value("points_kept", uint64_t{0});
      const uint64_t trimmed = job["counts"].value("points_trimmed", uint64_t{0});
      std::printf("[%s] points.ply: %llu points kept, %llu trimmed\n", pc.name,
                  (unsigned long long)kept, (unsigned long long)trimmed);
      EXPECT_GT(trimmed, 0u);  // the points seen deep inside them
      EXPECT_GT(kept, 20 * trimmed);  // seen through doors: a sliver of the walk's points
    }
  }
}

// Measured (docs/BENCHMARKS.md), objects re-carved at 3.125 cm (the default: half
// of 6.25 cm):
// - at the rig's 40 Hz (1° beams): found 95 %, false 1 %, wall cover 97.7 %, behind furniture
//   93.5 %. The misses: two shelves and a lamp in the room the walk never entered, two lamps
//   at IoU 0.28 and 0.47 (their 2 cm rods got few points);
// - at 10 Hz, a quarter of the frames (frames 10 cm apart at a walk): found 76 %, false 5 %.
//   Sparse frames leave lamps' rods without points and chairs' seats sheared along the walk.
//   Found 65 % before wedges stopped bridging occlusion edges (a desk's edge to the chair seat),
//   29 % before the scan points kept legs, rods and boards (§4.2.3) and stacked pieces were
//   grouped. Kept as a test so sparse scans do not get worse.
INSTANTIATE_TEST_SUITE_P(Presets, ObjectSegmentation,
                         // points.ply on the sparser case only (the other's is 18 M points).
                         ::testing::Values(PresetCase{"office", "office", 0, 40, 0.03125, 0.90,
                                                      0.10, 0.95, 0.8, false},
                                           PresetCase{"office_10hz", "office", 0, 10, 0.03125,
                                                      0.72, 0.10, 0.95, 0.8, true}),
                         [](const auto& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace carvemap
