#include "services/rpc/merge_metrics.h"

#include <gtest/gtest.h>

#include "services/rpc/metrics_text.h"

namespace carvemap {
namespace {

using std::chrono::seconds;

// Two merges on a fake clock: each stage's seconds go to its own counter, the stage gauge
// names the stage running, and the queue and running gauges follow the slot.
TEST(MergeMetricsTest, StageSecondsAndResults) {
  MergeMetrics m;
  const std::chrono::steady_clock::time_point t0{};
  m.Queued();
  m.MergeStarted(t0);
  m.Stage("boundary faces", t0);
  m.Stage("boundary faces", t0 + seconds(1));  // the same stage again: nothing changes
  m.Stage("planar mesh", t0 + seconds(3));
  auto s = ParsePrometheusText(m.Text());
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(SumOf(*s, "carvemap_merge_queued"), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_running"), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_stage", {{"stage", "planar mesh"}}), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_stage"), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_stage_seconds_total", {{"stage", "boundary faces"}}), 3);

  m.MergeFinished("succeeded", t0 + seconds(10));
  m.Dequeued();
  m.MergeStarted(t0 + seconds(20));
  m.Stage("boundary faces", t0 + seconds(20));
  m.MergeFinished("failed", t0 + seconds(22));
  s = ParsePrometheusText(m.Text());
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(SumOf(*s, "carvemap_merge_queued"), 0);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_running"), 0);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_stage"), 0);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_stage_seconds_total", {{"stage", "boundary faces"}}), 5);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_stage_seconds_total", {{"stage", "planar mesh"}}), 7);
  EXPECT_EQ(SumOf(*s, "carvemap_merges_total", {{"result", "succeeded"}}), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_merges_total", {{"result", "failed"}}), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_seconds_count"), 2);
  EXPECT_EQ(SumOf(*s, "carvemap_merge_seconds_sum"), 12);
}

}  // namespace
}  // namespace carvemap
