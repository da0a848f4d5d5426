#include "coordinator/carve_task.h"

#include <gtest/gtest.h>

#include "absl/strings/match.h"

namespace carvemap {
namespace {

JobRuntime Runtime() {
  JobRuntime rt;
  rt.params.resolution_m = 0.0625;
  rt.params.evaluation = CarveEvaluation::kExact;
  rt.tiles_dir = "/srv/out/t/tiles";
  rt.pass_dir = "/srv/work/j-1/partials";
  rt.input_path = "uploads/scan.h5";
  rt.world_yaw_rad = 0.25;
  for (uint32_t k = 0; k < 3; ++k) {
    ScanSlice s;
    s.index = k;
    s.own = {{100 * k, 100 * k + 100}};
    s.read = {{100 * k, 100 * k + 120}};
    s.own_rays = 1000 + k;
    rt.slices.push_back(s);
  }
  return rt;
}

LeaseTable::Grant Grant(ChunkCoord key) {
  LeaseTable::Grant g;
  g.job_id = "j-1";
  g.chunk = key;
  g.lease_id = "j-1/lease-7";
  g.generation = 3;
  g.attempt = 2;
  return g;
}

TEST(CarveTaskTest, ASliceReadsItsRowsAndWritesItsPartialSums) {
  JobRuntime rt = Runtime();
  absl::StatusOr<CarveTask> task = CarveTaskOf(Grant(SliceTaskKey(1, 0)), rt, "/srv/data/acme");
  ASSERT_TRUE(task.ok()) << task.status();
  EXPECT_EQ(task->grant.lease_id, "j-1/lease-7");
  EXPECT_EQ(task->resolution_m, 0.0625);
  EXPECT_EQ(task->leaf_depth, 5);  // 2 m chunks of 6.25 cm leaves
  EXPECT_EQ(task->tile_dir, "/srv/out/t/tiles");
  EXPECT_EQ(task->evaluation, CarveEvaluation::kExact);
  EXPECT_EQ(task->world_yaw_rad, 0.25);
  const SliceWork* slice = std::get_if<SliceWork>(&task->work);
  ASSERT_NE(slice, nullptr);
  EXPECT_EQ(slice->index, 1u);
  EXPECT_EQ(slice->pass, 0);
  EXPECT_EQ(slice->scan_root, "/srv/data/acme");
  EXPECT_EQ(slice->scan_path, "uploads/scan.h5");
  ASSERT_EQ(slice->own.size(), 1u);
  EXPECT_EQ(slice->own[0].begin, 100u);
  EXPECT_EQ(slice->read[0].end, 220u);
  EXPECT_EQ(slice->own_rays, 1001u);
  EXPECT_EQ(slice->partial_path, "/srv/work/j-1/partials/slice_1.part");
  EXPECT_EQ(slice->regions_path, "");
}

TEST(CarveTaskTest, ARecarvePassWritesBesideItsRegions) {
  JobRuntime rt = Runtime();
  rt.pass = 2;
  rt.pass_dir = "/srv/work/j-1/partials/p2-ab12";
  rt.regions_path = rt.pass_dir + "/regions.bin";
  rt.params.resolution_m = 0.03125;
  absl::StatusOr<CarveTask> task = CarveTaskOf(Grant(SliceTaskKey(2, 2)), rt, "/srv/data");
  ASSERT_TRUE(task.ok()) << task.status();
  EXPECT_EQ(task->leaf_depth, 6);
  const SliceWork& slice = std::get<SliceWork>(task->work);
  EXPECT_EQ(slice.pass, 2);
  EXPECT_EQ(slice.partial_path, "/srv/work/j-1/partials/p2-ab12/slice_2.part");
  EXPECT_EQ(slice.regions_path, "/srv/work/j-1/partials/p2-ab12/regions.bin");
}

TEST(CarveTaskTest, AChunkCombinesEverySliceOfThePassInOrder) {
  JobRuntime rt = Runtime();
  absl::StatusOr<CarveTask> task = CarveTaskOf(Grant({3, -1, 0}), rt, "/srv/data");
  ASSERT_TRUE(task.ok()) << task.status();
  const CombineWork* combine = std::get_if<CombineWork>(&task->work);
  ASSERT_NE(combine, nullptr);
  EXPECT_EQ(combine->partial_paths,
            (std::vector<std::string>{"/srv/work/j-1/partials/slice_0.part",
                                      "/srv/work/j-1/partials/slice_1.part",
                                      "/srv/work/j-1/partials/slice_2.part"}));
}

TEST(CarveTaskTest, ASliceThePlanDoesNotHaveIsAnInternalError) {
  absl::StatusOr<CarveTask> task = CarveTaskOf(Grant(SliceTaskKey(7, 0)), Runtime(), "/d");
  EXPECT_TRUE(absl::IsInternal(task.status())) << task.status();
  EXPECT_TRUE(absl::StrContains(task.status().message(), "no slice 7"));
}

}  // namespace
}  // namespace carvemap
