#include "services/rpc/process_metrics.h"

#include <fcntl.h>
#include <unistd.h>

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "services/rpc/http_get.h"
#include "services/rpc/metrics_text.h"

namespace carvemap {
namespace {

// Memory touched and descriptors opened show in the next reading.
TEST(ProcessMetricsTest, FollowsTheProcess) {
  const ProcessStats before = ReadProcessStats();
  EXPECT_GT(before.resident_bytes, 0u);
  EXPECT_GE(before.peak_resident_bytes, before.resident_bytes);
  EXPECT_GE(before.threads, 1);
  std::vector<char> block(64 << 20);
  for (size_t i = 0; i < block.size(); i += 4096) block[i] = 1;
  const int fd = ::open("/proc/self/status", O_RDONLY);
  ASSERT_GE(fd, 0);
  const ProcessStats after = ReadProcessStats();
  ::close(fd);
  EXPECT_GE(after.peak_resident_bytes, before.peak_resident_bytes + (60u << 20));
  EXPECT_EQ(after.open_fds, before.open_fds + 1);
  if (before.read_bytes) {
    EXPECT_GT(*after.read_bytes, *before.read_bytes);  // it read /proc
  }
  EXPECT_EQ(block[4096], 1);
}

// Served over HTTP with the process metrics beside the caller's, as Prometheus scrapes it.
TEST(ProcessMetricsTest, ServedAtMetrics) {
  absl::StatusOr<MetricsEndpoint> endpoint = ServeMetrics("127.0.0.1:0", {}, "test");
  ASSERT_TRUE(endpoint.ok()) << endpoint.status();
  ASSERT_GT(endpoint->port, 0);
  absl::StatusOr<std::string> text =
      HttpGet("http://127.0.0.1:" + std::to_string(endpoint->port) + "/metrics", 10);
  ASSERT_TRUE(text.ok()) << text.status();
  auto s = ParsePrometheusText(*text);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_GT(SumOf(*s, "process_resident_memory_bytes", {{"service", "test"}}), 1e6);
  EXPECT_GT(SumOf(*s, "carvemap_process_peak_resident_memory_bytes"), 1e6);
  EXPECT_GT(SumOf(*s, "process_start_time_seconds"), 1.7e9);

  absl::StatusOr<MetricsEndpoint> taken = ServeMetrics(
      "127.0.0.1:" + std::to_string(endpoint->port), {}, "worker");
  ASSERT_FALSE(taken.ok());
  EXPECT_NE(taken.status().message().find("worker: cannot serve metrics on 127.0.0.1:"),
            std::string::npos)
      << taken.status();
}

}  // namespace
}  // namespace carvemap
