// The merge service's Prometheus metrics (`carvemap merger --metrics-listen`; names and
// meanings in docs/RPC.md, "Metrics"): merges running and waiting (one runs at a time), merges
// finished by result, seconds of each merge and of each of its stages, and the stage running
// now. Peak memory comes with every server's process metrics (process_metrics.h). No job id
// or tenant in a label. Thread-safe.
#ifndef CARVEMAP_SERVICES_RPC_MERGE_METRICS_H_
#define CARVEMAP_SERVICES_RPC_MERGE_METRICS_H_

#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <chrono>
#include <memory>
#include <mutex>
#include <string>

namespace carvemap {

class MergeMetrics {
 public:
  MergeMetrics();
  MergeMetrics(const MergeMetrics&) = delete;
  MergeMetrics& operator=(const MergeMetrics&) = delete;

  [[nodiscard]] std::shared_ptr<prometheus::Registry> registry() const { return registry_; }

  // A call waiting for the one merge slot, and when it stops waiting (with or without it).
  void Queued();
  void Dequeued();
  void MergeStarted(std::chrono::steady_clock::time_point now);
  // The merge entered `stage` (RunMerge's progress names): the previous stage's seconds are
  // added to carvemap_merge_stage_seconds_total, and carvemap_merge_stage names the new one.
  void Stage(const std::string& stage, std::chrono::steady_clock::time_point now);
  // `result`: "succeeded", "failed" or "cancelled".
  void MergeFinished(const std::string& result, std::chrono::steady_clock::time_point now);

  [[nodiscard]] std::string Text() const;

 private:
  void EndStage(std::chrono::steady_clock::time_point now);  // mu_ held

  std::shared_ptr<prometheus::Registry> registry_;
  prometheus::Gauge& running_;
  prometheus::Gauge& queued_;
  prometheus::Family<prometheus::Counter>& merges_;
  prometheus::Histogram& merge_seconds_;
  prometheus::Family<prometheus::Counter>& stage_seconds_;
  prometheus::Family<prometheus::Gauge>& stage_;

  std::mutex mu_;
  std::string stage_name_;  // guarded by mu_; "" between merges
  std::chrono::steady_clock::time_point stage_start_, merge_start_;
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_MERGE_METRICS_H_
