#include "services/rpc/worker_metrics.h"

#include <prometheus/text_serializer.h>

#include <sstream>

namespace carvemap {
namespace {

// 0.1 s .. ~3,300 s in factors of 2: a combine of a small chunk takes a fraction of a second,
// a slice of a full-rate scan minutes.
prometheus::Histogram::BucketBoundaries TaskBuckets() {
  prometheus::Histogram::BucketBoundaries b;
  for (double s = 0.1; s < 4000; s *= 2) b.push_back(s);
  return b;
}

}  // namespace

WorkerMetrics::WorkerMetrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      rays_carved_(prometheus::BuildCounter()
                       .Name("carvemap_worker_rays_carved_total")
                       .Help("Rays carved by this worker, counted as the carve goes")
                       .Register(*registry_)
                       .Add({})),
      tasks_running_(prometheus::BuildGauge()
                         .Name("carvemap_worker_tasks_running")
                         .Help("Tasks (slices, chunks to combine) being carved now")
                         .Register(*registry_)
                         .Add({})),
      tasks_(prometheus::BuildCounter()
                 .Name("carvemap_worker_tasks_total")
                 .Help("Tasks finished, by kind (slice, combine) and result (ok, failed)")
                 .Register(*registry_)),
      task_seconds_(prometheus::BuildHistogram()
                        .Name("carvemap_worker_task_seconds")
                        .Help("Time to carve one task, by kind (slice, combine)")
                        .Register(*registry_)),
      bytes_written_(prometheus::BuildCounter()
                         .Name("carvemap_worker_bytes_written_total")
                         .Help("Bytes of partial sums and tiles committed")
                         .Register(*registry_)
                         .Add({})) {
  // Every series from the start at 0: increase() then sees the first task (a series born at
  // 1 has no earlier sample to compare).
  for (const char* kind : {"slice", "combine"}) {
    for (const char* result : {"ok", "failed"}) tasks_.Add({{"kind", kind}, {"result", result}});
    task_seconds_.Add({{"kind", kind}}, TaskBuckets());
  }
}

void WorkerMetrics::RaysCarved(uint64_t rays) {
  if (rays > 0) rays_carved_.Increment(double(rays));
}

void WorkerMetrics::TaskStarted() { tasks_running_.Increment(); }

void WorkerMetrics::TaskFinished(const std::string& kind, bool ok, double seconds,
                                 uint64_t bytes_written) {
  tasks_running_.Decrement();
  tasks_.Add({{"kind", kind}, {"result", ok ? "ok" : "failed"}}).Increment();
  task_seconds_.Add({{"kind", kind}}, TaskBuckets()).Observe(seconds);
  if (ok && bytes_written > 0) bytes_written_.Increment(double(bytes_written));
}

std::string WorkerMetrics::Text() const {
  std::ostringstream out;
  prometheus::TextSerializer().Serialize(out, registry_->Collect());
  return out.str();
}

}  // namespace carvemap
