#include "services/merge/merge_params.h"

#include <cmath>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "geometry/octree_keys.h"
#include "services/floorplan/floorplan_pipeline.h"

namespace carvemap {

absl::Status MergeParams::Validate() const {
  for (const auto& [name, value] :
       {std::pair{"resolution_m", resolution_m}, {"object_resolution_m", object_resolution_m}}) {
    if (value == 0) continue;
    if (absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(value); !grid.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("merge: ", name, ": ", grid.status().message()));
    }
  }
  if (absl::Status s = ParseFloorPlanMethod(floorplan_method).status(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("merge: floorplan_method: ", s.message()));
  }
  if (!std::isfinite(min_object_volume_m3)) {
    return absl::InvalidArgumentError("merge: min_object_volume_m3 must be finite");
  }
  if (!std::isfinite(world_yaw_rad)) {
    return absl::InvalidArgumentError("merge: world_yaw_rad must be finite");
  }
  return absl::OkStatus();
}

}  // namespace carvemap
