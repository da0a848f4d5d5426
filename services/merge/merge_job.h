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
//   octree_bt, topdown_png, job_json   MergeFirstOutputs: octree.bt, level_<k>/topdown.png per
//                    level, job.json last (its presence means the merge finished)
// Every file goes through "<name>.partial" and a rename. A stage that cannot make its output
// for a reason of the data (no scan, no level, a planar mesh that fails) is not fatal: job.json
// lists why under "warnings"; when the building's planar mesh fails, building.ply is the
// building volume's dense mesh instead (counts.building_planar = false).
#pragma once

#include "absl/status/statusor.h"
#include "services/merge/first_outputs.h"

namespace carvemap {

// Progress stages are the names above; errors are MergeFirstOutputs's, those of each stage
// (naming the stage), and Cancelled when `progress` returns false.
absl::StatusOr<MergeSummary> RunMerge(const MergeOptions& options,
                                      const MergeProgressCallback& progress = nullptr);

}  // namespace carvemap
