#include "services/rpc/coordinator_metrics.h"

#include <prometheus/text_serializer.h>

#include <sstream>

namespace carvemap {
namespace {

using prometheus::BuildCounter;
using prometheus::BuildGauge;
using prometheus::BuildHistogram;

// 0.25 ms .. ~32 s in factors of 2: a lease long poll waits up to 30 s, a heartbeat takes
// well under a millisecond on loopback.
prometheus::Histogram::BucketBoundaries RpcBuckets() {
  prometheus::Histogram::BucketBoundaries b;
  for (double s = 0.00025; s < 40; s *= 2) b.push_back(s);
  return b;
}

}  // namespace

CoordinatorMetrics::CoordinatorMetrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      chunks_(BuildGauge()
                  .Name("carvemap_chunks")
                  .Help("Tasks (slices and chunks) of the jobs being carved, by state (queued, "
                        "leased, done)")
                  .Register(*registry_)),
      chunks_queued_(chunks_.Add({{"state", "queued"}})),
      chunks_leased_(chunks_.Add({{"state", "leased"}})),
      chunks_done_(chunks_.Add({{"state", "done"}})),
      workers_(BuildGauge()
                   .Name("carvemap_workers")
                   .Help("Workers registered and heartbeating")
                   .Register(*registry_)
                   .Add({})),
      active_jobs_(BuildGauge()
                       .Name("carvemap_jobs_active")
                       .Help("Jobs between submit and a terminal state in this coordinator")
                       .Register(*registry_)
                       .Add({})),
      rays_carved_(BuildCounter()
                       .Name("carvemap_rays_carved_total")
                       .Help("Rays of the scan carved by workers, from completed slices")
                       .Register(*registry_)
                       .Add({})),
      rays_per_second_(BuildGauge()
                           .Name("carvemap_rays_per_second")
                           .Help("Rays of the scan carved per second over the last 10 s, as the "
                                 "workers' heartbeats report them (mid-slice too)")
                           .Register(*registry_)
                           .Add({})),
      chunks_completed_(BuildCounter()
                            .Name("carvemap_chunks_completed_total")
                            .Help("Tasks committed (slices' partial sums and chunks' tiles)")
                            .Register(*registry_)
                            .Add({})),
      chunk_failures_(BuildCounter()
                          .Name("carvemap_chunk_failures_total")
                          .Help("FailChunk calls from workers")
                          .Register(*registry_)
                          .Add({})),
      lease_expiries_(BuildCounter()
                          .Name("carvemap_lease_expiries_total")
                          .Help("Leases that passed their deadline and were requeued")
                          .Register(*registry_)
                          .Add({})),
      workers_lost_(BuildCounter()
                        .Name("carvemap_workers_lost_total")
                        .Help("Workers declared lost (no heartbeat for worker_timeout_s)")
                        .Register(*registry_)
                        .Add({})),
      jobs_submitted_(BuildCounter()
                          .Name("carvemap_jobs_submitted_total")
                          .Help("Jobs created by SubmitJob")
                          .Register(*registry_)
                          .Add({})),
      jobs_finished_(BuildCounter()
                         .Name("carvemap_jobs_finished_total")
                         .Help("Jobs that reached a terminal state, by state")
                         .Register(*registry_)),
      calls_refused_(BuildCounter()
                         .Name("carvemap_calls_unauthenticated_total")
                         .Help("Calls refused for a missing or wrong token or secret, by API")
                         .Register(*registry_)),
      rpc_seconds_(BuildHistogram()
                       .Name("carvemap_rpc_duration_seconds")
                       .Help("Time from an RPC's start to its status (whole stream for "
                             "WatchJob, FetchArtifact and UploadScan), by method and status code")
                       .Register(*registry_)) {
  // Every label value a counter can take exists from the start at 0, so that increase() and
  // rate() see the first job finish (a series born at 1 has no earlier sample to compare).
  for (const char* state : {"SUCCEEDED", "FAILED", "CANCELLED"}) {
    jobs_finished_.Add({{"state", state}});
  }
  for (const char* api : {"job", "carve"}) calls_refused_.Add({{"api", api}});
}

void CoordinatorMetrics::SetChunks(int64_t queued, int64_t leased, int64_t done) {
  chunks_queued_.Set(static_cast<double>(queued));
  chunks_leased_.Set(static_cast<double>(leased));
  chunks_done_.Set(static_cast<double>(done));
}

void CoordinatorMetrics::SetWorkers(int64_t registered) {
  workers_.Set(static_cast<double>(registered));
}

void CoordinatorMetrics::SetActiveJobs(int64_t jobs) { active_jobs_.Set(static_cast<double>(jobs)); }

void CoordinatorMetrics::ChunkCompleted(int64_t rays) {
  chunks_completed_.Increment();
  if (rays > 0) rays_carved_.Increment(static_cast<double>(rays));
}

void CoordinatorMetrics::RaysCarvedLive(int64_t wedges) {
  std::lock_guard<std::mutex> lock(rate_mu_);
  if (wedges > 0) live_wedges_ += double(wedges);
}

void CoordinatorMetrics::ChunkFailed() { chunk_failures_.Increment(); }

void CoordinatorMetrics::LeasesExpired(int64_t n) {
  if (n > 0) lease_expiries_.Increment(static_cast<double>(n));
}

void CoordinatorMetrics::WorkerLost(int64_t) { workers_lost_.Increment(); }

void CoordinatorMetrics::JobSubmitted() { jobs_submitted_.Increment(); }

void CoordinatorMetrics::JobFinished(absl::string_view state) {
  jobs_finished_.Add({{"state", std::string(state)}}).Increment();
}

void CoordinatorMetrics::CallRefused(absl::string_view api) {
  calls_refused_.Add({{"api", std::string(api)}}).Increment();
}

void CoordinatorMetrics::ObserveRpc(absl::string_view method, absl::string_view code,
                                    double seconds) {
  rpc_seconds_.Add({{"method", std::string(method)}, {"code", std::string(code)}}, RpcBuckets())
      .Observe(seconds);
}

void CoordinatorMetrics::UpdateRate(std::chrono::steady_clock::time_point now,
                                    std::chrono::steady_clock::duration window) {
  std::lock_guard<std::mutex> lock(rate_mu_);
  rate_samples_.emplace_back(now, live_wedges_);
  while (rate_samples_.size() > 2 && now - rate_samples_[1].first >= window) {
    rate_samples_.pop_front();
  }
  const auto& [t0, v0] = rate_samples_.front();
  const double dt = std::chrono::duration<double>(now - t0).count();
  rays_per_second_.Set(dt > 0 ? (live_wedges_ - v0) / dt : 0.0);
}

std::string CoordinatorMetrics::Text() const {
  std::ostringstream out;
  prometheus::TextSerializer().Serialize(out, registry_->Collect());
  return out.str();
}

}  // namespace carvemap
