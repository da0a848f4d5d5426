// The coordinator's Prometheus metrics (docs/DESIGN.md §8 "expose counters"): chunks
// queued, leased and done, workers, rays carved and rays/s, lease expiries and lost workers,
// refused calls, and the latency of every RPC. prometheus-cpp (Debian's prometheus-cpp-dev) keeps
// the values; `--metrics-listen` serves them at /metrics, and `carvemap watch --metrics` shows
// them. Names and meanings: docs/RPC.md, "Metrics". Aggregates only: no job id or tenant
// appears in a label, so a scrape says nothing about whose work it is.
// Thread-safe (prometheus-cpp's metrics are).
#ifndef CARVEMAP_SERVICES_RPC_COORDINATOR_METRICS_H_
#define CARVEMAP_SERVICES_RPC_COORDINATOR_METRICS_H_

#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>

#include "absl/strings/string_view.h"

namespace carvemap {

class CoordinatorMetrics {
 public:
  CoordinatorMetrics();
  CoordinatorMetrics(const CoordinatorMetrics&) = delete;
  CoordinatorMetrics& operator=(const CoordinatorMetrics&) = delete;

  [[nodiscard]] std::shared_ptr<prometheus::Registry> registry() const { return registry_; }

  // Gauges, set from the lease table by the coordinator's sweeper.
  void SetChunks(int64_t queued, int64_t leased, int64_t done);
  void SetWorkers(int64_t registered);
  void SetActiveJobs(int64_t jobs);

  void ChunkCompleted(int64_t rays);
  // Wedges a worker's heartbeat reports carved since its last one (mid-chunk too): what
  // carvemap_rays_per_second follows. carvemap_rays_carved_total counts completed chunks only.
  void RaysCarvedLive(int64_t wedges);
  void ChunkFailed();
  void LeasesExpired(int64_t n);
  void WorkerLost(int64_t leases_requeued);
  void JobSubmitted();
  // `state` is the terminal state's name: "SUCCEEDED", "FAILED", "CANCELLED".
  void JobFinished(absl::string_view state);
  // `api` "job" or "carve".
  void CallRefused(absl::string_view api);
  // One finished RPC (for a server stream: the whole stream).
  void ObserveRpc(absl::string_view method, absl::string_view code, double seconds);

  // Rays carved per second over the last `window` (carvemap_rays_per_second, from the
  // heartbeats' counts); called by the sweeper, which owns the clock.
  void UpdateRate(std::chrono::steady_clock::time_point now,
                  std::chrono::steady_clock::duration window = std::chrono::seconds(10));

  // The exposition text of everything (what /metrics serves).
  [[nodiscard]] std::string Text() const;

 private:
  std::shared_ptr<prometheus::Registry> registry_;
  prometheus::Family<prometheus::Gauge>& chunks_;
  prometheus::Gauge& chunks_queued_;
  prometheus::Gauge& chunks_leased_;
  prometheus::Gauge& chunks_done_;
  prometheus::Gauge& workers_;
  prometheus::Gauge& active_jobs_;
  prometheus::Counter& rays_carved_;
  prometheus::Gauge& rays_per_second_;
  prometheus::Counter& chunks_completed_;
  prometheus::Counter& chunk_failures_;
  prometheus::Counter& lease_expiries_;
  prometheus::Counter& workers_lost_;
  prometheus::Counter& jobs_submitted_;
  prometheus::Family<prometheus::Counter>& jobs_finished_;
  prometheus::Family<prometheus::Counter>& calls_refused_;
  prometheus::Family<prometheus::Histogram>& rpc_seconds_;

  std::mutex rate_mu_;
  std::deque<std::pair<std::chrono::steady_clock::time_point, double>> rate_samples_;
  double live_wedges_ = 0;  // guarded by rate_mu_
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_COORDINATOR_METRICS_H_
