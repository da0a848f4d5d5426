// A worker's Prometheus metrics (`carvemap worker --metrics-listen`; names and meanings in
// docs/RPC.md, "Metrics"): rays carved (counted as the carve goes, mid-task too, as the
// heartbeats report them), tasks finished by kind and result, task seconds, tasks running,
// bytes of partial sums and tiles written. Memory, CPU and bytes read come with every server's
// process metrics (process_metrics.h). No job id or tenant in a label. Thread-safe.
#ifndef CARVEMAP_SERVICES_RPC_WORKER_METRICS_H_
#define CARVEMAP_SERVICES_RPC_WORKER_METRICS_H_

#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <cstdint>
#include <memory>
#include <string>

namespace carvemap {

class WorkerMetrics {
 public:
  WorkerMetrics();
  WorkerMetrics(const WorkerMetrics&) = delete;
  WorkerMetrics& operator=(const WorkerMetrics&) = delete;

  [[nodiscard]] std::shared_ptr<prometheus::Registry> registry() const { return registry_; }

  void RaysCarved(uint64_t rays);
  void TaskStarted();
  // `kind`: "slice" or "combine"; `ok`: the task's result (a failed task is reported to the
  // coordinator with FailChunk); `bytes_written`: the partial sums' or tile's size.
  void TaskFinished(const std::string& kind, bool ok, double seconds, uint64_t bytes_written);

  [[nodiscard]] std::string Text() const;

 private:
  std::shared_ptr<prometheus::Registry> registry_;
  prometheus::Counter& rays_carved_;
  prometheus::Gauge& tasks_running_;
  prometheus::Family<prometheus::Counter>& tasks_;
  prometheus::Family<prometheus::Histogram>& task_seconds_;
  prometheus::Counter& bytes_written_;
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_WORKER_METRICS_H_
