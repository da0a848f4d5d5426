// The parameters of a job that decide what its merge makes (docs/DESIGN.md §6): declared once
// here and carried as this struct from the coordinator's resolved job parameters
// (coordinator/job_params.h, JobParams::merge_params) through MergeJobRequest
// (services/rpc/merge_request.h) and the MergeJob message (services/rpc/merge_params_proto.h
// converts both ways) to RunMerge (MergeOptions, services/merge/merge_job.h), which is also
// what `carvemap merge` fills from its flags. Where and how a process runs the merge (folders,
// threads, memory) is not here. Plain data.
#pragma once

#include <string>

#include "absl/status/status.h"

namespace carvemap {

struct MergeParams {
  // Leaf size of the tiles, 2 m / 2^k; 0 = take it from the tiles (when set, every tile must
  // have it, else InvalidArgument naming the tile).
  double resolution_m = 0;
  // §5.6.1 (Fig 5.17): the chunks that hold objects are carved again at this finer leaf size,
  // so that the furniture's boards, legs and rods, thinner than a cell, survive. 0, equal to
  // resolution_m, or no one to carve (MergeOptions::recarve): the objects come from the tiles.
  double object_resolution_m = 0;
  // The floor-plan method: "rooms" (§3.3) or "eigencrust" (§3.2).
  std::string floorplan_method = "rooms";
  // §5.5 on request: OUT/points.ply, the scan's returns without those the floor plans trim.
  bool trimmed_points = false;
  // §5.6: objects with less volume than this are specks, dropped, m³; ≤ 0: the default
  // (ObjectSplitOptions::min_volume_m3, 5 litres). Pieces under its speck_volume_m3 (1 litre)
  // go whatever this says.
  double min_object_volume_m3 = 0;
  // §2.3: the turn about the vertical (radians, counter-clockwise from above) the tiles were
  // carved with (ScanReader::OpenOptions::world_yaw_rad); the merge reads the scan's path and
  // points turned by it, so that they lie where the tiles do.
  double world_yaw_rad = 0;

  // InvalidArgument naming the field: a resolution that is not 2 m / 2^k, an unknown
  // floor-plan method, a volume or turn that is not finite.
  [[nodiscard]] absl::Status Validate() const;
  bool operator==(const MergeParams&) const = default;
};

}  // namespace carvemap
