#include "services/rpc/merge_metrics.h"

#include <prometheus/text_serializer.h>

#include <sstream>

namespace carvemap {
namespace {

// 1 s .. ~9 h in factors of 2: a demo's merge takes seconds, a large building's hours.
prometheus::Histogram::BucketBoundaries MergeBuckets() {
  prometheus::Histogram::BucketBoundaries b;
  for (double s = 1; s < 40000; s *= 2) b.push_back(s);
  return b;
}

double Seconds(std::chrono::steady_clock::duration d) {
  return std::chrono::duration<double>(d).count();
}

}  // namespace

MergeMetrics::MergeMetrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      running_(prometheus::BuildGauge()
                   .Name("carvemap_merge_running")
                   .Help("Merges running now (at most one per merge service)")
                   .Register(*registry_)
                   .Add({})),
      queued_(prometheus::BuildGauge()
                  .Name("carvemap_merge_queued")
                  .Help("Merge calls waiting for the running merge to end")
                  .Register(*registry_)
                  .Add({})),
      merges_(prometheus::BuildCounter()
                  .Name("carvemap_merges_total")
                  .Help("Merges finished, by result (succeeded, failed, cancelled)")
                  .Register(*registry_)),
      merge_seconds_(prometheus::BuildHistogram()
                         .Name("carvemap_merge_seconds")
                         .Help("Time of one merge, from taking the slot to its result")
                         .Register(*registry_)
                         .Add({}, MergeBuckets())),
      stage_seconds_(prometheus::BuildCounter()
                         .Name("carvemap_merge_stage_seconds_total")
                         .Help("Seconds spent in each merge stage, over every merge")
                         .Register(*registry_)),
      stage_(prometheus::BuildGauge()
                 .Name("carvemap_merge_stage")
                 .Help("1 for the stage the running merge is in")
                 .Register(*registry_)) {
  // Every result from the start at 0: increase() then sees the first merge end.
  for (const char* result : {"succeeded", "failed", "cancelled"}) merges_.Add({{"result", result}});
}

void MergeMetrics::Queued() { queued_.Increment(); }
void MergeMetrics::Dequeued() { queued_.Decrement(); }

void MergeMetrics::MergeStarted(std::chrono::steady_clock::time_point now) {
  std::lock_guard<std::mutex> lock(mu_);
  running_.Set(1);
  merge_start_ = now;
  stage_name_.clear();
}

void MergeMetrics::EndStage(std::chrono::steady_clock::time_point now) {
  if (stage_name_.empty()) return;
  stage_seconds_.Add({{"stage", stage_name_}}).Increment(Seconds(now - stage_start_));
  stage_.Add({{"stage", stage_name_}}).Set(0);
  stage_name_.clear();
}

void MergeMetrics::Stage(const std::string& stage, std::chrono::steady_clock::time_point now) {
  std::lock_guard<std::mutex> lock(mu_);
  if (stage == stage_name_) return;
  EndStage(now);
  stage_name_ = stage;
  stage_start_ = now;
  stage_.Add({{"stage", stage}}).Set(1);
}

void MergeMetrics::MergeFinished(const std::string& result,
                                 std::chrono::steady_clock::time_point now) {
  std::lock_guard<std::mutex> lock(mu_);
  EndStage(now);
  running_.Set(0);
  merges_.Add({{"result", result}}).Increment();
  merge_seconds_.Observe(Seconds(now - merge_start_));
}

std::string MergeMetrics::Text() const {
  std::ostringstream out;
  prometheus::TextSerializer().Serialize(out, registry_->Collect());
  return out.str();
}

}  // namespace carvemap
