// Levels of a real carved octree (docs/DESIGN.md §6 stages 1–3): the office2 preset (two levels) is
// simulated and carved in process, its boundary faces are found chunk by chunk
// (ChunkBoundaryFaces over 27-tile neighbourhoods), fitted into planar regions (§4.2.4) and
// split into levels (§5.2); the result is checked against gt/building.json.
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "services/levels/level_split.h"
#include "services/merge/tile_set.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/planar_regions.h"
#include "tests/support/carved_preset.h"

namespace carvemap {
namespace {

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double EnvOr(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != 0 ? std::atof(v) : fallback;
}

// Every boundary face of the tiles, chunk by chunk through the TileSet's cache.
absl::StatusOr<std::vector<BoundaryFace>> AllFaces(TileSet& set) {
  std::vector<BoundaryFace> faces;
  for (const ChunkKey& chunk : set.chunks()) {
    ChunkNeighbourhood hood;
    hood.grid = set.grid();
    hood.chunk = chunk;
    std::array<std::shared_ptr<const TileData>, 27> held;
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const ChunkKey c = chunk + ChunkKey(dx, dy, dz);
          if (!set.Contains(c)) continue;
          absl::StatusOr<std::shared_ptr<const TileData>> tile = set.Get(c);
          if (!tile.ok()) return tile.status();
          const int i = ChunkNeighbourhood::Index(dx, dy, dz);
          held[i] = *tile;
          hood.tiles[i] = held[i].get();
        }
      }
    }
    absl::StatusOr<std::vector<BoundaryFace>> chunk_faces = ChunkBoundaryFaces(hood);
    if (!chunk_faces.ok()) return chunk_faces.status();
    faces.insert(faces.end(), chunk_faces->begin(), chunk_faces->end());
  }
  return faces;
}

// DISABLED by default: it carves office2's whole walk (1144 s, back at the stairs with level 1
// done) at 10 Hz and 1°. Until the rays carried their share of the gaps (SamplingCovariance)
// that took 7–14 minutes here and thinner scans left the volume between floor and ceiling
// unobserved; since then the test took 105 s (carve 100 s) and gave floors
// +0.4 mm and +0.5 mm, ceilings −1.1 cm and −1.1 cm from gt/building.json (floors +2.6 cm
// before the isosurface took each leaf's p at the finest cell beside the face). CI checks the
// same through `carvemap run` on the thinner e2e scan (3 Hz, 2°): e2e_office2_outputs. Run
// it with --gtest_also_run_disabled_tests; CARVEMAP_LEVELS_{WALK_S,RATE_HZ,BEAM_DEG,RES_M}
// override the scan, CARVEMAP_LEVELS_REUSE_ROOT reuses a kept run (CARVEMAP_KEEP_TEST_TMPDIR)
// and CARVEMAP_LEVELS_VERBOSE lists the horizontal regions.
TEST(LevelSplitCarved, DISABLED_Office2GivesTwoLevelsWithinThreeCentimetres) {
  const auto t_start = std::chrono::steady_clock::now();
  testing::CarvedPresetOptions o;
  o.preset = "office2";
  o.seed = 1;
  // The walk through every room of both levels (each level's highest ceiling included), drift
  // off (range noise and clock jitter stay on).
  o.walk_s = EnvOr("CARVEMAP_LEVELS_WALK_S", 1144);  // back at the stairs, level 1 done
  o.rate_hz = EnvOr("CARVEMAP_LEVELS_RATE_HZ", 10);
  o.beam_step_deg = EnvOr("CARVEMAP_LEVELS_BEAM_DEG", 1);
  o.drift = false;
  o.resolution_m = EnvOr("CARVEMAP_LEVELS_RES_M", 0.0625);
  const std::string root = ::testing::TempDir() + "/office2";
  absl::StatusOr<testing::CarvedPreset> carved;
  if (const char* reuse = std::getenv("CARVEMAP_LEVELS_REUSE_ROOT"); reuse != nullptr && *reuse) {
    // Exploring: the tiles and truth of an earlier run (CARVEMAP_KEEP_TEST_TMPDIR=1).
    testing::CarvedPreset p;
    p.tiles_dir = std::string(reuse) + "/tiles";
    p.gt_dir = std::string(reuse) + "/sim/gt";
    p.grid = *OctreeGrid::FromResolution(o.resolution_m);
    carved = p;
  } else {
    carved = testing::CarvePreset(o, root);
  }
  ASSERT_TRUE(carved.ok()) << carved.status();
  const double carve_s = Seconds(t_start);

  auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<std::unique_ptr<TileSet>> set =
      TileSet::Open(carved->tiles_dir, carved->grid.resolution_m(), uint64_t{512} << 20);
  ASSERT_TRUE(set.ok()) << set.status();
  absl::StatusOr<std::vector<BoundaryFace>> faces = AllFaces(**set);
  ASSERT_TRUE(faces.ok()) << faces.status();
  const double faces_s = Seconds(t0);

  t0 = std::chrono::steady_clock::now();
  absl::StatusOr<PlanarRegionSet> regions = FitPlanarRegions(*faces, carved->grid, {});
  ASSERT_TRUE(regions.ok()) << regions.status();
  const double regions_s = Seconds(t0);

  absl::StatusOr<std::vector<Level>> levels = SplitLevelsFromRegions(regions->regions);
  ASSERT_TRUE(levels.ok()) << levels.status();

  int horizontal = 0;
  for (const PlanarRegion& r : regions->regions) {
    horizontal += std::abs(r.normal.z()) > std::cos(5 * M_PI / 180) && r.area_m2 >= 2.0;
  }
  std::printf("office2: %zu chunks, %zu faces (%.1f s), %zu flood-fill groups, %zu grown, "
              "%zu regions (%.1f s), %d horizontal regions >= 2 m2; carve %.1f s (walk %.0f s)\n",
              (*set)->chunks().size(), faces->size(), faces_s, regions->flood_fill_groups,
              regions->grown_regions, regions->regions.size(), regions_s, horizontal, carve_s,
              carved->simulation.duration_s);
  if (std::getenv("CARVEMAP_LEVELS_VERBOSE") != nullptr) {
    for (const PlanarRegion& r : regions->regions) {
      if (std::abs(r.normal.z()) > std::cos(5 * M_PI / 180) && r.area_m2 >= 1.0) {
        std::printf("  horizontal %s z %.4f area %.2f faces %zu\n",
                    r.normal.z() > 0 ? "floor  " : "ceiling", r.centroid.z(), r.area_m2,
                    r.faces.size());
      }
    }
  }
  std::printf("levels.json: %s\n", LevelsToJson(*levels).dump().c_str());

  std::ifstream in(carved->gt_dir + "/building.json");
  ASSERT_TRUE(in.good()) << carved->gt_dir;
  const nlohmann::json truth = nlohmann::json::parse(in);
  const nlohmann::json& gt_levels = truth.at("levels");
  ASSERT_EQ(gt_levels.size(), 2u);
  ASSERT_EQ(levels->size(), gt_levels.size());
  for (size_t i = 0; i < levels->size(); ++i) {
    const Level& l = (*levels)[i];
    const double gt_floor = gt_levels[i].at("floor_z").get<double>();
    const double gt_ceiling = gt_levels[i].at("ceiling_z").get<double>();
    std::printf("level %zu: floor %.4f (truth %.4f, %+.4f)  ceiling %.4f (truth %.4f, %+.4f)  "
                "split [%.3f, %.3f)\n",
                i, l.floor_z, gt_floor, l.floor_z - gt_floor, l.ceiling_z, gt_ceiling,
                l.ceiling_z - gt_ceiling, l.split_z_low, l.split_z_high);
    EXPECT_EQ(l.index, int(i));
    EXPECT_NEAR(l.floor_z, gt_floor, 0.03) << "level " << i;
    EXPECT_NEAR(l.ceiling_z, gt_ceiling, 0.03) << "level " << i;
  }
  // The split lies in the slab between the levels.
  EXPECT_GT((*levels)[0].split_z_high, gt_levels[0].at("ceiling_z").get<double>());
  EXPECT_LT((*levels)[0].split_z_high, gt_levels[1].at("floor_z").get<double>());
}

}  // namespace
}  // namespace carvemap
