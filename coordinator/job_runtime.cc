#include "coordinator/job_runtime.h"

#include <algorithm>

namespace carvemap {

namespace {

double Between(StageTimes::Time from, StageTimes::Time to) {
  return std::chrono::duration<double>(to - from).count();
}

}  // namespace

void StageTimes::Enter(const std::string& stage, Time now) {
  if (!current_.empty() && start_) stages_[current_].second = Between(*start_, now);
  current_ = stage;
  start_ = now;
  if (!stage.empty()) {
    if (stages_.count(stage) == 0) order_.push_back(stage);
    stages_[stage] = {now, 0.0};
  }
}

double StageTimes::RunningSeconds(Time now) const { return start_ ? Between(*start_, now) : 0.0; }

std::vector<StageTimes::Stage> StageTimes::List(Time now) const {
  std::vector<Stage> out;
  for (const std::string& name : order_) {
    const auto& [start, elapsed] = stages_.at(name);
    const bool running = name == current_;
    out.push_back({name, running ? Between(start, now) : elapsed, !running});
  }
  return out;
}

nlohmann::json StageTimes::Seconds() const {
  nlohmann::json out = nlohmann::json::object();
  for (const auto& [name, timing] : stages_) out[name] = timing.second;
  return out;
}

JobProgress ProgressOf(const JobRuntime& rt, const JobCounters& counters, JobState state,
                       StageTimes::Time now) {
  JobProgress p;
  const bool carving = state == JobState::kCarving || rt.pass > 0;
  if (carving) {
    const double total = double(rt.rays_to_carve);
    const double done = std::min(total, std::max(double(rt.rays_carved), rt.carve_rate.total()));
    const double rate = rt.carve_rate.Rate(now);
    p.rays_done = int64_t(done);
    p.rays_total = int64_t(total);
    p.rays_per_s = rate;
    const int64_t tasks_left = counters.chunks_total - counters.chunks_done;
    if (done >= total && tasks_left > 0) {
      // Every ray carved: what is left are the chunks' combines, at their own rate.
      const double tasks_per_s = rt.task_rate.Rate(now);
      if (tasks_per_s > 0) p.eta_s = double(tasks_left) / tasks_per_s;
    } else if (rate > 0) {
      p.eta_s = (total - done) / rate;
    }
  } else if (state == JobState::kMerging && rt.merge_total > 0) {
    p.stage_done = int64_t(rt.merge_done);
    p.stage_total = int64_t(rt.merge_total);
    const double stage_s = rt.stages.RunningSeconds(now);
    if (rt.merge_done > 0 && stage_s > 0) {
      p.eta_s = stage_s * double(rt.merge_total - std::min(rt.merge_done, rt.merge_total)) /
                double(rt.merge_done);
    }
  }
  p.stages = rt.stages.List(now);
  return p;
}

nlohmann::json MergeJobDocument(const JobRecord& job, const std::optional<JobCounters>& counters,
                                const JobRuntime& rt) {
  nlohmann::json doc = {{"job_id", job.id},
                        {"input_path", job.input_path},
                        {"output_name", job.output_name},
                        {"params", nlohmann::json::parse(job.params_json, nullptr, false)},
                        {"rays_carved", rt.rays_carved}};
  if (counters) {
    doc["chunks_total"] = counters->chunks_total;
    doc["chunk_retries"] = counters->chunk_retries;
  }
  doc["stage_seconds"] = rt.stages.Seconds();
  doc["north"] = rt.north;
  nlohmann::json carve = nlohmann::json::object();
  if (rt.slices_counted == rt.slices.size()) {
    carve = rt.carve_counts;
    if (carve.value("rays", 0.0) > 0) {
      carve["partial_bytes_per_ray"] = carve.value("partial_bytes", 0.0) / carve.value("rays", 1.0);
    }
    // The counts earlier versions wrote as "ingest", for readers of that key.
    nlohmann::json ingest = nlohmann::json::object();
    for (const char* k : {"frames", "rays", "returns", "wedges", "wedge_chunk_pairs"}) {
      if (carve.contains(k)) ingest[k] = carve[k];
    }
    doc["ingest"] = ingest;
  }
  carve["slices"] = rt.slices.size();
  carve["slice_s"] = rt.slice_s;
  doc["carve"] = carve;
  return doc;
}

}  // namespace carvemap
