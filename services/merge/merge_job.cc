#include "services/merge/merge_job.h"

#include <chrono>
#include <filesystem>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "services/levels/level_split.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/tile_set.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh.h"
#include "services/mesh/planar_regions.h"
#include "storage/atomic_file.h"
#include "storage/ply_io.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

absl::Status InStage(const char* stage, const absl::Status& s) {
  if (s.ok() || absl::IsCancelled(s)) return s;
  return absl::Status(s.code(), absl::StrCat("merge ", stage, ": ", s.message()));
}

// Adapts a stage's (done, total) progress to the merge's callback.
ChunkProgressFn StageProgress(const MergeProgressCallback& progress, const char* stage) {
  if (!progress) return nullptr;
  return [&progress, stage](uint64_t done, uint64_t total) {
    return progress(MergeProgress{stage, done, total});
  };
}


}  // namespace

absl::StatusOr<MergeSummary> RunMerge(const MergeOptions& options,
                                      const MergeProgressCallback& progress) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (!options.meshes) return MergeFirstOutputs(options, progress);
  const Clock::time_point t_start = Clock::now();

  absl::StatusOr<std::unique_ptr<TileSet>> opened =
      TileSet::Open(options.tiles_dir, options.resolution_m, options.cache_budget_bytes);
  if (!opened.ok()) return opened.status();
  TileSet& tiles = **opened;
  const OctreeGrid grid = tiles.grid();
  const fs::path out(options.output_dir);
  std::error_code ec;
  fs::create_directories(out / "mesh", ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat((out / "mesh").string(), ": cannot create: ", ec.message()));
  }

  nlohmann::json job = options.job.is_null() ? nlohmann::json::object() : options.job;
  nlohmann::json timings = nlohmann::json::object();
  nlohmann::json counts = nlohmann::json::object();
  std::vector<std::string> outputs;
  std::vector<std::string> warnings;

  // boundary faces (stage 1)
  Clock::time_point t0 = Clock::now();
  absl::StatusOr<std::vector<BoundaryFace>> faces =
      CollectBoundaryFaces(tiles, StageProgress(progress, "boundary_faces"));
  if (!faces.ok()) return InStage("boundary_faces", faces.status());
  double face_area = 0;
  for (const BoundaryFace& f : *faces) face_area += f.area_m2();
  counts["boundary_faces"] = faces->size();
  counts["boundary_area_m2"] = face_area;
  timings["merge.boundary_faces"] = SecondsSince(t0);

  // planar regions (stage 2, §4.2.4)
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "planar_regions", 0, 1); !s.ok()) return s;
  absl::StatusOr<PlanarRegionSet> regions = FitPlanarRegions(*faces, grid, PlanarRegionOptions{});
  if (!regions.ok()) return InStage("planar_regions", regions.status());
  counts["planar_regions"] = regions->regions.size();
  timings["merge.planar_regions"] = SecondsSince(t0);

  // levels (stage 3, §5.2) ➜ levels.json. The point-height fallback of §2.5 needs the scan,
  // which the merge does not read; without horizontal regions there is one level_0.
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "levels", 0, 1); !s.ok()) return s;
  absl::StatusOr<LevelSplit> levels = SplitLevels(regions->regions, nullptr);
  if (!levels.ok()) return InStage("levels", levels.status());
  MergeOptions first = options;
  first.levels.clear();
  for (const Level& level : levels->levels) {
    first.levels.push_back(TopdownZRange{level.split_z_low, level.split_z_high});
  }
  if (absl::Status s = WriteFileAtomically(
          (out / "levels.json").string(),
          [&](std::ostream& o) { o << LevelsToJson(levels->levels).dump(2) << "\n"; });
      !s.ok()) {
    return InStage("levels", s);
  }
  outputs.push_back("levels.json");
  counts["levels"] = levels->levels.size();
  job["levels_source"] = levels->source;
  if (levels->levels.empty()) {
    warnings.push_back("levels: no floor found among the horizontal regions; level_0 covers the "
                       "whole height");
  }
  timings["merge.levels"] = SecondsSince(t0);

  // dense mesh (§4.3.3) ➜ mesh/dense.ply; scoped: the mesh can be large and is not kept.
  t0 = Clock::now();
  uint64_t dense_triangles = 0;
  {
    absl::StatusOr<DenseMeshResult> dense =
        BuildDenseMesh(tiles, StageProgress(progress, "dense_mesh"));
    if (!dense.ok()) return InStage("dense_mesh", dense.status());
    if (absl::Status s = WritePly((out / "mesh" / "dense.ply").string(), dense->mesh); !s.ok()) {
      return InStage("dense_mesh", s);
    }
    dense_triangles = dense->mesh.triangles.size();
    counts["dense_vertices"] = dense->mesh.vertices.size();
    counts["dense_triangles"] = dense_triangles;
  }
  outputs.push_back("mesh/dense.ply");
  timings["merge.dense_mesh"] = SecondsSince(t0);

  // planar mesh (§4.3.3, eq 4.9, §4.2.5) ➜ mesh/building.ply. For now it holds the planar mesh
  // of everything (issue 4); segmentation (§5.6) will split furniture off.
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "planar_mesh", 0, 1); !s.ok()) return s;
  uint64_t building_triangles = 0;
  absl::StatusOr<PlanarMesh> planar = BuildPlanarMesh(*faces, *regions, grid);
  if (planar.ok()) {
    const MeshCheck check = CheckMesh(planar->mesh);
    if (!check.watertight()) {
      warnings.push_back("planar_mesh: not watertight (" + check.ToString() + ")");
    }
    if (absl::Status s = WritePly((out / "mesh" / "building.ply").string(), planar->mesh,
                                  &planar->triangle_region, "region");
        !s.ok()) {
      return InStage("planar_mesh", s);
    }
    outputs.push_back("mesh/building.ply");
    building_triangles = planar->mesh.triangles.size();
    counts["building_vertices"] = planar->mesh.vertices.size();
    counts["building_triangles"] = building_triangles;
    counts["building_watertight"] = check.watertight();
  } else if (absl::IsCancelled(planar.status())) {
    return planar.status();
  } else {
    // Not fatal: the other outputs stand; job.json says why building.ply is missing.
    warnings.push_back(std::string(planar.status().message()));
  }
  timings["merge.planar_mesh"] = SecondsSince(t0);

  // The first outputs write job.json last, with everything above in it.
  for (auto& [key, value] : counts.items()) job["counts"][key] = value;
  for (auto& [key, value] : timings.items()) job["timings_s"][key] = value;
  nlohmann::json listed = job.contains("outputs") && job["outputs"].is_array()
                              ? job["outputs"]
                              : nlohmann::json::array();
  for (const std::string& o : outputs) listed.push_back(o);
  job["outputs"] = listed;
  if (!warnings.empty()) job["warnings"] = warnings;
  first.job = std::move(job);
  absl::StatusOr<MergeSummary> summary = MergeFirstOutputs(first, progress);
  if (!summary.ok()) return summary.status();
  summary->num_boundary_faces = faces->size();
  summary->num_planar_regions = regions->regions.size();
  summary->num_levels = levels->levels.size();
  summary->dense_triangles = dense_triangles;
  summary->building_triangles = building_triangles;
  summary->warnings = warnings;
  summary->seconds_total = SecondsSince(t_start);
  return summary;
}

}  // namespace carvemap
