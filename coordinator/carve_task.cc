#include "coordinator/carve_task.h"

#include "absl/strings/str_cat.h"
#include "coordinator/job_plan.h"
#include "geometry/octree_keys.h"

namespace carvemap {

absl::StatusOr<CarveTask> CarveTaskOf(const LeaseTable::Grant& grant, const JobRuntime& rt,
                                      const std::string& scan_root) {
  CarveTask task;
  task.grant = grant;
  task.resolution_m = rt.params.resolution_m;
  task.method = rt.params.method;
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(rt.params.resolution_m);
  task.leaf_depth = grid.ok() ? grid->chunk_depth : 0;
  task.tile_dir = rt.tiles_dir;
  task.evaluation = rt.params.evaluation;
  task.world_yaw_rad = rt.world_yaw_rad;
  if (!IsSliceTask(grant.chunk)) {
    CombineWork combine;
    for (const ScanSlice& s : rt.slices) {
      combine.partial_paths.push_back(SlicePartialPath(rt.pass_dir, s.index));
    }
    task.work = std::move(combine);
    return task;
  }
  const uint32_t index = uint32_t(grant.chunk.y);
  if (index >= rt.slices.size()) {
    return absl::InternalError(
        absl::StrCat("lease ", grant.lease_id, ": no slice ", grant.chunk.y, " in the job's plan"));
  }
  const ScanSlice& slice = rt.slices[index];
  SliceWork work;
  work.index = slice.index;
  work.pass = rt.pass;
  work.scan_root = scan_root;
  work.scan_path = rt.input_path;
  work.own = slice.own;
  work.read = slice.read;
  work.own_rays = slice.own_rays;
  work.partial_path = SlicePartialPath(rt.pass_dir, slice.index);
  work.regions_path = rt.regions_path;
  task.work = std::move(work);
  return task;
}

}  // namespace carvemap
