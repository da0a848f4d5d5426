#include "services/merge/merge_job.h"

#include <chrono>
#include <filesystem>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "services/floorplan/floorplan_export.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/octree_wall_samples.h"
#include "services/levels/level_split.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/tile_set.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh.h"
#include "services/mesh/planar_regions.h"
#include "storage/atomic_file.h"
#include "storage/ply_io.h"
#include "storage/scan_reader.h"

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


// The recorded system path of the job's scan (DESIGN §3 /path): the scanner positions of the
// floor plans (§3.3.1). Small (poses, not rays), so read whole.
absl::StatusOr<std::vector<Eigen::Vector3d>> ReadPathPositions(const std::string& scan_path) {
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path);
  if (!reader.ok()) return reader.status();
  std::vector<Eigen::Vector3d> positions;
  positions.reserve((*reader)->path().size());
  for (const PathRecord& r : (*reader)->path()) positions.emplace_back(r.x, r.y, r.z);
  return positions;
}

// Floor plans per level (DESIGN §6 stages 4–5; seed §5.3, §3.3) ➜ level_<k>/floorplan.geojson,
// floorplan.svg, extruded.ply. A level whose plan cannot be made is not fatal: the other outputs
// stand and job.json says why under "warnings".
absl::Status FloorPlanStage(const MergeOptions& options, TileSet& tiles,
                            const std::vector<BoundaryFace>& faces,
                            const PlanarRegionSet& regions, const std::vector<Level>& levels,
                            const fs::path& out, nlohmann::json& job, nlohmann::json& counts,
                            nlohmann::json& timings, std::vector<std::string>& outputs,
                            std::vector<std::string>& warnings,
                            const MergeProgressCallback& progress) {
  if (options.scan_path.empty()) {
    warnings.push_back("floorplan: no scan given, so no scanner path for the lines of sight; "
                       "no floor plans");
    return absl::OkStatus();
  }
  if (levels.empty()) {
    warnings.push_back("floorplan: no levels found; no floor plans");
    return absl::OkStatus();
  }
  absl::StatusOr<std::vector<Eigen::Vector3d>> path = ReadPathPositions(options.scan_path);
  if (!path.ok()) return path.status();
  const OctreeLabelFn label_at = [&tiles](const Eigen::Vector3d& x) -> absl::StatusOr<OctreeLabel> {
    absl::StatusOr<LeafQuery> q = tiles.Query(x);
    if (!q.ok()) return q.status();
    if (!q->stored || !q->stats.observed()) return OctreeLabel::kUnobserved;
    return q->stats.interior() ? OctreeLabel::kInterior : OctreeLabel::kExterior;
  };
  nlohmann::json rooms = nlohmann::json::array();
  size_t total_samples = 0, total_rooms = 0;
  double seconds_samples = 0, seconds_plan = 0;
  for (size_t k = 0; k < levels.size(); ++k) {
    if (absl::Status s = ReportMergeProgress(progress, "floorplan", k, levels.size()); !s.ok()) {
      return s;
    }
    Clock::time_point t0 = Clock::now();
    OctreeWallSampleReport sample_report;
    absl::StatusOr<WallSampleSet> samples =
        OctreeWallSamples(faces, regions, tiles.grid(), levels[k], *path, label_at,
                          OctreeWallSampleOptions{}, &sample_report);
    if (!samples.ok()) {
      if (absl::IsInvalidArgument(samples.status()) || absl::IsFailedPrecondition(samples.status())) {
        warnings.push_back(absl::StrCat("floorplan level ", k, ": ", samples.status().message()));
        continue;
      }
      return samples.status();  // reading the tiles failed: the merge fails
    }
    seconds_samples += SecondsSince(t0);
    total_samples += samples->samples.size();
    t0 = Clock::now();
    absl::StatusOr<LevelFloorPlan> plan =
        BuildLevelFloorPlan(*samples, static_cast<int>(k), FloorPlanOptions{});
    seconds_plan += SecondsSince(t0);
    if (!plan.ok()) {
      warnings.push_back(absl::StrCat("floorplan level ", k, ": ", plan.status().message()));
      continue;
    }
    const std::string level_name = absl::StrCat("level_", k);
    const fs::path level_dir = out / level_name;
    if (absl::Status s = WriteFloorPlanFiles(level_dir.string(), plan->plan, plan->outline);
        !s.ok()) {
      return s;
    }
    if (absl::Status s =
            WriteExtrudedPly((level_dir / "extruded.ply").string(), plan->extruded);
        !s.ok()) {
      return s;
    }
    for (const char* name : {"floorplan.geojson", "floorplan.svg", "extruded.ply"}) {
      outputs.push_back(absl::StrCat(level_name, "/", name));
    }
    for (auto& room : RoomsToJson(*plan)) rooms.push_back(room);
    total_rooms += plan->plan.rooms.size();
    nlohmann::json& lc = counts["floorplan_levels"][level_name];
    lc = {{"wall_regions", sample_report.wall_regions},
          {"wall_samples", samples->samples.size()},
          {"samples_with_poses", sample_report.samples_with_poses},
          {"filled_behind_occlusion", sample_report.filled_behind_occlusion},
          {"poses", sample_report.poses},
          {"interior_triangles", plan->labeling.interior_triangles},
          {"initial_seeds", plan->labeling.initial_seeds},
          {"removed_rooms", plan->labeling.removed_rooms},
          {"rooms", plan->plan.rooms.size()},
          {"extruded_triangles", plan->extruded.triangles.size()}};
  }
  job["rooms"] = rooms;
  counts["wall_samples"] = total_samples;
  counts["rooms"] = total_rooms;
  timings["merge.wall_samples"] = seconds_samples;
  timings["merge.floorplan"] = seconds_plan;
  return absl::OkStatus();
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

  // floor plans (stages 4–5, §5.3, §3.3) ➜ level_<k>/floorplan.geojson, floorplan.svg,
  // extruded.ply; job.json "rooms"
  if (absl::Status s = FloorPlanStage(options, tiles, *faces, *regions, levels->levels, out, job,
                                      counts, timings, outputs, warnings, progress);
      !s.ok()) {
    return InStage("floorplan", s);
  }

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
  summary->num_rooms = counts.value("rooms", uint64_t{0});
  summary->warnings = warnings;
  summary->seconds_total = SecondsSince(t_start);
  return summary;
}

}  // namespace carvemap
