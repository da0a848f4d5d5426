// RunMerge: every output of the merge from a tiles directory whose geometry is known exactly
// (a box room: interior leaves inside a one-leaf exterior shell, across chunk borders).
#include "services/merge/merge_job.h"

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "services/merge/merge_test_util.h"
#include "services/mesh/mesh_checks.h"
#include "storage/ply_io.h"
#include "storage/tile_store.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using carvemap::testing::FreshDir;
using carvemap::testing::StatsWithP;

constexpr int kDepth = 4;  // 12.5 cm leaves, 16 per chunk side

// Interior finest cells [lo, hi) (global leaf keys) except those `solid` picks, wrapped in a
// one-cell exterior shell; written as one tile per chunk. Returns the tiles dir.
std::string WriteBoxRoom(const std::string& dir, const LeafKey& lo, const LeafKey& hi,
                         const std::function<bool(const LeafKey&)>& solid = nullptr) {
  OctreeGrid grid;
  grid.chunk_depth = kDepth;
  const int n = grid.leaves_per_side();
  std::map<ChunkKey, TileData, ChunkKeyLess> tiles;
  for (int x = lo.x() - 1; x < hi.x() + 1; ++x)
    for (int y = lo.y() - 1; y < hi.y() + 1; ++y)
      for (int z = lo.z() - 1; z < hi.z() + 1; ++z) {
        const LeafKey key(x, y, z);
        const bool inside = (key.array() >= lo.array()).all() &&
                            (key.array() < hi.array()).all() && !(solid && solid(key));
        const ChunkKey chunk = ChunkOfLeaf(grid, key);
        TileData& tile = tiles[chunk];
        tile.chunk = chunk;
        tile.grid = grid;
        tile.leaves.push_back(
            TileLeaf{ChunkNode{key - chunk * n, kDepth}, StatsWithP(inside ? 0.9 : 0.1)});
      }
  fs::create_directories(dir);
  for (auto& [chunk, tile] : tiles) {
    absl::StatusOr<std::string> written = WriteTile(dir, tile);
    EXPECT_TRUE(written.ok()) << written.status();
  }
  return dir;
}

nlohmann::json ReadJson(const std::string& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

// A memory budget the planar regions cannot fit: the merge stops before them, says why, and
// leaves no job.json (whose presence means the merge finished), not even an earlier merge's.
TEST(RunMerge, MemoryBudgetTooSmallFailsBeforeThePlanarRegions) {
  const std::string root = FreshDir();
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", LeafKey(-8, -4, 0), LeafKey(24, 20, 20));
  options.output_dir = root + "/out";
  options.memory_budget_bytes = uint64_t{64} << 30;  // one the merge fits: as without one
  ASSERT_TRUE(RunMerge(options).ok());
  ASSERT_TRUE(fs::exists(options.output_dir + "/job.json"));
  options.memory_budget_bytes = uint64_t{1} << 20;  // less than the process itself
  std::vector<std::string> stages;
  absl::StatusOr<MergeSummary> s = RunMerge(options, [&](const MergeProgress& p) {
    if (stages.empty() || stages.back() != p.stage) stages.push_back(p.stage);
    return true;
  });
  ASSERT_EQ(s.status().code(), absl::StatusCode::kResourceExhausted) << s.status();
  const std::string m(s.status().message());
  EXPECT_NE(m.find("merge planar_regions: the levels' planar regions (a slab of heights): "
                   "3776 boundary faces need about"),
            std::string::npos)
      << m;
  EXPECT_NE(m.find("over its memory budget of 1 MiB"), std::string::npos) << m;
  EXPECT_EQ(stages, (std::vector<std::string>{"pocket_fill", "boundary_faces"}));
  EXPECT_FALSE(fs::exists(options.output_dir + "/job.json"));
  // The dense mesh had started beside the planar regions: stopped, and no file of it left
  // (not even the first merge's).
  EXPECT_FALSE(fs::exists(options.output_dir + "/mesh/dense.ply"));
}

TEST(RunMerge, BoxRoomGivesEveryOutput) {
  const std::string root = FreshDir();
  // 4 m × 3 m × 2.5 m from (−1, −0.5, 0): crosses chunk borders in x and y.
  const LeafKey lo(-8, -4, 0), hi(24, 20, 20);
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", lo, hi);
  options.output_dir = root + "/out";
  std::vector<std::string> stages;
  absl::StatusOr<MergeSummary> s = RunMerge(options, [&](const MergeProgress& p) {
    if (stages.empty() || stages.back() != p.stage) stages.push_back(p.stage);
    return true;
  });
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(stages, (std::vector<std::string>{"pocket_fill", "boundary_faces", "planar_regions",
                                              "levels", "dense_mesh", "planar_mesh", "index",
                                              "octree_bt", "topdown_png", "job_json"}));
  const double res = 0.125;
  // 6 walls of the box: 2(32·24 + 32·20 + 24·20) faces.
  EXPECT_EQ(s->num_boundary_faces, 2u * (32 * 24 + 32 * 20 + 24 * 20));
  // The levels' six; no scan, so no floor plan and no level's own regions.
  EXPECT_EQ(s->num_planar_regions, 6u);
  EXPECT_EQ(s->num_levels, 1u);
  // Tiles without a scan: no path for the floor plans' lines of sight, so no plan to segment
  // objects against; job.json says both.
  ASSERT_EQ(s->warnings.size(), 2u);
  EXPECT_NE(s->warnings[0].find("floorplan: no scan given"), std::string::npos) << s->warnings[0];
  EXPECT_NE(s->warnings[1].find("segmentation: no floor plan"), std::string::npos)
      << s->warnings[1];

  // levels.json (docs/DESIGN.md §7): the floor and ceiling are the isosurfaces of Fig 4.9, between
  // the shell's and the room's leaf centres: p 0.1 → 0.9 crosses 0.5 halfway, on the leaf border.
  const nlohmann::json levels = ReadJson(options.output_dir + "/levels.json");
  ASSERT_EQ(levels.size(), 1u);
  EXPECT_EQ(levels[0]["index"], 0);
  EXPECT_NEAR(levels[0]["floor_z"].get<double>(), lo.z() * res, 0.02);
  EXPECT_NEAR(levels[0]["ceiling_z"].get<double>(), hi.z() * res, 0.02);
  EXPECT_LT(levels[0]["split_z"].get<double>(), lo.z() * res);

  // Meshes: watertight, on the box.
  absl::StatusOr<PlyMesh> dense = ReadPly(options.output_dir + "/mesh/dense.ply");
  ASSERT_TRUE(dense.ok()) << dense.status();
  EXPECT_TRUE(CheckMesh(dense->mesh).watertight()) << CheckMesh(dense->mesh).ToString();
  EXPECT_EQ(dense->mesh.triangles.size(), s->dense_triangles);
  absl::StatusOr<PlyMesh> building = ReadPly(options.output_dir + "/mesh/building.ply");
  ASSERT_TRUE(building.ok()) << building.status();
  EXPECT_TRUE(CheckMesh(building->mesh).watertight()) << CheckMesh(building->mesh).ToString();
  ASSERT_EQ(building->face_values.size(), 1u);
  EXPECT_EQ(building->face_values[0].first, "region");
  // The planar mesh is far lighter than the dense one (the goal: ≤ 10 %).
  EXPECT_LE(10 * building->mesh.triangles.size(), dense->mesh.triangles.size());
  for (const Eigen::Vector3f& v : building->mesh.vertices) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(v[a], lo[a] * res - 0.02);
      EXPECT_LE(v[a], hi[a] * res + 0.02);
    }
  }

  // job.json, written last, lists every output and the stage counts.
  const nlohmann::json job = ReadJson(options.output_dir + "/job.json");
  for (const char* o : {"octree.bt", "job.json", "levels.json", "mesh/dense.ply",
                        "mesh/building.ply", "level_0/topdown.png", "level_0/topdown.json",
                        "level_0/occupancy.pgm", "level_0/occupancy.yaml"}) {
    EXPECT_NE(std::find(job["outputs"].begin(), job["outputs"].end(), o), job["outputs"].end())
        << o;
    EXPECT_TRUE(fs::exists(options.output_dir + "/" + o)) << o;
  }
  EXPECT_EQ(job["counts"]["planar_regions"], 6);
  EXPECT_EQ(job["counts"]["level_planar_regions"], 6);
  EXPECT_EQ(job["counts"]["building_watertight"], true);
  // A box's six walls are each re-triangulated in their plane.
  EXPECT_EQ(job["counts"]["building_regions_not_retriangulated"], 0);
  EXPECT_EQ(job["counts"]["building_triangles_not_retriangulated"], 0);
  EXPECT_EQ(job["levels_source"], "regions");
  const nlohmann::json topdown = ReadJson(options.output_dir + "/level_0/topdown.json");
  EXPECT_TRUE(topdown.contains("z_range"));
}

// The levels (and floor plans) and mesh/building.ply get regions grown their own way: a floor
// with one-leaf bumps (carving speckle) keeps each bump's four sides as regions of their own
// for the levels, while the building mesh's regions (PlanarRegionOptions::mesh_growth) take
// them into the floor: six regions, the box's sides, and fewer triangles.
TEST(RunMerge, BuildingMeshRegionsTakeInOneLeafBumps) {
  const std::string root = FreshDir();
  const LeafKey lo(-8, -4, 0), hi(24, 20, 20);
  size_t bumps = 0;
  auto bump = [&](const LeafKey& k) {
    return k.z() == lo.z() && (k.x() - lo.x()) % 5 == 2 && (k.y() - lo.y()) % 5 == 2;
  };
  for (int x = lo.x(); x < hi.x(); ++x)
    for (int y = lo.y(); y < hi.y(); ++y) bumps += bump(LeafKey(x, y, lo.z()));
  ASSERT_GT(bumps, 20u);
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", lo, hi, bump);
  options.output_dir = root + "/out";
  absl::StatusOr<MergeSummary> s = RunMerge(options);
  ASSERT_TRUE(s.ok()) << s.status();
  const nlohmann::json job = ReadJson(options.output_dir + "/job.json");
  // Default growth (the levels' regions): the bumps' sides are at 90° to the floor and stay out
  // of it.
  EXPECT_GT(job["counts"]["level_planar_regions"].get<size_t>(), 6 + bumps);
  EXPECT_EQ(s->num_levels, 1u);
  EXPECT_EQ(job["counts"]["building_planar_regions"], 6);
  EXPECT_EQ(job["counts"]["building_watertight"], true);
  absl::StatusOr<PlyMesh> building = ReadPly(options.output_dir + "/mesh/building.ply");
  ASSERT_TRUE(building.ok()) << building.status();
  EXPECT_TRUE(CheckMesh(building->mesh).watertight()) << CheckMesh(building->mesh).ToString();
  EXPECT_EQ(building->mesh.triangles.size(), s->building_triangles);
  EXPECT_LE(10 * building->mesh.triangles.size(), s->dense_triangles);
}

TEST(RunMerge, CancelledMidwayWritesNoJobJson) {
  const std::string root = FreshDir();
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", LeafKey(0, 0, 0), LeafKey(16, 16, 16));
  options.output_dir = root + "/out";
  absl::StatusOr<MergeSummary> s =
      RunMerge(options, [](const MergeProgress& p) { return p.stage != "dense_mesh"; });
  EXPECT_EQ(s.status().code(), absl::StatusCode::kCancelled);
  EXPECT_FALSE(fs::exists(options.output_dir + "/job.json"));
  EXPECT_FALSE(fs::exists(options.output_dir + "/mesh/dense.ply"));
}

TEST(RunMerge, UnknownFloorPlanMethodIsRefusedBeforeAnyOutput) {
  const std::string root = FreshDir();
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", LeafKey(0, 0, 0), LeafKey(16, 16, 16));
  options.output_dir = root + "/out";
  options.floorplan_method = "powercrust";
  absl::StatusOr<MergeSummary> s = RunMerge(options);
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("powercrust"), std::string::npos) << s.status();
  EXPECT_FALSE(fs::exists(options.output_dir + "/job.json"));
}

TEST(RunMerge, NoMeshesGivesTheFirstOutputsOnly) {
  const std::string root = FreshDir();
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", LeafKey(0, 0, 0), LeafKey(16, 16, 16));
  options.output_dir = root + "/out";
  options.meshes = false;
  absl::StatusOr<MergeSummary> s = RunMerge(options);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_TRUE(fs::exists(options.output_dir + "/job.json"));
  EXPECT_FALSE(fs::exists(options.output_dir + "/mesh"));
  EXPECT_FALSE(fs::exists(options.output_dir + "/levels.json"));
}

// Points asked for without a scan (a merge of tiles alone): the other outputs do not need them,
// so the job goes on and job.json says why there is no points.ply.
TEST(RunMerge, PointsWithoutAScanAreAWarning) {
  const std::string root = FreshDir();
  MergeOptions options;
  options.tiles_dir = WriteBoxRoom(root + "/tiles", LeafKey(0, 0, 0), LeafKey(16, 16, 16));
  options.output_dir = root + "/out";
  options.trimmed_points = true;
  absl::StatusOr<MergeSummary> s = RunMerge(options);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_NE(std::find(s->warnings.begin(), s->warnings.end(),
                      "trimmed_points: no scan given, so no points.ply"),
            s->warnings.end());
  EXPECT_FALSE(fs::exists(options.output_dir + "/points.ply"));
  EXPECT_TRUE(fs::exists(options.output_dir + "/mesh/building.ply"));
}

}  // namespace
}  // namespace carvemap
