// The merge of a job (DESIGN §6, §7): every output the tiles give today, stage by stage, out of
// core where the stage allows:
//   boundary_faces   faces between interior and exterior leaves (§4.3.2, Fig 4.9)
//   planar_regions   flood fill, PCA growing, 15° relaxation (§4.2.4)
//   levels           floors and ceilings from horizontal regions (§5.2) ➜ levels.json
//   dense_mesh       dual contouring (§4.3.3) ➜ mesh/dense.ply
//   planar_mesh      eq 4.9 vertices + §4.2.5 triangulation ➜ mesh/building.ply (face property
//                    `region`)
//   octree_bt, topdown_png, job_json   MergeFirstOutputs: octree.bt, level_<k>/topdown.png per
//                    level, job.json last (its presence means the merge finished)
// Every file goes through "<name>.partial" and a rename. A planar mesh that cannot be built is
// not fatal: job.json then lists the reason under "warnings" and omits mesh/building.ply.
#pragma once

#include "absl/status/statusor.h"
#include "services/merge/first_outputs.h"

namespace carvemap {

// Progress stages are the names above; errors are MergeFirstOutputs's, those of each stage
// (naming the stage), and Cancelled when `progress` returns false.
absl::StatusOr<MergeSummary> RunMerge(const MergeOptions& options,
                                      const MergeProgressCallback& progress = nullptr);

}  // namespace carvemap
