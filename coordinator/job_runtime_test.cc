#include "coordinator/job_runtime.h"

#include <gtest/gtest.h>

#include <chrono>

namespace carvemap {
namespace {

using Time = StageTimes::Time;
using std::chrono::milliseconds;

const Time kT0 = Time{} + std::chrono::hours(1);

Time At(double s) { return kT0 + milliseconds(static_cast<int64_t>(s * 1000)); }

TEST(StageTimesTest, ListsStagesInOrderWithTheRunningOneUpToNow) {
  StageTimes t;
  EXPECT_TRUE(t.List(At(0)).empty());
  EXPECT_EQ(t.RunningSeconds(At(3)), 0.0);
  t.Enter("ingest", At(0));
  t.Enter("carve", At(2));
  t.Enter("merge", At(10));
  t.Enter("merge/levels", At(11));
  const std::vector<StageTimes::Stage> list = t.List(At(12.5));
  ASSERT_EQ(list.size(), 4u);
  EXPECT_EQ(list[0].name, "ingest");
  EXPECT_DOUBLE_EQ(list[0].elapsed_s, 2);
  EXPECT_TRUE(list[0].finished);
  EXPECT_DOUBLE_EQ(list[1].elapsed_s, 8);
  EXPECT_EQ(list[3].name, "merge/levels");
  EXPECT_DOUBLE_EQ(list[3].elapsed_s, 1.5);
  EXPECT_FALSE(list[3].finished);
  EXPECT_EQ(t.running(), "merge/levels");
  EXPECT_DOUBLE_EQ(t.RunningSeconds(At(12.5)), 1.5);
  // Finished stages with their seconds, the running one as entered.
  EXPECT_EQ(
      t.Seconds(),
      (nlohmann::json{{"ingest", 2.0}, {"carve", 8.0}, {"merge", 1.0}, {"merge/levels", 0.0}}));
}

TEST(StageTimesTest, AStageEnteredAgainIsListedOnceWithItsLastRun) {
  StageTimes t;
  t.Enter("merge", At(0));
  t.Enter("merge/dense", At(5));
  t.Enter("merge", At(7));  // retried on another merge service
  t.Enter("", At(9));
  const std::vector<StageTimes::Stage> list = t.List(At(20));
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].name, "merge");
  EXPECT_DOUBLE_EQ(list[0].elapsed_s, 2);
  EXPECT_TRUE(list[0].finished && list[1].finished);
  EXPECT_EQ(t.running(), "");
}

TEST(ProgressOfTest, CarvingEtaFollowsTheHeartbeatsRate) {
  JobRuntime rt;
  rt.rays_to_carve = 1000;
  rt.rays_carved = 100;           // slices completed
  rt.carve_rate.Add(At(0), 200);  // heartbeats, mid-slice too
  rt.carve_rate.Add(At(10), 200);
  JobCounters c;
  c.chunks_total = 8;
  c.chunks_done = 2;
  const JobProgress p = ProgressOf(rt, c, JobState::kCarving, At(10));
  EXPECT_EQ(p.rays_done, 400);  // the heartbeats' 400 over the completions' 100
  EXPECT_EQ(p.rays_total, 1000);
  EXPECT_GT(p.rays_per_s, 0);
  EXPECT_NEAR(p.eta_s, 600 / p.rays_per_s, 1e-9);
}

TEST(ProgressOfTest, OnceEveryRayIsCarvedTheCombinesRateGivesTheEta) {
  JobRuntime rt;
  rt.rays_to_carve = 1000;
  rt.rays_carved = 1000;
  rt.carve_rate.Add(At(0), 1500);  // more than planned: never shown past the plan
  rt.task_rate.Add(At(0), 1);
  rt.task_rate.Add(At(4), 4);
  JobCounters c;
  c.chunks_total = 20;
  c.chunks_done = 10;
  const JobProgress p = ProgressOf(rt, c, JobState::kCarving, At(4));
  EXPECT_EQ(p.rays_done, 1000);
  ASSERT_GT(rt.task_rate.Rate(At(4)), 0);
  EXPECT_NEAR(p.eta_s, 10 / rt.task_rate.Rate(At(4)), 1e-9);
}

TEST(ProgressOfTest, MergingEtaFollowsTheStagesCounts) {
  JobRuntime rt;
  rt.stages.Enter("merge/objects", At(0));
  rt.merge_done = 25;
  rt.merge_total = 100;
  const JobProgress p = ProgressOf(rt, JobCounters{}, JobState::kMerging, At(10));
  EXPECT_EQ(p.stage_done, 25);
  EXPECT_EQ(p.stage_total, 100);
  EXPECT_DOUBLE_EQ(p.eta_s, 30);
  EXPECT_EQ(p.rays_total, 0);
  ASSERT_EQ(p.stages.size(), 1u);
  // Not known before the stage counted anything; a re-carve during the merge is a carve.
  rt.merge_done = 0;
  EXPECT_LT(ProgressOf(rt, JobCounters{}, JobState::kMerging, At(10)).eta_s, 0);
  rt.pass = 1;
  rt.rays_to_carve = 50;
  EXPECT_EQ(ProgressOf(rt, JobCounters{}, JobState::kMerging, At(10)).rays_total, 50);
}

TEST(MergeJobDocumentTest, HoldsTheJobAndTheCarveCountsWhenEverySliceReported) {
  JobRecord job;
  job.id = "j-1";
  job.input_path = "uploads/scan.h5";
  job.output_name = "office";
  job.params_json = R"({"resolution_m":0.0625})";
  JobRuntime rt;
  rt.rays_carved = 900;
  rt.slices.resize(2);
  rt.slice_s = 12.5;
  rt.slices_counted = 2;
  rt.carve_counts = {
      {"rays", 1000.0}, {"partial_bytes", 18000.0}, {"frames", 40.0}, {"votes", 5.0}};
  rt.north = {{"mode", "none"}};
  rt.stages.Enter("ingest", At(0));
  rt.stages.Enter("carve", At(1));
  JobCounters counters;
  counters.chunks_total = 9;
  counters.chunk_retries = 1;
  nlohmann::json doc = MergeJobDocument(job, counters, rt);
  EXPECT_EQ(doc["job_id"], "j-1");
  EXPECT_EQ(doc["input_path"], "uploads/scan.h5");
  EXPECT_EQ(doc["params"]["resolution_m"], 0.0625);
  EXPECT_EQ(doc["rays_carved"], 900);
  EXPECT_EQ(doc["chunks_total"], 9);
  EXPECT_EQ(doc["chunk_retries"], 1);
  EXPECT_EQ(doc["stage_seconds"]["ingest"], 1.0);
  EXPECT_EQ(doc["north"]["mode"], "none");
  EXPECT_EQ(doc["carve"]["partial_bytes_per_ray"], 18.0);
  EXPECT_EQ(doc["carve"]["slices"], 2);
  EXPECT_EQ(doc["carve"]["slice_s"], 12.5);
  EXPECT_EQ(doc["ingest"], (nlohmann::json{{"frames", 40.0}, {"rays", 1000.0}}));
  // After a restart fewer slices reported their counts: none are written, nor the store's.
  rt.slices_counted = 1;
  doc = MergeJobDocument(job, std::nullopt, rt);
  EXPECT_FALSE(doc.contains("ingest"));
  EXPECT_FALSE(doc.contains("chunks_total"));
  EXPECT_EQ(doc["carve"], (nlohmann::json{{"slices", 2}, {"slice_s", 12.5}}));
}

}  // namespace
}  // namespace carvemap
