#include "coordinator/job_plan.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "services/sim/simulator.h"
#include "storage/partial_sums.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

std::string TempDir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("job_plan_test_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// The plan of a simulated scan: the slices PlanScanSlices makes, and the north as the mode
// says (no magnetometer decision needed with "none").
TEST(JobPlanTest, PlansTheSlicesAndTheTurnOfAScan) {
  SimulateOptions sim;
  sim.preset = "office";
  sim.rig.rate_hz = 3;
  sim.rig.beam_step_deg = 2;
  sim.max_duration_s = 12;
  sim.output_dir = TempDir("scan");
  absl::StatusOr<SimulationSummary> simulated = Simulate(sim);
  ASSERT_TRUE(simulated.ok()) << simulated.status();
  JobParams params;
  params.north = NorthMode::kNone;
  absl::StatusOr<JobPlan> plan = PlanJob(simulated->scan_path, params);
  ASSERT_TRUE(plan.ok()) << plan.status();
  EXPECT_GE(plan->slices.slices.size(), 4u);
  EXPECT_GT(plan->slices.rays, 0u);
  uint64_t own = 0;
  for (const ScanSlice& s : plan->slices.slices) own += s.own_rays;
  EXPECT_EQ(own, plan->slices.rays);  // the slices' own rows partition the scan
  EXPECT_FALSE(plan->north.decision.turned);
  EXPECT_EQ(plan->north.decision.yaw_rad, 0);

  const std::vector<ChunkRecord> tasks = SliceTasks("j-1", plan->slices.slices, 2);
  ASSERT_EQ(tasks.size(), plan->slices.slices.size());
  for (size_t k = 0; k < tasks.size(); ++k) {
    EXPECT_EQ(tasks[k].job_id, "j-1");
    EXPECT_EQ(tasks[k].key, SliceTaskKey(plan->slices.slices[k].index, 2));
    EXPECT_EQ(tasks[k].wedge_count, int64_t(plan->slices.slices[k].own_rays));
  }
}

TEST(JobPlanTest, AScanThatCannotBeReadNamesTheFile) {
  const std::string path = TempDir("bad") + "/scan.h5";
  std::ofstream(path) << "not hdf5";
  absl::StatusOr<JobPlan> plan = PlanJob(path, JobParams{});
  ASSERT_FALSE(plan.ok());
  EXPECT_TRUE(absl::StrContains(plan.status().message(), "scan.h5")) << plan.status();
}

TEST(JobPlanTest, ChunksOfPartialsAreTheSortedUnionOfTheFilesSections) {
  const std::string dir = TempDir("partials");
  const std::vector<std::vector<ChunkKey>> files = {
      {ChunkKey(1, 0, 0), ChunkKey(-1, 2, 0), ChunkKey(1, 0, 0)},
      {ChunkKey(-1, 2, 0), ChunkKey(0, 0, -3)}};
  std::vector<std::string> paths;
  for (size_t f = 0; f < files.size(); ++f) {
    paths.push_back(SlicePartialPath(dir, uint32_t(f)));
    auto w = PartialSumsWriter::Create(paths.back(), 5, uint32_t(f));
    ASSERT_TRUE(w.ok()) << w.status();
    for (const ChunkKey& c : files[f]) ASSERT_TRUE((*w)->AddSection(c, 1, {}).ok());
    ASSERT_TRUE((*w)->Finish().ok());
  }
  EXPECT_EQ(paths[1], dir + "/slice_1.part");
  absl::StatusOr<std::vector<ChunkCoord>> chunks = ChunksOfPartials(paths);
  ASSERT_TRUE(chunks.ok()) << chunks.status();
  EXPECT_EQ(*chunks, (std::vector<ChunkCoord>{{-1, 2, 0}, {0, 0, -3}, {1, 0, 0}}));
  paths.push_back(SlicePartialPath(dir, 9));
  absl::StatusOr<std::vector<ChunkCoord>> missing = ChunksOfPartials(paths);
  EXPECT_TRUE(absl::IsNotFound(missing.status())) << missing.status();
  EXPECT_TRUE(absl::StrContains(missing.status().message(), "slice_9.part"));
}

}  // namespace
}  // namespace carvemap
