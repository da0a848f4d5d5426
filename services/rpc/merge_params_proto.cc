#include "services/rpc/merge_params_proto.h"

#include "proto/carvemap/v1/merge.pb.h"

namespace carvemap {

void MergeParamsToProto(const MergeParams& params, v1::MergeJob* job) {
  job->set_resolution_m(params.resolution_m);
  job->set_object_resolution_m(params.object_resolution_m);
  job->set_floorplan_method(params.floorplan_method);
  job->set_trimmed_points(params.trimmed_points);
  job->set_min_object_volume_m3(params.min_object_volume_m3);
  job->set_world_yaw_rad(params.world_yaw_rad);
}

MergeParams MergeParamsFromProto(const v1::MergeJob& job) {
  MergeParams params;
  params.resolution_m = job.resolution_m();
  params.object_resolution_m = job.object_resolution_m();
  if (!job.floorplan_method().empty()) params.floorplan_method = job.floorplan_method();
  params.trimmed_points = job.trimmed_points();
  params.min_object_volume_m3 = job.min_object_volume_m3();
  params.world_yaw_rad = job.world_yaw_rad();
  return params;
}

}  // namespace carvemap
