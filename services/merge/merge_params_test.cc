#include "services/merge/merge_params.h"

#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "services/merge/merge_job.h"

namespace carvemap {
namespace {

TEST(MergeParams, DefaultsAreValid) { EXPECT_TRUE(MergeParams{}.Validate().ok()); }

TEST(MergeParams, EachBadFieldIsNamed) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const struct {
    MergeParams params;
    std::string field;
  } cases[] = {
      {{.resolution_m = 0.1}, "resolution_m"},
      {{.object_resolution_m = 0.05}, "object_resolution_m"},
      {{.floorplan_method = "powercrust"}, "floorplan_method"},
      {{.min_object_volume_m3 = nan}, "min_object_volume_m3"},
      {{.world_yaw_rad = std::numeric_limits<double>::infinity()}, "world_yaw_rad"},
  };
  for (const auto& c : cases) {
    const absl::Status s = c.params.Validate();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << c.field;
    EXPECT_NE(s.message().find(c.field), std::string::npos) << s;
  }
  EXPECT_TRUE((MergeParams{.resolution_m = 0.0625,
                           .object_resolution_m = 0.03125,
                           .floorplan_method = "eigencrust"})
                  .Validate()
                  .ok());
}

// RunMerge's options check the job's parameters as well as their own.
TEST(MergeOptions, ValidateChecksTheParamsAndTheFolders) {
  MergeOptions o;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);  // no folders
  o.tiles_dir = "t";
  o.output_dir = "o";
  EXPECT_TRUE(o.Validate().ok());
  o.floorplan_method = "powercrust";
  EXPECT_NE(o.Validate().message().find("floorplan_method"), std::string::npos);
  o.floorplan_method = "rooms";
  o.topdown_max_height_m = 0;
  EXPECT_NE(o.Validate().message().find("topdown_max_height_m"), std::string::npos);
}

TEST(MergeOptions, FirstOutputsCarryTheFoldersJobAndScale) {
  MergeOptions o;
  o.tiles_dir = "t";
  o.output_dir = "o";
  o.resolution_m = 0.125;
  o.job = {{"job_id", "j"}};
  o.cache_budget_bytes = 1 << 20;
  o.topdown_max_height_m = 2.5;
  const FirstOutputsOptions f = o.FirstOutputs();
  EXPECT_EQ(f.tiles_dir, "t");
  EXPECT_EQ(f.output_dir, "o");
  EXPECT_EQ(f.resolution_m, 0.125);
  EXPECT_EQ(f.job, o.job);
  EXPECT_EQ(f.cache_budget_bytes, uint64_t{1} << 20);
  EXPECT_EQ(f.topdown_max_height_m, 2.5);
  EXPECT_TRUE(f.levels.empty());
}

}  // namespace
}  // namespace carvemap
