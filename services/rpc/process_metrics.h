// What every carvemap server exposes about its own process, read from /proc at each scrape
// (plain Prometheus names, as the official clients export them, so stock dashboards work):
// process_resident_memory_bytes, carvemap_process_peak_resident_memory_bytes (VmHWM: what
// sizes a pod's memory limit), process_cpu_seconds_total, process_open_fds, process_threads,
// process_start_time_seconds, and carvemap_process_read_bytes_total /
// carvemap_process_written_bytes_total (/proc/self/io rchar/wchar: every byte through read and
// write calls, page cache included; absent where the kernel hides /proc/self/io). Each sample
// carries service="coordinator|worker|merger", so dashboards tell the servers apart whatever
// the scrape configuration names its jobs.
// Plus ServeMetrics, the HTTP endpoint (prometheus-cpp's Exposer) the servers share.
#ifndef CARVEMAP_SERVICES_RPC_PROCESS_METRICS_H_
#define CARVEMAP_SERVICES_RPC_PROCESS_METRICS_H_

#include <prometheus/collectable.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace prometheus {
class Exposer;
}

namespace carvemap {

struct ProcessStats {
  uint64_t resident_bytes = 0;
  uint64_t peak_resident_bytes = 0;
  int64_t threads = 0;
  int64_t open_fds = -1;  // -1: /proc/self/fd unreadable
  double cpu_seconds = 0;
  std::optional<uint64_t> read_bytes, written_bytes;
};

// Now, for this process. Fields stay 0 (or unset) where /proc does not say.
ProcessStats ReadProcessStats();

class ProcessCollector : public prometheus::Collectable {
 public:
  explicit ProcessCollector(std::string service) : service_(std::move(service)) {}
  std::vector<prometheus::MetricFamily> Collect() const override;

 private:
  const std::string service_;
  const double start_time_s_ = StartTime();
  static double StartTime();
};

// Serves `collectables` (and a ProcessCollector for `service`) at http://ADDRESS/metrics,
// ADDRESS "host:port" (port 0: any free one), and logs "SERVICE: metrics on
// http://HOST:PORT/metrics". `service` ("coordinator", "worker", "merger") also names the
// server in errors.
// The exposer holds its collectables weakly: the endpoint keeps them alive.
struct MetricsEndpoint {
  std::unique_ptr<prometheus::Exposer> exposer;
  std::vector<std::shared_ptr<prometheus::Collectable>> collectables;
  int port = 0;
  MetricsEndpoint();
  MetricsEndpoint(MetricsEndpoint&&) noexcept;
  MetricsEndpoint& operator=(MetricsEndpoint&&) noexcept;
  ~MetricsEndpoint();
};
absl::StatusOr<MetricsEndpoint> ServeMetrics(
    const std::string& address,
    const std::vector<std::shared_ptr<prometheus::Collectable>>& collectables,
    const std::string& service);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_PROCESS_METRICS_H_
