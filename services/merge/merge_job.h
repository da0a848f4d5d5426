// The merge of a job (docs/DESIGN.md §6, §7): every output the tiles give today, stage by stage,
// out of core where the stage allows:
//   boundary_faces   faces between interior and exterior leaves (§4.3.2, Fig 4.9)
//   planar_regions   flood fill, PCA growing, 15° relaxation (§4.2.4)
//   levels           floors and ceilings from horizontal regions (§5.2) ➜ levels.json
//   floorplan        wall samples, rooms, extrusion per level (§5.3, §3.3) ➜
//                    level_<k>/floorplan.geojson, floorplan.svg, extruded.ply (needs the scan)
//   dense_mesh       dual contouring (§4.3.3) ➜ mesh/dense.ply
//   segmentation     with floor plans: every tile split against the extruded plans into
//                    building and object tiles (§5.5 trimming, §5.6; services/segment), in
//                    <out>/.segment while the merge runs
//   trimmed_points   with MergeOptions::trimmed_points: the scan's points without those the
//                    plans trim (§5.5; services/merge/trimmed_points.h) ➜ points.ply
//   building_faces, planar_mesh   the building tiles' faces, regions and planar mesh ➜
//                    mesh/building.ply (face property `region`); without floor plans the
//                    planar mesh of everything
//   recarve, recarve_segmentation   with MergeOptions::recarve (§5.6.1): the chunks holding
//                    objects carved again at object_resolution_m around their objects, and
//                    segmented again, in <out>/.segment/finer_objects. The building's faces
//                    and planar mesh are made while the caller re-carves (its workers' wait is
//                    the merge's idle time), reporting no stage of their own
//   object_mesh      dual contouring of the (finer) object tiles, split into objects ➜
//                    mesh/objects.ply (face property `object`), mesh/objects/<id>.ply,
//                    mesh/combined.ply (`object`, −1 = building); job.json "objects"
//   octree_bt, topdown_png, job_json
//                    MergeFirstOutputs: octree.bt, octree.ot, level_<k>/topdown.png per
//                    level, job.json last (its presence means the merge finished)
// Every file goes through "<name>.partial" and a rename. A stage that cannot make its output
// for a reason of the data (no scan, no level, a planar mesh that fails) is not fatal: job.json
// lists why under "warnings"; when the building's planar mesh fails, building.ply is the
// building volume's dense mesh instead (counts.building_planar = false).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/chunk_region.h"
#include "services/merge/first_outputs.h"
#include "services/merge/merge_params.h"

namespace carvemap {

// The job's parameters (MergeParams) and where and how this process runs its merge.
struct MergeOptions : MergeParams {
  std::string tiles_dir;   // holds c_<x>_<y>_<z>.h5 tiles (storage/TILE_FORMAT.md)
  std::string output_dir;  // created if missing; existing outputs are replaced
  // The caller's job document: FirstOutputsOptions::job.
  nlohmann::json job = nlohmann::json::object();
  // Bound on the decoded tiles each stage holds at once (TileSet's LRU cache).
  uint64_t cache_budget_bytes = uint64_t{256} << 20;
  // Threads for the per-chunk stages (boundary faces, dense meshes, segmentation,
  // self-intersections); ≤ 0: the CPUs the process may use (UsableCpus: affinity and cgroup
  // quota). The outputs do not depend on it.
  int threads = 0;
  // The most memory the merge process may hold, bytes; 0 = no bound. The memory of the planar
  // regions (a slab of heights for the levels, a level for its floor plan) and of the
  // building's planar mesh (a level's part of the building) grows with their boundary faces:
  // before each, RunMerge estimates it (kPlanarBytesPerFace, services/merge/memory_budget.h)
  // and fails with ResourceExhausted, naming the level, the estimate and this budget, rather
  // than be killed for memory later.
  uint64_t memory_budget_bytes = 0;
  double topdown_max_height_m = 3.0;  // FirstOutputsOptions::topdown_max_height_m
  // False skips the meshing stages (faces, regions, levels, dense and planar meshes), leaving
  // the first outputs.
  bool meshes = true;
  // The meshing stages read the tiles with their thin unobserved pockets (enclosed by free
  // space) filled as free (services/segment/fill_pockets.h): no floating surface around air no
  // scanner swept. False: they read the job's tiles as carved. The first outputs always do.
  bool fill_pockets = true;
  // The job's scan.h5 (docs/DESIGN.md §3), whose /path (poses, small) gives the floor plans
  // their scanner positions (§3.3.1 lines of sight, §3.3.2 unentered rooms), and whose returns
  // make points.ply. Empty: no floor plans and no points.ply (job.json says why under
  // "warnings"; the other outputs do not depend on them, so the job goes on).
  std::string scan_path;
  // Carves each of `chunks`, inside its region only, at `resolution_m` into one tile each and
  // returns the directory that holds them (storage/TILE_FORMAT.md names): §5.6.1's re-carve at
  // object_resolution_m, which needs the job's wedges the merge does not have (the coordinator
  // leases the chunks to its workers; tests carve in process). Errors fail the merge. Empty:
  // the objects come from the job's tiles.
  std::function<absl::StatusOr<std::string>(const std::vector<RecarveChunk>& chunks,
                                            double resolution_m)>
      recarve;

  // MergeParams::Validate, and InvalidArgument for empty dirs, a non-object job or a
  // non-positive topdown_max_height_m.
  [[nodiscard]] absl::Status Validate() const;
  // What MergeFirstOutputs gets: these folders, job, cache and scale; the caller adds the levels.
  [[nodiscard]] FirstOutputsOptions FirstOutputs() const;
};

// Progress stages are the names above; errors are MergeFirstOutputs's, those of each stage
// (naming the stage), and Cancelled when `progress` returns false.
absl::StatusOr<MergeSummary> RunMerge(const MergeOptions& options,
                                      const MergeProgressCallback& progress = nullptr);

}  // namespace carvemap
