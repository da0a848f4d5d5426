#include "services/rpc/worker_metrics.h"

#include <gtest/gtest.h>

#include "services/rpc/metrics_text.h"

namespace carvemap {
namespace {

TEST(WorkerMetricsTest, CountsTasksRaysAndBytes) {
  WorkerMetrics m;
  m.TaskStarted();
  m.TaskStarted();
  m.RaysCarved(700);
  m.RaysCarved(300);
  m.TaskFinished("slice", true, 3.0, 5000);
  m.TaskFinished("combine", false, 0.2, 999);  // a failed task's bytes are not counted
  m.TaskStarted();
  auto s = ParsePrometheusText(m.Text());
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(SumOf(*s, "carvemap_worker_rays_carved_total"), 1000);
  EXPECT_EQ(SumOf(*s, "carvemap_worker_tasks_running"), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_worker_tasks_total", {{"kind", "slice"}, {"result", "ok"}}), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_worker_tasks_total", {{"result", "failed"}}), 1);
  EXPECT_EQ(SumOf(*s, "carvemap_worker_bytes_written_total"), 5000);
  EXPECT_EQ(SumOf(*s, "carvemap_worker_task_seconds_count"), 2);
  EXPECT_DOUBLE_EQ(SumOf(*s, "carvemap_worker_task_seconds_sum", {{"kind", "slice"}}), 3.0);
}

}  // namespace
}  // namespace carvemap
