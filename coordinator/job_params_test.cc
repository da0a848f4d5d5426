#include "coordinator/job_params.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace carvemap {
namespace {

TEST(JobParamsTest, EmptyRequestGivesTheDefaults) {
  absl::StatusOr<JobParams> p = ResolveJobParams({});
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->resolution_m, 0.0625);
  EXPECT_EQ(p->method, CarveMethod::kProbabilistic);
  EXPECT_EQ(p->workers_hint, 0);
  EXPECT_EQ(p->object_resolution_m, 0.03125);  // half the leaf: §5.6.1's re-carve
  EXPECT_EQ(p->floorplan_method, "rooms");
  EXPECT_FALSE(p->trimmed_points);
  EXPECT_EQ(p->min_object_volume_m3, 0);
  EXPECT_EQ(p->evaluation, CarveEvaluation::kFast);
}

TEST(JobParamsTest, ObjectResolutionStopsAtTheFinestLeaf) {
  absl::StatusOr<JobParams> p = ResolveJobParams({.resolution_m = 0.0078125});
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->object_resolution_m, 0.0078125);  // no re-carve finer than the finest
}

TEST(JobParamsTest, EveryFieldTakesItsValue) {
  absl::StatusOr<JobParams> p = ResolveJobParams({.resolution_m = 0.03125,
                                                  .method = 1,
                                                  .workers_hint = 4,
                                                  .object_resolution_m = 0.015625,
                                                  .floorplan_method = "eigencrust",
                                                  .trimmed_points = true,
                                                  .min_object_volume_m3 = 0.01,
                                                  .evaluation = 2});
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->resolution_m, 0.03125);
  EXPECT_EQ(p->workers_hint, 4);
  EXPECT_EQ(p->object_resolution_m, 0.015625);
  EXPECT_EQ(p->floorplan_method, "eigencrust");
  EXPECT_TRUE(p->trimmed_points);
  EXPECT_EQ(p->min_object_volume_m3, 0.01);
  EXPECT_EQ(p->evaluation, CarveEvaluation::kExact);
  // What the merge gets: these, with the turn the tiles were carved with.
  EXPECT_EQ(p->merge_params(0.5), (MergeParams{.resolution_m = 0.03125,
                                               .object_resolution_m = 0.015625,
                                               .floorplan_method = "eigencrust",
                                               .trimmed_points = true,
                                               .min_object_volume_m3 = 0.01,
                                               .world_yaw_rad = 0.5}));
}

TEST(JobParamsTest, BadFieldsFailNamingThem) {
  struct Case {
    JobParamsRequest request;
    absl::StatusCode code;
    const char* names;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Case cases[] = {
      {{.resolution_m = 0.05}, absl::StatusCode::kInvalidArgument, "resolution_m 0.05"},
      {{.resolution_m = 0.125}, absl::StatusCode::kInvalidArgument, "resolution_m"},  // k = 4
      {{.resolution_m = 0.00390625}, absl::StatusCode::kInvalidArgument, "resolution_m"},
      {{.method = 2}, absl::StatusCode::kUnimplemented, "VOXEL"},
      {{.method = 7}, absl::StatusCode::kInvalidArgument, "unknown method 7"},
      {{.workers_hint = -1}, absl::StatusCode::kInvalidArgument, "workers_hint"},
      {{.object_resolution_m = 0.125},
       absl::StatusCode::kInvalidArgument,
       "object_resolution_m 0.125"},  // coarser than the job's leaves
      {{.object_resolution_m = 0.02}, absl::StatusCode::kInvalidArgument, "object_resolution_m"},
      {{.floorplan_method = "voronoi"}, absl::StatusCode::kInvalidArgument, "floorplan_method"},
      {{.min_object_volume_m3 = -1}, absl::StatusCode::kInvalidArgument, "min_object_volume_m3"},
      {{.min_object_volume_m3 = nan}, absl::StatusCode::kInvalidArgument, "min_object_volume_m3"},
      {{.evaluation = 3}, absl::StatusCode::kInvalidArgument, "unknown evaluation 3"},
      {{.north = "true"}, absl::StatusCode::kInvalidArgument, "north: 'true'"},
      {{.location = "91,0"}, absl::StatusCode::kInvalidArgument, "location '91,0'"},
      {{.survey_date = "2026-01-01"}, absl::StatusCode::kInvalidArgument, "survey_date"},
  };
  for (const Case& c : cases) {
    absl::StatusOr<JobParams> p = ResolveJobParams(c.request);
    ASSERT_FALSE(p.ok()) << c.names;
    EXPECT_EQ(p.status().code(), c.code) << p.status();
    EXPECT_NE(p.status().message().find(c.names), std::string::npos) << p.status();
  }
}

TEST(JobParamsTest, JsonRoundTrip) {
  absl::StatusOr<JobParams> p = ResolveJobParams({.resolution_m = 0.03125,
                                                  .workers_hint = 3,
                                                  .floorplan_method = "eigencrust",
                                                  .trimmed_points = true,
                                                  .min_object_volume_m3 = 0.002,
                                                  .evaluation = 2,
                                                  .north = "magnetic",
                                                  .location = "48.1,11.6",
                                                  .survey_date = "2026-11-28"});
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->north, NorthMode::kMagnetic);
  EXPECT_EQ(JobParams::FromJson(p->ToJson()), *p);
  JobParams defaults;
  EXPECT_EQ(JobParams::FromJson(defaults.ToJson()), defaults);
}

TEST(JobParamsTest, JsonTextIsFixed) {
  // Stored jobs are compared by this text (a resubmission with the same idempotency key):
  // it must not change for the same values.
  EXPECT_EQ(JobParams{}.ToJson(),
            R"({"evaluation":"fast","floorplan_method":"rooms","method":1,)"
            R"("min_object_volume_m3":0.0,"north":"auto","object_resolution_m":0.0625,)"
            R"("resolution_m":0.0625,)"
            R"("trimmed_points":false,"workers_hint":0})");
}

TEST(JobParamsTest, JobsStoredBeforeAKeyExistedResumeAsTheyRan) {
  const JobParams p = JobParams::FromJson(R"({"resolution_m":0.03125,"method":1})");
  EXPECT_EQ(p.resolution_m, 0.03125);
  EXPECT_EQ(p.object_resolution_m, 0.03125);  // no re-carve
  EXPECT_EQ(p.evaluation, CarveEvaluation::kExact);
  EXPECT_EQ(p.floorplan_method, "rooms");
  EXPECT_EQ(p.north, NorthMode::kNone);  // carved in the scan's frame
  // Not an object: the defaults.
  EXPECT_EQ(JobParams::FromJson("not json"), JobParams{});
  EXPECT_EQ(JobParams::FromJson("[1, 2]"), JobParams{});
}

}  // namespace
}  // namespace carvemap
