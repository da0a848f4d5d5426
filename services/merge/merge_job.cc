#include "services/merge/merge_job.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "absl/cleanup/cleanup.h"
#include "absl/strings/str_cat.h"
#include "services/floorplan/export/building_ifc.h"
#include "services/floorplan/export/floorplan_export.h"
#include "services/floorplan/floorplan_pipeline.h"
#include "services/floorplan/samples/octree_wall_samples.h"
#include "services/floorplan/samples/scan_cloud_stream.h"
#include "services/levels/level_regions.h"
#include "services/levels/level_split.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/face_store.h"
#include "services/merge/memory_budget.h"
#include "services/merge/model_glb.h"
#include "services/merge/object_files.h"
#include "services/merge/pocket_tiles.h"
#include "services/merge/segment_tiles.h"
#include "services/merge/tile_set.h"
#include "services/merge/trimmed_points.h"
#include "services/mesh/level_cut.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh.h"
#include "services/mesh/planar_regions.h"
#include "services/mesh/self_intersections.h"
#include "services/segment/object_meshes.h"
#include "services/segment/plan_volume.h"
#include "services/system/process_memory.h"
#include "services/system/usable_cpus.h"
#include "storage/atomic_file.h"
#include "storage/hdf5_lock.h"
#include "storage/ply_io.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// `mesh`'s self-intersections into counts["<name>_self_intersections"] (the sum over calls of
// one name; "<name>_triangles_not_tested" when some could not be), timed under
// merge.self_intersections, with a warning when any (`warnings` null: the caller warns once
// for many meshes): a watertight mesh that crosses itself is not a valid solid. Returns the
// pairs found. `threads` for a large mesh (the dense one).
// job.json's counts of a mesh's self-intersections (`name`_self_intersections, summed over the
// meshes of that name), the time they took, and a warning when there are any.
void RecordSelfIntersections(const SelfIntersections& s, const std::string& name, double seconds,
                             nlohmann::json& counts, nlohmann::json& timings,
                             std::vector<std::string>* warnings) {
  const std::string key = name + "_self_intersections";
  counts[key] = counts.value(key, uint64_t{0}) + s.pairs;
  if (s.unchecked > 0) {
    const std::string untested = name + "_triangles_not_tested";
    counts[untested] = counts.value(untested, uint64_t{0}) + s.unchecked;
  }
  if (s.pairs > 0 && warnings != nullptr) {
    warnings->push_back(absl::StrCat(
        name, ": ", s.pairs, " pairs of triangles cross each other (self-intersections)"));
  }
  timings["merge.self_intersections"] = timings.value("merge.self_intersections", 0.0) + seconds;
}

uint64_t CountSelfIntersectionsInto(const TriangleMesh& mesh, const std::string& name,
                                    nlohmann::json& counts, nlohmann::json& timings,
                                    std::vector<std::string>* warnings, int threads = 1) {
  const Clock::time_point t0 = Clock::now();
  const SelfIntersections s = CountSelfIntersections(mesh, threads);
  RecordSelfIntersections(s, name, SecondsSince(t0), counts, timings, warnings);
  return s.pairs;
}

absl::Status InStage(const char* stage, const absl::Status& s) {
  if (s.ok() || absl::IsCancelled(s)) return s;
  return absl::Status(s.code(), absl::StrCat("merge ", stage, ": ", s.message()));
}

// CheckPlanarMemory against what this process holds now.
// `settle`, when given, waits for the dense mesh made beside the stage (RunMerge).
absl::Status CheckPlanarMemory(const MergeOptions& options, std::string_view what, size_t num_faces,
                               const std::function<void()>& settle = nullptr) {
  return carvemap::CheckPlanarMemory(
      what, num_faces, [] { return ReadProcessStatus().resident_bytes; },
      options.memory_budget_bytes, settle);
}

int MergeThreads(const MergeOptions& options) {
  return options.threads > 0 ? options.threads
                             : UsableCpus();
}

// Adapts a stage's (done, total) progress to the merge's callback.
ChunkProgressFn StageProgress(const MergeProgressCallback& progress, const char* stage) {
  if (!progress) return nullptr;
  return [&progress, stage](uint64_t done, uint64_t total) {
    return progress(MergeProgress{stage, done, total});
  };
}

// `read` on the job's scan opened without its path held (the readers read it in blocks), under
// the process's HDF5 lock: the dense mesh reads tiles on another thread meanwhile (RunMerge).
template <typename Read>
auto WithScanPath(const std::string& scan_path, double world_yaw_rad, Read read)
    -> decltype(read(std::declval<ScanReader&>())) {
  std::lock_guard<std::mutex> lock(Hdf5Lock());
  ScanReader::OpenOptions open;
  open.path_rows = ScanReader::PathRows::kNone;
  open.world_yaw_rad = world_yaw_rad;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path, open);
  if (!reader.ok()) return reader.status();
  return read(**reader);
}

// The recorded system path of the job's scan (docs/DESIGN.md §3 /path): the scanner positions of
// the floor plans (§3.3.1), 24 bytes per pose; the poses' other fields are not read.
absl::StatusOr<std::vector<Eigen::Vector3d>> ReadPathPositions(const std::string& scan_path,
                                                               double world_yaw_rad) {
  return WithScanPath(scan_path, world_yaw_rad, [](ScanReader& r) { return r.PathPositions(); });
}

// How far the scan's path may be off horizontally (ScanReader::HorizontalPositionSigma), m;
// nullopt without /path_cov. A turn about the vertical keeps it.
absl::StatusOr<std::optional<double>> ReadPathSigma(const std::string& scan_path) {
  return WithScanPath(scan_path, 0.0, [](ScanReader& r) { return r.HorizontalPositionSigma(); });
}

// Before a planar fit, which reads no tile: the cached tiles, and the small blocks the last fit
// freed (millions of them, resident until given back), go back to the system.
void ClearForFit(TileSet& tiles) {
  tiles.ReleaseCache();
  ReturnFreedMemory();
}

// The boundary faces of `tiles` in a FaceStore at `path`, sorted by height (face_store.h): the
// stages after read them a slab or a level at a time.
absl::StatusOr<std::unique_ptr<FaceStore>> StoreBoundaryFaces(TileSet& tiles,
                                                              const std::string& path,
                                                              const ChunkProgressFn& progress,
                                                              int threads) {
  absl::StatusOr<std::unique_ptr<FaceStore>> store = FaceStore::Create(path, tiles.grid());
  if (!store.ok()) return store.status();
  if (absl::Status s = CollectBoundaryFacesInto(
          tiles, [&](std::vector<BoundaryFace>&& f) { return (*store)->Add(f); }, progress,
          threads);
      !s.ok()) {
    return s;
  }
  if (absl::Status s = (*store)->Finish(); !s.ok()) return s;
  return store;
}

// Floor plans per level (docs/DESIGN.md §6 stages 4–5; §5.3, §3.3) ➜ level_<k>/floorplan.geojson,
// floorplan.svg, floorplan.dxf, extruded.ply. A level whose plan cannot be made is not fatal: the
// other outputs stand and job.json says why under "warnings".
absl::Status FloorPlanStage(const MergeOptions& options, TileSet& tiles, const FaceStore& faces,
                            const std::vector<Level>& levels, const fs::path& out,
                            nlohmann::json& job, nlohmann::json& counts, nlohmann::json& timings,
                            std::vector<std::string>& outputs, std::vector<std::string>& warnings,
                            const MergeProgressCallback& progress,
                            const std::function<void()>& settle_memory,
                            std::vector<std::pair<Level, FloorPlan>>& plans) {
  if (options.scan_path.empty()) {
    warnings.push_back("floorplan: no scan given, so no scanner path for the lines of sight; "
                       "no floor plans");
    return absl::OkStatus();
  }
  if (levels.empty()) {
    warnings.push_back("floorplan: no levels found; no floor plans");
    return absl::OkStatus();
  }
  absl::StatusOr<std::vector<Eigen::Vector3d>> path =
      ReadPathPositions(options.scan_path, options.world_yaw_rad);
  if (!path.ok()) return path.status();
  const OctreeLabelFn label_at = [&tiles](const Eigen::Vector3d& x) -> absl::StatusOr<OctreeLabel> {
    absl::StatusOr<LeafQuery> q = tiles.Query(x);
    if (!q.ok()) return q.status();
    if (!q->stored || !q->stats.observed()) return OctreeLabel::kUnobserved;
    return q->stats.interior() ? OctreeLabel::kInterior : OctreeLabel::kExterior;
  };
  nlohmann::json rooms = nlohmann::json::array();
  size_t total_samples = 0, total_rooms = 0, total_regions = 0;
  double seconds_regions = 0, seconds_samples = 0, seconds_plan = 0;
  for (size_t k = 0; k < levels.size(); ++k) {
    if (absl::Status s = ReportMergeProgress(progress, "floorplan", k, levels.size()); !s.ok()) {
      return s;
    }
    // §4.2.4's regions of this level's faces alone (level_regions.h): the memory of the fit
    // follows the level, not the building. This level's wall samples read other tiles than
    // the last one's.
    ClearForFit(tiles);
    Clock::time_point t0 = Clock::now();
    PlanarRegionSet regions;
    const auto [band_begin, band_end] = LevelBand(faces.heights(), levels[k]);
    if (absl::Status s = CheckPlanarMemory(
            options,
            absl::StrCat("level ", k, "'s planar regions (its faces from ",
                         absl::SixDigits(levels[k].split_z_low - kLevelBandMarginM), " to ",
                         absl::SixDigits(levels[k].split_z_high + kLevelBandMarginM), " m)"),
            band_end - band_begin, settle_memory);
        !s.ok()) {
      return s;
    }
    absl::StatusOr<std::vector<BoundaryFace>> band = faces.Read(band_begin, band_end);
    if (!band.ok()) return band.status();
    if (absl::StatusOr<PlanarRegionSet> fit = FitPlanarRegions(*band, tiles.grid(), {}); fit.ok()) {
      regions = *std::move(fit);
    } else {
      return fit.status();
    }
    seconds_regions += SecondsSince(t0);
    total_regions += regions.regions.size();
    t0 = Clock::now();
    OctreeWallSampleReport sample_report;
    absl::StatusOr<WallSampleSet> samples =
        OctreeWallSamples(*band, regions, tiles.grid(), levels[k], *path, label_at,
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
    FloorPlanOptions plan_options;
    plan_options.method = *ParseFloorPlanMethod(options.floorplan_method);  // checked by RunMerge
    absl::StatusOr<LevelFloorPlan> plan =
        BuildLevelFloorPlan(*samples, static_cast<int>(k), plan_options);
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
    CountSelfIntersectionsInto(plan->extruded, "extruded", counts, timings, &warnings);
    for (const char* name :
         {"floorplan.geojson", "floorplan.svg", "floorplan.dxf", "extruded.ply"}) {
      outputs.push_back(absl::StrCat(level_name, "/", name));
    }
    for (auto& room : RoomsToJson(*plan)) rooms.push_back(room);
    plans.emplace_back(levels[k], plan->plan);
    total_rooms += plan->plan.rooms.size();
    nlohmann::json& lc = counts["floorplan_levels"][level_name];
    lc = {{"planar_regions", regions.regions.size()},
          {"wall_regions", sample_report.wall_regions},
          {"wall_samples", samples->samples.size()},
          {"samples_with_poses", sample_report.samples_with_poses},
          {"filled_behind_occlusion", sample_report.filled_behind_occlusion},
          {"poses", sample_report.poses},
          {"interior_triangles", plan->labeling.interior_triangles},
          {"initial_seeds", plan->labeling.initial_seeds},
          {"removed_rooms", plan->labeling.removed_rooms},
          {"open_sides_split", plan->labeling.open_sides_split},
          {"rooms", plan->plan.rooms.size()},
          {"extruded_triangles", plan->extruded.triangles.size()}};
  }
  job["rooms"] = rooms;
  counts["wall_samples"] = total_samples;
  counts["rooms"] = total_rooms;
  counts["floorplan_planar_regions"] = total_regions;
  timings["merge.floorplan_regions"] = seconds_regions;
  timings["merge.wall_samples"] = seconds_samples;
  timings["merge.floorplan"] = seconds_plan;
  return absl::OkStatus();
}

// Regions for the planar mesh only (§4.3.3): mesh_growth gives less than half the triangles
// of the default growth on the simulated office (the goal: ≤ 10 % of dense), but its vertical
// regions make worse wall samples (§5.3.1), so the levels and floor plans keep the default.
// Its bigger planes also sit a little farther from the true walls (object_segmentation_test:
// wall cover within 5 cm 63.1 → 59.5 %; docs/BENCHMARKS.md "Dense vs planar meshes").
PlanarRegionOptions MeshRegionOptions() {
  PlanarRegionOptions o;
  o.mesh_growth = true;
  return o;
}

// A planar mesh (§4.3.3, eq 4.9, §4.2.5) ➜ mesh/building.ply with face property `region`, and
// its counts in job.json.
absl::StatusOr<TriangleMesh> WriteBuildingMesh(PlanarMesh planar, const fs::path& out,
                                               nlohmann::json& counts, nlohmann::json& timings,
                                               std::vector<std::string>& outputs,
                                               std::vector<std::string>& warnings) {
  const MeshCheck check = CheckMesh(planar.mesh);
  if (!check.watertight()) {
    warnings.push_back("planar_mesh: not watertight (" + check.ToString() + ")");
  }
  if (absl::Status s = WritePly((out / "mesh" / "building.ply").string(), planar.mesh,
                                &planar.triangle_region, "region");
      !s.ok()) {
    return s;
  }
  outputs.push_back("mesh/building.ply");
  counts["building_vertices"] = planar.mesh.vertices.size();
  counts["building_triangles"] = planar.mesh.triangles.size();
  counts["building_watertight"] = check.watertight();
  counts["building_regions_not_retriangulated"] = planar.regions_not_retriangulated;
  counts["building_triangles_not_retriangulated"] = planar.triangles_not_retriangulated;
  CountSelfIntersectionsInto(planar.mesh, "building", counts, timings, &warnings);
  return std::move(planar.mesh);
}

// The building's planar mesh made a level at a time (level_cut.h): each level's part of
// `faces`, closed by caps where free space crosses the split heights, gets its own regions and
// mesh, so that the memory of both follows the largest level. The parts' meshes are closed
// shells, joined into one mesh (region ids offset). nullopt when a level's mesh cannot be
// built (job.json says why).
absl::StatusOr<std::optional<PlanarMesh>> PlanarMeshByLevel(
    const MergeOptions& options, const FaceStore& faces, TileSet& tiles,
    std::span<const Level> levels, nlohmann::json& counts, nlohmann::json& timings,
    std::vector<std::string>& warnings, const MergeProgressCallback& progress) {
  const OctreeGrid& grid = tiles.grid();
  const InteriorAtFn interior_at = [&tiles](const Eigen::Vector3d& x) -> absl::StatusOr<bool> {
    absl::StatusOr<LeafQuery> q = tiles.Query(x);
    if (!q.ok()) return q.status();
    return q->stored && q->stats.observed() && q->stats.interior();
  };
  const size_t parts = std::max<size_t>(levels.size(), 1);
  PlanarMesh joined;
  size_t regions_before = 0, caps = 0;
  double cut_seconds = 0;
  // The faces that may reach between two planes: a coarse face's centre lies up to half its
  // side beyond them.
  const double reach = faces.max_size_m() + grid.resolution_m();
  // Each split height's plane caps the parts on both its sides: found once, kept for the next.
  CutPlane low{-std::numeric_limits<double>::infinity(), {}};
  for (size_t k = 0; k < parts; ++k) {
    if (absl::Status s = ReportMergeProgress(progress, "planar_mesh", k, parts); !s.ok()) return s;
    const double hi =
        k + 1 >= parts ? std::numeric_limits<double>::infinity() : levels[k + 1].split_z_low;
    const Clock::time_point t0 = Clock::now();
    absl::StatusOr<CutPlane> high =
        FindCutPlane(grid, hi, faces.xy_min(), faces.xy_max(), interior_at);
    if (!high.ok()) return high.status();
    ClearForFit(tiles);  // the plane's tiles are not read again
    const auto [begin, end] = faces.heights().Range(low.z - reach, high->z + reach);
    absl::StatusOr<std::vector<BoundaryFace>> near = faces.Read(begin, end);
    if (!near.ok()) return near.status();
    absl::StatusOr<LevelPart> part = CutLevelPart(*near, grid, low, *high);
    if (!part.ok()) return part.status();
    *near = {};
    low = *std::move(high);
    cut_seconds += SecondsSince(t0);
    caps += part->caps;
    if (absl::Status s = CheckPlanarMemory(
            options, absl::StrCat("level ", k, "'s part of the building's planar mesh"),
            part->faces.size());
        !s.ok()) {
      return s;
    }
    // These regions only shape the planar mesh, so they are grown for it (mesh_growth:
    // fewer, bigger regions, §4.3.3); the floor plans were made from the job's own regions.
    absl::StatusOr<PlanarRegionSet> regions =
        FitPlanarRegions(part->faces, grid, MeshRegionOptions());
    if (!regions.ok()) return regions.status();
    absl::StatusOr<PlanarMesh> planar = BuildPlanarMesh(part->faces, *regions, grid);
    if (!planar.ok()) {
      if (absl::IsCancelled(planar.status())) return planar.status();
      warnings.push_back(absl::StrCat("planar_mesh level ", k, ": ", planar.status().message()));
      return std::optional<PlanarMesh>();
    }
    for (int& r : planar->triangle_region) r += static_cast<int>(regions_before);
    regions_before += regions->regions.size();
    joined.mesh.Append(planar->mesh);
    joined.triangle_region.insert(joined.triangle_region.end(), planar->triangle_region.begin(),
                                  planar->triangle_region.end());
    joined.regions_not_retriangulated += planar->regions_not_retriangulated;
    joined.triangles_not_retriangulated += planar->triangles_not_retriangulated;
  }
  counts["building_planar_regions"] = regions_before;
  counts["building_level_caps"] = caps;
  timings["merge.planar_mesh_level_cut"] = cut_seconds;
  return std::optional<PlanarMesh>(std::move(joined));
}

// PlanarMeshByLevel written by WriteBuildingMesh: the mesh written, or nullopt when a level's
// mesh cannot be built (job.json says why).
absl::StatusOr<std::optional<TriangleMesh>> PlanarBuildingMesh(
    const MergeOptions& options, const FaceStore& faces, TileSet& tiles,
    std::span<const Level> levels, const fs::path& out, nlohmann::json& counts,
    nlohmann::json& timings, std::vector<std::string>& outputs, std::vector<std::string>& warnings,
    const MergeProgressCallback& progress) {
  absl::StatusOr<std::optional<PlanarMesh>> by_level =
      PlanarMeshByLevel(options, faces, tiles, levels, counts, timings, warnings, progress);
  if (!by_level.ok()) return by_level.status();
  if (!*by_level) return std::optional<TriangleMesh>();
  absl::StatusOr<TriangleMesh> written =
      WriteBuildingMesh(**std::move(by_level), out, counts, timings, outputs, warnings);
  if (!written.ok()) return written.status();
  return std::optional<TriangleMesh>(*std::move(written));
}

// §5.6's object split as this job asks for it; the re-carving region reaches as far up as the
// split groups stacked pieces, so both read it here.
ObjectSplitOptions SplitOptionsFor(const MergeOptions& options, const OctreeGrid& grid) {
  ObjectSplitOptions split;
  split.min_thickness_m = 2 * grid.resolution_m();  // one-cell films are carving noise
  if (options.min_object_volume_m3 > 0) split.min_volume_m3 = options.min_object_volume_m3;
  return split;
}

struct SegmentStageResult {
  uint64_t building_triangles = 0;
  uint64_t objects = 0;
};

// Where the objects are meshed from: a directory of object tiles at a resolution, and, when
// that is finer than the job's, the extruded plans rasterized at it.
struct ObjectSource {
  std::string dir;
  double resolution_m = 0;
  std::optional<PlanVolume> finer_volume;
};

// §5.6.1 (Fig 5.17): the chunks that hold object cells carved again at the finer resolution
// by the caller's `recarve`, only around their objects (ObjectRecarveRegion: "recarve the
// nodes of the octree containing object geometry"), segmented again against the plans
// rasterized at that resolution (objects only, inside the same regions), into
// <work>/finer_objects. The plan's walls keep the job's tolerance (one coarse cell): the plan
// came from the coarse octree, so it is no more exact than that, and a finer tolerance would
// turn the re-carved walls' skin into objects. No region (objects too small): no re-carving.
// In three parts, so that the building's planar mesh is made while the workers re-carve
// (SegmentStage): RecarveRegions (none: nothing to re-carve), RecarveChunks and
// SegmentRecarvedObjects.
struct RecarvePass {
  std::string recarved_dir;
  RecarveRegionMap regions;  // the chunks' regions, for the second segmentation
};

absl::StatusOr<std::vector<RecarveChunk>> RecarveRegions(
    const MergeOptions& options, const std::vector<ChunkKey>& chunks, const OctreeGrid& grid,
    const PlanVolume& coarse_volume, const ObjectSource& source, nlohmann::json& counts,
    const MergeProgressCallback& progress) {
  if (absl::Status s = ReportMergeProgress(progress, "recarve", 0, chunks.size()); !s.ok()) {
    return s;
  }
  std::vector<RecarveChunk> again;
  double region_volume = 0;  // in chunks
  // Up to the ceiling over objects as close to it as SplitObjects groups stacked pieces: a
  // lamp's rod, whose points join it only when they are in the region.
  const double ceiling_reach_m = SplitOptionsFor(options, grid).stack_gap_m;
  absl::StatusOr<std::unique_ptr<TileSet>> objects =
      TileSet::Open(source.dir, grid.resolution_m(), options.cache_budget_bytes);
  if (!objects.ok()) return objects.status();
  for (const ChunkKey& chunk : chunks) {
    absl::StatusOr<std::shared_ptr<const TileData>> tile = (*objects)->Get(chunk);
    if (!tile.ok()) return tile.status();
    ChunkRegion region =
        ObjectRecarveRegion(**tile, coarse_volume, /*margin_cells=*/1, ceiling_reach_m);
    if (region.empty()) continue;
    region_volume += std::ldexp(double(region.count()), -3 * region.depth());
    again.push_back(RecarveChunk::Of(chunk, region));
  }
  counts["recarved_chunks"] = again.size();
  // The share of those chunks' volume carved again.
  if (!again.empty()) counts["recarved_volume_fraction"] = region_volume / double(again.size());
  return again;
}

// The caller's re-carve of `again`. Touches nothing of the merge's, so it can wait on the
// workers beside the building (SegmentStage).
absl::StatusOr<RecarvePass> RecarveChunks(const MergeOptions& options,
                                          std::vector<RecarveChunk> again) {
  const double res = options.object_resolution_m;
  absl::StatusOr<std::string> dir = options.recarve(again, res);
  if (!dir.ok()) {
    return absl::Status(dir.status().code(), absl::StrCat("re-carving ", again.size(),
                                                          " object chunks at ", res, " m: ",
                                                          dir.status().message()));
  }
  RecarvePass pass;
  pass.recarved_dir = *std::move(dir);
  for (RecarveChunk& c : again) {
    const ChunkKey chunk = c.chunk;
    pass.regions.emplace(chunk, std::move(c));
  }
  return pass;
}

absl::Status SegmentRecarvedObjects(const MergeOptions& options,
                                    std::span<const PlanLevelInput> inputs, const OctreeGrid& grid,
                                    const fs::path& work, const RecarvePass& pass,
                                    ObjectSource& source, nlohmann::json& counts,
                                    nlohmann::json& timings,
                                    const MergeProgressCallback& progress) {
  const double res = options.object_resolution_m;
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<TileSet>> tiles =
      TileSet::Open(pass.recarved_dir, res, options.cache_budget_bytes);
  if (!tiles.ok()) return tiles.status();
  if (options.fill_pockets) {  // as the job's tiles (RunMerge)
    const fs::path filled_dir = work / "finer_pockets";
    absl::StatusOr<PocketTilesResult> pockets =
        FillPocketTiles(**tiles, pass.recarved_dir, filled_dir.string(), PocketFillOptions{},
                        StageProgress(progress, "recarve_pocket_fill"), MergeThreads(options));
    if (!pockets.ok()) return pockets.status();
    counts["recarved_pocket_cells"] = pockets->filled_cells;
    tiles = TileSet::Open(filled_dir.string(), res, options.cache_budget_bytes);
    if (!tiles.ok()) return tiles.status();
  }
  SegmentOptions seg;
  seg.plan_tolerance_m = grid.resolution_m();
  absl::StatusOr<PlanVolume> volume =
      RasterizePlanVolume(inputs, res, seg.trim_distance_m + 2 * grid.resolution_m());
  if (!volume.ok()) return volume.status();
  source.dir = (work / "finer_objects").string();
  absl::StatusOr<SegmentTilesResult> segmented = SegmentTiles(
      **tiles, *volume, seg, "", source.dir, StageProgress(progress, "recarve_segmentation"),
      MergeThreads(options), &pass.regions);
  if (!segmented.ok()) return segmented.status();
  counts["recarved_object_cells"] = segmented->object_cells;
  source.resolution_m = res;
  source.finer_volume = std::move(*volume);
  timings["merge.recarve_segmentation"] = SecondsSince(t0);
  return absl::OkStatus();
}

// The building tiles' (<work>/building) faces, regions and planar mesh ➜ mesh/building.ply;
// the building volume's dense mesh when the planar mesher fails. Returns the mesh written.
absl::StatusOr<TriangleMesh> BuildingStage(const MergeOptions& options, const OctreeGrid& grid,
                                           std::span<const Level> levels, const fs::path& work,
                                           const fs::path& out, nlohmann::json& counts,
                                           nlohmann::json& timings,
                                           std::vector<std::string>& outputs,
                                           std::vector<std::string>& warnings,
                                           const MergeProgressCallback& progress) {
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<TileSet>> btiles =
      TileSet::Open((work / "building").string(), grid.resolution_m(), options.cache_budget_bytes);
  if (!btiles.ok()) return btiles.status();
  absl::StatusOr<std::unique_ptr<FaceStore>> bfaces =
      StoreBoundaryFaces(**btiles, (work / "building.faces").string(),
                         StageProgress(progress, "building_faces"), MergeThreads(options));
  if (!bfaces.ok()) return bfaces.status();
  // The cache is filled again only by the caps' queries along each split height (dropped
  // before each level's fit) and by the dense fallback below.
  (*btiles)->ReleaseCache();
  absl::StatusOr<std::optional<TriangleMesh>> planar = PlanarBuildingMesh(
      options, **bfaces, **btiles, levels, out, counts, timings, outputs, warnings, progress);
  if (!planar.ok()) return planar.status();
  bfaces = nullptr;
  std::optional<TriangleMesh> building = *std::move(planar);
  if (!building) {
    // The planar mesher failed (its reason is in the warnings): the building volume's dense
    // mesh stands in, watertight by construction, so combined.ply stays whole.
    absl::StatusOr<DenseMeshResult> dense = BuildDenseMesh(
        **btiles, StageProgress(progress, "building_dense_mesh"), MergeThreads(options));
    if (!dense.ok()) return dense.status();
    if (absl::Status s = WritePly((out / "mesh" / "building.ply").string(), dense->mesh); !s.ok()) {
      return s;
    }
    warnings.push_back(
        "segmentation: mesh/building.ply is the dense mesh of the building "
        "volume, not a planar one");
    outputs.push_back("mesh/building.ply");
    counts["building_vertices"] = dense->mesh.vertices.size();
    counts["building_triangles"] = dense->mesh.triangles.size();
    counts["building_watertight"] = CheckMesh(dense->mesh).watertight();
    CountSelfIntersectionsInto(dense->mesh, "building", counts, timings, &warnings,
                               MergeThreads(options));
    counts["building_planar"] = false;
    building = std::move(dense->mesh);
  } else {
    counts["building_planar"] = true;
  }
  timings["merge.planar_mesh"] = SecondsSince(t0);
  return *std::move(building);
}

// building.ifc (docs/DESIGN.md §7): the levels' plans as one IFC 4 building model. It needs
// the plans alone, so it is written as soon as they are made. A file that cannot be made is a
// warning, not a failure: the plans' own files stand.
void WriteBuildingIfcStage(std::span<const std::pair<Level, FloorPlan>> plans, const fs::path& out,
                           nlohmann::json& counts, nlohmann::json& timings,
                           std::vector<std::string>& outputs, std::vector<std::string>& warnings) {
  std::error_code ec;
  fs::remove(out / "building.ifc", ec);  // an earlier merge's into this folder is not this one's
  if (plans.empty()) return;
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<BuildingIfcCounts> ifc = WriteBuildingIfc((out / "building.ifc").string(), plans);
  if (ifc.ok()) {
    outputs.push_back("building.ifc");
    counts["ifc"] = {{"storeys", ifc->storeys},
                     {"spaces", ifc->spaces},
                     {"walls", ifc->walls},
                     {"doors", ifc->doors}};
  } else {
    warnings.push_back(absl::StrCat("ifc: ", ifc.status().message()));
  }
  timings["merge.ifc"] = SecondsSince(t0);
}

// docs/DESIGN.md §6 stages 6–8 (§5.5, §5.6): the tiles segmented against the extruded plans into
// building and object tiles (in <out>/.segment, removed afterwards), the building tiles' faces,
// regions and planar mesh, the object tiles' dense mesh split into objects, and combined.ply.
absl::StatusOr<SegmentStageResult> SegmentStage(
    const MergeOptions& options, TileSet& tiles,
    const std::vector<std::pair<Level, FloorPlan>>& plans, const fs::path& out,
    nlohmann::json& job, nlohmann::json& counts, nlohmann::json& timings,
    std::vector<std::string>& outputs, std::vector<std::string>& warnings,
    const MergeProgressCallback& progress) {
  SegmentStageResult result;
  const OctreeGrid grid = tiles.grid();
  const SegmentOptions seg_options;
  Clock::time_point t0 = Clock::now();
  std::vector<PlanLevelInput> inputs;
  std::vector<Level> levels;
  for (const auto& [level, plan] : plans) {
    inputs.push_back(PlanLevelInput{&plan, level.index, level.split_z_low, level.split_z_high});
    levels.push_back(level);
  }
  absl::StatusOr<PlanVolume> volume = RasterizePlanVolume(
      inputs, grid.resolution_m(), seg_options.trim_distance_m + 2 * grid.resolution_m());
  if (!volume.ok()) return volume.status();
  const fs::path work = out / ".segment";
  std::error_code ec;
  fs::remove_all(work, ec);
  absl::StatusOr<SegmentTilesResult> segmented = SegmentTiles(
      tiles, *volume, seg_options, (work / "building").string(), (work / "objects").string(),
      StageProgress(progress, "segmentation"), MergeThreads(options));
  if (!segmented.ok()) return segmented.status();
  tiles.ReleaseCache();  // the job's tiles are read again only by the first outputs, in order
  counts["segmented_chunks"] = segmented->chunks;
  counts["object_cells"] = segmented->object_cells;
  counts["unobserved_object_cells"] = segmented->unobserved_object_cells;
  counts["trimmed_cells"] = segmented->trimmed_cells;
  timings["merge.segmentation"] = SecondsSince(t0);

  if (options.trimmed_points) {
    t0 = Clock::now();
    if (absl::Status s = ReportMergeProgress(progress, "trimmed_points", 0, 1); !s.ok()) return s;
    absl::StatusOr<std::unique_ptr<ScanCloudStream>> scan =
        ScanCloudStream::Open(options.scan_path, /*validate=*/false,  // the floor plans read it
                              options.world_yaw_rad);
    if (!scan.ok()) return scan.status();
    absl::StatusOr<TrimmedPointsCounts> points = WriteTrimmedPoints(
        (*scan)->Stream(), *volume, seg_options.trim_distance_m, (out / "points.ply").string());
    if (!points.ok()) return points.status();
    counts["points_kept"] = points->kept;
    counts["points_trimmed"] = points->trimmed;
    outputs.push_back("points.ply");
    timings["merge.trimmed_points"] = SecondsSince(t0);
  }

  // The building's planar mesh, and the objects' re-carve (§5.6.1) when the caller can: the
  // building is made while the workers re-carve, so that neither waits for the other, then
  // the re-carved tiles are segmented.
  ObjectSource source{(work / "objects").string(), grid.resolution_m(), std::nullopt};
  std::vector<RecarveChunk> again;
  const Clock::time_point t_recarve = Clock::now();
  if (segmented->object_tiles > 0 && options.recarve && options.object_resolution_m > 0 &&
      options.object_resolution_m < grid.resolution_m()) {
    absl::StatusOr<std::vector<RecarveChunk>> regions =
        RecarveRegions(options, segmented->object_chunks, grid, *volume, source, counts, progress);
    if (!regions.ok()) return regions.status();
    again = *std::move(regions);
  }
  absl::StatusOr<TriangleMesh> building = absl::UnknownError("not made");
  if (again.empty()) {
    building = BuildingStage(options, grid, levels, work, out, counts, timings, outputs, warnings,
                             progress);
  } else {
    absl::StatusOr<RecarvePass> pass = absl::UnknownError("not made");
    double recarve_s = 0;
    {
      std::atomic<bool> stop{false};
      // The building reports no stage of its own meanwhile (the re-carve's is the one that
      // tells the user how long): it only stops when the merge is stopped. The re-carve, a
      // wait on the workers, is the one on another thread, so that the building's memory
      // comes from the arenas the earlier stages freed.
      const MergeProgressCallback building_progress = [&](const MergeProgress&) {
        return !stop.load();
      };
      std::jthread recarve_thread([&] {
        pass = RecarveChunks(options, std::move(again));
        recarve_s = SecondsSince(t_recarve);
        if (!pass.ok()) stop = true;
      });
      building = BuildingStage(options, grid, levels, work, out, counts, timings, outputs, warnings,
                               building_progress);
    }
    if (!pass.ok()) return pass.status();
    timings["merge.recarve"] = recarve_s;
    if (!building.ok()) return building.status();
    absl::Status s = SegmentRecarvedObjects(options, inputs, grid, work, *pass, source, counts,
                                            timings, progress);
    if (!s.ok()) return s;
  }
  if (!building.ok()) return building.status();
  result.building_triangles = building->triangles.size();

  // The objects: dense mesh of the (finer) object tiles, split into closed pieces as it
  // streams past, each kept piece's mesh into a scratch file; then each object's file.
  t0 = Clock::now();
  ObjectLayout layout;
  absl::StatusOr<std::unique_ptr<ObjectPieceFile>> pieces =
      ObjectPieceFile::Create((work / "object_pieces").string());
  if (!pieces.ok()) return pieces.status();
  if (segmented->object_tiles > 0) {
    counts["object_resolution_m"] = source.resolution_m;
    absl::StatusOr<std::unique_ptr<TileSet>> otiles =
        TileSet::Open(source.dir, source.resolution_m, options.cache_budget_bytes);
    if (!otiles.ok()) return otiles.status();
    // Specks within 3 σ of the path's horizontal error of a wall are the wall's smear
    // (ObjectSplitOptions::wall_smear_m): 3 σ holds 99.7 % of a normal error along the wall's
    // normal.
    ObjectSplitOptions split = SplitOptionsFor(options, grid);
    if (!options.scan_path.empty()) {
      absl::StatusOr<std::optional<double>> sigma = ReadPathSigma(options.scan_path);
      if (!sigma.ok()) return sigma.status();
      if (sigma->has_value()) split.wall_smear_m = 3 * **sigma;
    }
    counts["object_wall_smear_m"] = split.wall_smear_m;
    ObjectSplitter splitter(
        source.finer_volume ? *source.finer_volume : *volume, split,
        [&pieces](uint64_t key, const TriangleMesh& mesh) { return (*pieces)->Add(key, mesh); });
    DenseMeshSink sink;
    sink.vertices = [&splitter](std::span<const Eigen::Vector3f> v) {
      splitter.AddVertices(v);
      return absl::OkStatus();
    };
    sink.triangles = [&splitter](const ChunkKey& chunk, std::span<const Eigen::Vector3i> t) {
      return splitter.AddTriangles(chunk.x(), t);
    };
    // Each object's crossings are counted below, on its own.
    absl::StatusOr<DenseMeshStreamResult> dense =
        StreamDenseMesh(**otiles, sink, StageProgress(progress, "object_mesh"),
                        MergeThreads(options), /*count_self_intersections=*/false);
    if (!dense.ok()) return dense.status();
    if (absl::Status s = ReportMergeProgress(progress, "object_split", 0, 1); !s.ok()) return s;
    const Clock::time_point t_split = Clock::now();
    absl::StatusOr<ObjectLayout> found = splitter.Finish();
    if (!found.ok()) return found.status();
    layout = *std::move(found);
    timings["merge.object_split"] = SecondsSince(t_split);
  }
  if (absl::Status s = (*pieces)->FinishWriting(); !s.ok()) return s;
  counts["object_scratch_bytes"] = (*pieces)->bytes();
  const Clock::time_point t_files = Clock::now();
  absl::StatusOr<std::unique_ptr<ModelGlb>> glb =
      ModelGlb::Create((out / "mesh" / "model.glb").string(), *building, plans);
  if (!glb.ok()) return glb.status();
  absl::StatusOr<ObjectFilesResult> files =
      WriteObjectFiles(layout, **pieces, *building, out, MergeThreads(options),
                       StageProgress(progress, "object_files"),
                       [&glb](const SegmentedObject& o, const TriangleMesh& mesh) {
                         return (*glb)->AddObject(o, mesh);
                       });
  if (!files.ok()) return files.status();
  if (absl::Status s = (*glb)->Finish(); !s.ok()) return s;
  timings["merge.object_files"] = SecondsSince(t_files);
  *pieces = nullptr;
  fs::remove_all(work, ec);  // scratch: every output is written

  uint64_t object_triangles = 0;
  uint64_t objects_crossing = 0;  // objects whose mesh crosses itself: one warning for all
  uint64_t object_pairs = 0, object_untested = 0;
  nlohmann::json listed = nlohmann::json::array();
  for (size_t i = 0; i < layout.objects.size(); ++i) {
    const SegmentedObject& o = layout.objects[i];
    const std::string name = absl::StrCat("mesh/objects/", o.id, ".ply");
    objects_crossing += files->crossings[i].pairs > 0;
    object_pairs += files->crossings[i].pairs;
    object_untested += files->crossings[i].unchecked;
    outputs.push_back(name);
    object_triangles += files->triangles[i];
    listed.push_back({{"id", o.id},
                      {"level", o.level},
                      {"room", o.room},
                      {"aabb",
                       {{o.box.min().x(), o.box.min().y(), o.box.min().z()},
                        {o.box.max().x(), o.box.max().y(), o.box.max().z()}}},
                      {"volume_m3", o.volume_m3},
                      {"triangles", files->triangles[i]},
                      {"mesh", name}});
  }
  if (!layout.objects.empty()) counts["object_self_intersections"] = object_pairs;
  if (object_untested > 0) counts["object_triangles_not_tested"] = object_untested;
  if (objects_crossing > 0) {
    warnings.push_back(absl::StrCat("objects: the meshes of ", objects_crossing, " objects cross "
                                    "themselves (", object_pairs, " pairs of triangles)"));
  }
  outputs.push_back("mesh/objects.ply");
  outputs.push_back("mesh/combined.ply");
  outputs.push_back("mesh/model.glb");
  job["objects"] = listed;
  counts["objects"] = layout.objects.size();
  counts["object_triangles"] = object_triangles;
  counts["object_components"] = layout.report.components;
  counts["objects_dropped_small"] = layout.report.dropped_small;
  counts["objects_dropped_cavities"] = layout.report.dropped_cavities;
  counts["objects_dropped_ceiling"] = layout.report.dropped_ceiling;
  counts["objects_grouped"] = layout.report.grouped;
  counts["object_specks_unmeshed"] = layout.report.specks_unmeshed;
  counts["object_specks_off_walls"] = layout.report.specks_off_walls;
  counts["objects_dropped_wall_smear"] = layout.report.dropped_wall_smear;
  timings["merge.object_mesh"] = SecondsSince(t0);
  result.objects = layout.objects.size();
  return result;
}

// mesh/dense.ply from `tiles_dir` (§4.3.3), welded and checked for self-intersections as it
// streams (it grows with the building and is not held). It reads its own TileSet, so that it
// can run on a thread of its own beside the floor plans (RunMerge): it needs the tiles alone.
// A quarter of the cache budget: it reads the chunks in order, each with its neighbours, so it
// holds a few columns of them at a time, and the floor plans' own cache is in use meanwhile.
struct DenseMeshOutput {
  absl::Status status;
  DenseMeshStreamResult result;
  double seconds = 0;
};

DenseMeshOutput DenseMeshToPly(const MergeOptions& options, const std::string& tiles_dir,
                               double resolution_m, const fs::path& out,
                               const ChunkProgressFn& progress) {
  DenseMeshOutput d;
  const Clock::time_point t0 = Clock::now();
  d.status = [&]() -> absl::Status {
    absl::StatusOr<std::unique_ptr<TileSet>> tiles =
        TileSet::Open(tiles_dir, resolution_m, options.cache_budget_bytes / 4);
    if (!tiles.ok()) return tiles.status();
    absl::StatusOr<std::unique_ptr<PlyStreamWriter>> ply =
        PlyStreamWriter::Create((out / "mesh" / "dense.ply").string());
    if (!ply.ok()) return ply.status();
    DenseMeshSink sink;
    sink.vertices = [&ply](std::span<const Eigen::Vector3f> v) { return (*ply)->AddVertices(v); };
    sink.triangles = [&ply](const ChunkKey&, std::span<const Eigen::Vector3i> t) {
      return (*ply)->AddTriangles(t);
    };
    absl::StatusOr<DenseMeshStreamResult> dense =
        StreamDenseMesh(**tiles, sink, progress, MergeThreads(options));
    if (!dense.ok()) return dense.status();
    if (absl::Status s = (*ply)->Finish(); !s.ok()) return s;
    d.result = *std::move(dense);
    return absl::OkStatus();
  }();
  d.seconds = SecondsSince(t0);
  return d;
}

}  // namespace

absl::Status MergeOptions::Validate() const {
  if (absl::Status s = MergeParams::Validate(); !s.ok()) return s;
  return FirstOutputs().Validate();
}

FirstOutputsOptions MergeOptions::FirstOutputs() const {
  FirstOutputsOptions first;
  first.tiles_dir = tiles_dir;
  first.output_dir = output_dir;
  first.resolution_m = resolution_m;
  first.job = job;
  first.cache_budget_bytes = cache_budget_bytes;
  first.topdown_max_height_m = topdown_max_height_m;
  return first;
}

absl::StatusOr<MergeSummary> RunMerge(const MergeOptions& options,
                                      const MergeProgressCallback& progress) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  {
    // job.json, written last, says the merge finished: an earlier merge's must not stand
    // beside this one's outputs if this one fails partway.
    std::error_code ec;
    fs::remove(fs::path(options.output_dir) / "job.json", ec);
    if (ec && ec != std::errc::no_such_file_or_directory) {
      return absl::UnavailableError(
          absl::StrCat(options.output_dir, "/job.json: cannot remove: ", ec.message()));
    }
  }
  if (!options.meshes) return MergeFirstOutputs(options.FirstOutputs(), progress);
  const Clock::time_point t_start = Clock::now();

  absl::StatusOr<std::unique_ptr<TileSet>> opened =
      TileSet::Open(options.tiles_dir, options.resolution_m, options.cache_budget_bytes);
  if (!opened.ok()) return opened.status();
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

  // Thin unobserved pockets filled as free for every stage below (fill_pockets.h); the first
  // outputs (octree.bt, the top-down maps) read the job's own tiles, as carved.
  Clock::time_point t0 = Clock::now();
  const fs::path pocket_dir = out / ".pockets";
  fs::remove_all(pocket_dir, ec);  // an earlier merge's
  absl::Cleanup remove_pockets = [&pocket_dir] {
    std::error_code ignored;
    fs::remove_all(pocket_dir, ignored);
  };
  if (options.fill_pockets) {
    absl::StatusOr<PocketTilesResult> pockets =
        FillPocketTiles(**opened, options.tiles_dir, pocket_dir.string(), PocketFillOptions{},
                        StageProgress(progress, "pocket_fill"), MergeThreads(options));
    if (!pockets.ok()) return InStage("pocket_fill", pockets.status());
    counts["pocket_cells"] = pockets->filled_cells;
    counts["pocket_chunks"] = pockets->filled_tiles;
    const double resolution_m = (*opened)->grid().resolution_m();
    opened = TileSet::Open(pocket_dir.string(), resolution_m, options.cache_budget_bytes);
    if (!opened.ok()) return InStage("pocket_fill", opened.status());
    timings["merge.pocket_fill"] = SecondsSince(t0);
  }
  TileSet& tiles = **opened;
  const OctreeGrid grid = tiles.grid();

  // boundary faces (stage 1), sorted by height into a scratch file that the stages below read
  // a slab or a level at a time (face_store.h)
  const fs::path scratch = out / ".faces";
  fs::create_directories(scratch, ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat(scratch.string(), ": cannot create: ", ec.message()));
  }
  absl::Cleanup remove_scratch = [&scratch] {
    std::error_code ignored;
    fs::remove_all(scratch, ignored);
  };
  t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<FaceStore>> faces =
      StoreBoundaryFaces(tiles, (scratch / "job.faces").string(),
                         StageProgress(progress, "boundary_faces"), MergeThreads(options));
  if (!faces.ok()) return InStage("boundary_faces", faces.status());
  ClearForFit(tiles);  // the wall samples read their own tiles again
  counts["boundary_faces"] = (*faces)->size();
  counts["boundary_area_m2"] = (*faces)->area_m2();
  timings["merge.boundary_faces"] = SecondsSince(t0);

  // The dense mesh needs the tiles alone, so it is made on a thread of its own while the
  // levels and floor plans below (one thread) are made: the cores they leave idle mesh it.
  // Not beside the faces above, which use every core and hold the most memory of these
  // stages. It reports no stage of its own and stops when the merge stops (any return below;
  // its file goes too, as it would not have been made yet); joined before the segmentation,
  // as if made there.
  std::atomic<bool> stop_dense{false};
  DenseMeshOutput dense;
  bool dense_joined = false;
  absl::Cleanup remove_dense_ply = [&dense_joined, &out] {
    std::error_code ignored;
    if (!dense_joined) fs::remove(out / "mesh" / "dense.ply", ignored);
  };
  std::jthread dense_thread(
      [&, dir = options.fill_pockets ? pocket_dir.string() : options.tiles_dir] {
        dense = DenseMeshToPly(options, dir, grid.resolution_m(), out,
                               [&stop_dense](uint64_t, uint64_t) { return !stop_dense.load(); });
      });
  absl::Cleanup stop_dense_mesh = [&stop_dense] { stop_dense = true; };
  // The dense mesh's tile cache and buffers count in what the process holds: a planar fit whose
  // memory check fails beside it waits for it to end, then checks again.
  const std::function<void()> settle_dense = [&dense_thread] {
    if (dense_thread.joinable()) dense_thread.join();
    ReturnFreedMemory();
  };

  // planar regions (stage 2, §4.2.4) for the levels, fitted a slab of heights at a time
  // (level_regions.h); each level's own are fitted with its floor plan. Beyond two slabs' faces
  // the building is a large one, whose slab fits (a core and its margins above and below) and
  // dense mesh together would pass 0.9 GiB (a four-level office at 10 Hz): the fits wait.
  if ((*faces)->size() > 2 * kLevelSlabFaces) settle_dense();
  if (absl::Status s =
          CheckPlanarMemory(options, "the levels' planar regions (a slab of heights)",
                            std::min<uint64_t>((*faces)->size(), kLevelSlabFaces), settle_dense);
      !s.ok()) {
    return InStage("planar_regions", s);
  }
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "planar_regions", 0, 1); !s.ok()) return s;
  absl::StatusOr<std::vector<PlanarRegion>> level_regions =
      LevelRegions((*faces)->heights(), (*faces)->Reader(), grid);
  if (!level_regions.ok()) return InStage("planar_regions", level_regions.status());
  ReturnFreedMemory();  // the slabs' fits
  counts["level_planar_regions"] = level_regions->size();
  timings["merge.planar_regions"] = SecondsSince(t0);

  // levels (stage 3, §5.2) ➜ levels.json. The point-height fallback of §2.5 needs the scan,
  // which the merge does not read; without horizontal regions there is one level_0.
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "levels", 0, 1); !s.ok()) return s;
  absl::StatusOr<LevelSplit> levels = SplitLevels(*level_regions, nullptr);
  if (!levels.ok()) return InStage("levels", levels.status());
  FirstOutputsOptions first = options.FirstOutputs();
  for (const Level& level : levels->levels) {
    first.levels.push_back(TopdownZRange{level.split_z_low, level.split_z_high});
    first.level_floors_z.push_back(level.floor_z);
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
  // floorplan.dxf, extruded.ply; job.json "rooms"
  std::vector<std::pair<Level, FloorPlan>> plans;
  if (absl::Status s = FloorPlanStage(options, tiles, **faces, levels->levels, out, job, counts,
                                      timings, outputs, warnings, progress, settle_dense, plans);
      !s.ok()) {
    return InStage("floorplan", s);
  }
  WriteBuildingIfcStage(plans, out, counts, timings, outputs, warnings);

  // Once the floor plans are made, the faces serve only the planar mesh of a job without
  // plans (which fits its own regions).
  const size_t num_boundary_faces = (*faces)->size();
  const size_t num_planar_regions =
      level_regions->size() + counts.value("floorplan_planar_regions", size_t{0});
  counts["planar_regions"] = num_planar_regions;
  level_regions = std::vector<PlanarRegion>{};
  if (!plans.empty()) *faces = nullptr;

  // dense mesh (§4.3.3) ➜ mesh/dense.ply, made beside the stages above
  t0 = Clock::now();
  if (absl::Status s = ReportMergeProgress(progress, "dense_mesh", 0, 1); !s.ok()) return s;
  if (dense_thread.joinable()) dense_thread.join();
  dense_joined = true;
  if (!dense.status.ok()) return InStage("dense_mesh", dense.status);
  const uint64_t dense_triangles = dense.result.triangles;
  counts["dense_vertices"] = dense.result.vertices;
  counts["dense_triangles"] = dense_triangles;
  RecordSelfIntersections(dense.result.self_intersections, "dense",
                          dense.result.self_intersection_seconds, counts, timings, &warnings);
  outputs.push_back("mesh/dense.ply");
  timings["merge.dense_mesh"] = dense.seconds;
  timings["merge.dense_mesh_wait"] = SecondsSince(t0);

  // §5.5–§5.6 segmentation against the floor plans, then the building's planar mesh and the
  // objects' dense meshes ➜ mesh/building.ply, mesh/objects.ply, mesh/objects/<id>.ply,
  // mesh/combined.ply. Without floor plans the building mesh holds everything.
  t0 = Clock::now();
  uint64_t building_triangles = 0, object_count = 0;
  {
    std::error_code ec;  // an earlier merge's points.ply is not this one's (rewritten on request)
    fs::remove(out / "points.ply", ec);
  }
  if (plans.empty()) {
    warnings.push_back("segmentation: no floor plan, so no objects; mesh/building.ply is the "
                       "planar mesh of everything");
    // An earlier merge into the same folder may have left objects: they are not this job's.
    std::error_code ec;
    for (const char* stale : {"objects", "objects.ply", "combined.ply"}) {
      fs::remove_all(out / "mesh" / stale, ec);
    }
    if (options.trimmed_points) {
      warnings.push_back(options.scan_path.empty()
                             ? "trimmed_points: no scan given, so no points.ply"
                             : "trimmed_points: no floor plan to trim by, so no points.ply");
    }
    // The regions above made the levels (and would have made the floor plans); the planar
    // mesh gets its own, grown for it (mesh_growth, §4.3.3), a level at a time.
    absl::StatusOr<std::optional<TriangleMesh>> building = PlanarBuildingMesh(
        options, **faces, tiles, levels->levels, out, counts, timings, outputs, warnings, progress);
    if (!building.ok()) return InStage("planar_mesh", building.status());
    if (*building) {
      building_triangles = (*building)->triangles.size();
      // The building alone as the glTF scene: no rooms and no objects without floor plans.
      absl::StatusOr<std::unique_ptr<ModelGlb>> glb =
          ModelGlb::Create((out / "mesh" / "model.glb").string(), **building, {});
      if (!glb.ok()) return InStage("planar_mesh", glb.status());
      if (absl::Status s = (*glb)->Finish(); !s.ok()) return InStage("planar_mesh", s);
      outputs.push_back("mesh/model.glb");
    } else {
      std::error_code ec;
      fs::remove(out / "mesh" / "model.glb", ec);
    }
    timings["merge.planar_mesh"] = SecondsSince(t0);
  } else {
    absl::StatusOr<SegmentStageResult> seg =
        SegmentStage(options, tiles, plans, out, job, counts, timings, outputs, warnings,
                     progress);
    if (!seg.ok()) return InStage("segmentation", seg.status());
    building_triangles = seg->building_triangles;
    object_count = seg->objects;
  }

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
  first.seconds_before = SecondsSince(t_start);
  absl::StatusOr<MergeSummary> summary = MergeFirstOutputs(first, progress);
  if (!summary.ok()) return summary.status();
  summary->num_boundary_faces = num_boundary_faces;
  summary->num_planar_regions = num_planar_regions;
  summary->num_levels = levels->levels.size();
  summary->dense_triangles = dense_triangles;
  summary->building_triangles = building_triangles;
  summary->num_rooms = counts.value("rooms", uint64_t{0});
  summary->num_objects = object_count;
  summary->warnings = warnings;
  summary->seconds_total = SecondsSince(t_start);
  return summary;
}

}  // namespace carvemap
