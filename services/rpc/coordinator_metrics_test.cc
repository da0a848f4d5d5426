#include "services/rpc/coordinator_metrics.h"

#include <cmath>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "services/rpc/metrics_text.h"

namespace carvemap {
namespace {
using ::testing::HasSubstr;

std::vector<MetricSample> Scrape(const CoordinatorMetrics& m) {
  auto samples = ParsePrometheusText(m.Text());
  EXPECT_TRUE(samples.ok()) << samples.status();
  return samples.ok() ? *samples : std::vector<MetricSample>{};
}

TEST(CoordinatorMetricsTest, CountsWhatItIsTold) {
  CoordinatorMetrics m;
  m.SetChunks(3, 1, 5);
  m.SetWorkers(2);
  m.ChunkCompleted(1000);
  m.ChunkCompleted(500);
  m.ChunkFailed();
  m.LeasesExpired(2);
  m.LeasesExpired(0);
  m.WorkerLost(1);
  m.JobSubmitted();
  m.JobFinished("SUCCEEDED");
  m.JobFinished("FAILED");
  m.JobFinished("FAILED");
  m.CallRefused("job");
  m.CallRefused("carve");
  m.CallRefused("job");
  const auto s = Scrape(m);
  EXPECT_EQ(SumOf(s, "carvemap_chunks", {{"state", "queued"}}), 3);
  EXPECT_EQ(SumOf(s, "carvemap_chunks", {{"state", "leased"}}), 1);
  EXPECT_EQ(SumOf(s, "carvemap_chunks", {{"state", "done"}}), 5);
  EXPECT_EQ(SumOf(s, "carvemap_chunks"), 9);
  EXPECT_EQ(SumOf(s, "carvemap_workers"), 2);
  EXPECT_EQ(SumOf(s, "carvemap_rays_carved_total"), 1500);
  EXPECT_EQ(SumOf(s, "carvemap_chunks_completed_total"), 2);
  EXPECT_EQ(SumOf(s, "carvemap_chunk_failures_total"), 1);
  EXPECT_EQ(SumOf(s, "carvemap_lease_expiries_total"), 2);
  EXPECT_EQ(SumOf(s, "carvemap_workers_lost_total"), 1);
  EXPECT_EQ(SumOf(s, "carvemap_jobs_submitted_total"), 1);
  EXPECT_EQ(SumOf(s, "carvemap_jobs_finished_total", {{"state", "FAILED"}}), 2);
  EXPECT_EQ(SumOf(s, "carvemap_calls_unauthenticated_total", {{"api", "job"}}), 2);
  EXPECT_EQ(SumOf(s, "carvemap_calls_unauthenticated_total"), 3);
  const std::string line = FormatCoordinatorMetrics(s);
  EXPECT_THAT(line, HasSubstr("workers 2  chunks 3 queued / 1 leased / 5 done"));
  EXPECT_THAT(line, HasSubstr("lease expiries 2  workers lost 1  refused calls 3"));
}

// PromQL's histogram_quantile on the RPC histogram: 100 calls of 1 ms and one of 1 s. The
// median's rank 50.5 falls in the bucket (0.5 ms, 1 ms] holding 100: 0.5 + 0.5 · 50.5/100 ms.
TEST(CoordinatorMetricsTest, RpcLatencyQuantiles) {
  CoordinatorMetrics m;
  for (int i = 0; i < 100; ++i) m.ObserveRpc("LeaseChunk", "OK", 0.001);
  m.ObserveRpc("LeaseChunk", "UNAVAILABLE", 1.0);
  m.ObserveRpc("GetJob", "OK", 0.004);
  const auto s = Scrape(m);
  EXPECT_EQ(SumOf(s, "carvemap_rpc_duration_seconds_count", {{"method", "LeaseChunk"}}), 101);
  EXPECT_EQ(SumOf(s, "carvemap_rpc_duration_seconds_count",
                  {{"method", "LeaseChunk"}, {"code", "UNAVAILABLE"}}),
            1);
  EXPECT_NEAR(HistogramQuantile(s, "carvemap_rpc_duration_seconds", 0.5, {{"method", "LeaseChunk"}}),
              0.0005 + 0.0005 * 50.5 / 100, 1e-12);
  // p99.5 lands in the bucket of the 1 s call: (0.512, 1.024].
  const double p995 =
      HistogramQuantile(s, "carvemap_rpc_duration_seconds", 0.995, {{"method", "LeaseChunk"}});
  EXPECT_GT(p995, 0.512);
  EXPECT_LE(p995, 1.024);
  EXPECT_TRUE(std::isnan(HistogramQuantile(s, "carvemap_rpc_duration_seconds", 0.5,
                                           {{"method", "NoSuchMethod"}})));
  EXPECT_THAT(FormatCoordinatorMetrics(s), HasSubstr("RPC p50/p99 ms: LeaseChunk 0.8/"));
}

TEST(CoordinatorMetricsTest, RaysPerSecondOverTheWindow) {
  CoordinatorMetrics m;
  const auto t0 = std::chrono::steady_clock::time_point{} + std::chrono::hours(1);
  m.UpdateRate(t0);
  EXPECT_EQ(SumOf(Scrape(m), "carvemap_rays_per_second"), 0);
  m.ChunkCompleted(2000);  // the counter of completed chunks: not the rate
  m.UpdateRate(t0 + std::chrono::seconds(1));
  EXPECT_EQ(SumOf(Scrape(m), "carvemap_rays_per_second"), 0);
  m.RaysCarvedLive(2000);  // a heartbeat's count
  m.UpdateRate(t0 + std::chrono::seconds(2));
  EXPECT_DOUBLE_EQ(SumOf(Scrape(m), "carvemap_rays_per_second"), 1000);
  // Long after, with nothing carved: the window has moved past the work.
  m.UpdateRate(t0 + std::chrono::seconds(30));
  m.UpdateRate(t0 + std::chrono::seconds(45));
  EXPECT_DOUBLE_EQ(SumOf(Scrape(m), "carvemap_rays_per_second"), 0);
}

TEST(MetricsTextTest, ParsesTheFormat) {
  auto s = ParsePrometheusText(
      "# HELP a_total things\n# TYPE a_total counter\n"
      "a_total 3\n"
      "b{x=\"1\",y=\"q\\\"uote\\\\ \\n\"} 2.5e3 1700000000\n"
      "c_bucket{le=\"+Inf\"} 7\n"
      "  \n"
      "d NaN\n");
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->size(), 4u);
  EXPECT_EQ((*s)[1].labels.at("y"), "q\"uote\\ \n");
  EXPECT_EQ((*s)[1].value, 2500);
  EXPECT_TRUE(std::isinf((*s)[2].value) == false && (*s)[2].value == 7);
  EXPECT_TRUE(std::isnan((*s)[3].value));
  EXPECT_EQ(SumOf(*s, "b", {{"x", "1"}}), 2500);
  EXPECT_EQ(SumOf(*s, "b", {{"x", "2"}}), 0);
  for (const char* bad : {"{x=\"1\"} 3", "a{x=1} 3", "a{x=\"1} 3", "a", "a b"}) {
    auto r = ParsePrometheusText(std::string("ok 1\n") + bad + "\n");
    EXPECT_FALSE(r.ok()) << bad;
    EXPECT_THAT(r.status().message(), HasSubstr("metrics line 2")) << bad;
  }
}

}  // namespace
}  // namespace carvemap
