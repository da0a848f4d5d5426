#include "services/rpc/merge_params_proto.h"

#include <gtest/gtest.h>

#include "proto/carvemap/v1/merge.pb.h"

namespace carvemap {
namespace {

TEST(MergeParamsProto, RoundTripsEveryField) {
  const MergeParams params{.resolution_m = 0.125,
                           .object_resolution_m = 0.0625,
                           .floorplan_method = "eigencrust",
                           .trimmed_points = true,
                           .min_object_volume_m3 = 0.01,
                           .world_yaw_rad = 1.25};
  v1::MergeJob job;
  job.set_job_id("j");
  MergeParamsToProto(params, &job);
  EXPECT_EQ(job.job_id(), "j");  // the caller's fields are left alone
  v1::MergeJob wire;
  ASSERT_TRUE(wire.ParseFromString(job.SerializeAsString()));
  EXPECT_EQ(MergeParamsFromProto(wire), params);
}

TEST(MergeParamsProto, AnEmptyMessageGivesTheDefaults) {
  EXPECT_EQ(MergeParamsFromProto(v1::MergeJob{}), MergeParams{});
}

}  // namespace
}  // namespace carvemap
