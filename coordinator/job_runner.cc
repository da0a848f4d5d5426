#include "coordinator/job_runner.h"

#include <functional>

#include "absl/strings/str_cat.h"

namespace carvemap {

absl::StatusOr<JobState> RunJob(const std::string& job_id, JobStore& store, JobStages& stages,
                                LeaseTable::Clock& clock) {
  absl::StatusOr<JobRecord> job = store.GetJob(job_id);
  if (!job.ok()) return job.status();
  JobState state = job->state;
  // `raw`: a FAILED job's reason as the coordinator logs it; the store keeps the tenant's view.
  const auto move_to = [&](JobState to, const std::string& raw = "") {
    const std::string error = raw.empty() ? "" : stages.TenantView(job_id, raw);
    absl::Status s = store.TransitionJob(job_id, {to, error, clock.NowUnixMs()});
    if (s.ok()) {
      stages.Moved(job_id, state, to, raw);
      state = to;
    } else {
      stages.NotMoved(job_id, to, s);
    }
    return s.ok();
  };
  // Runs `stage` (entered as `name`) and moves the job to `next()` after it. A stage's error
  // fails the job unless it ended meanwhile (Cancelled); while the coordinator stops, the job
  // stays as stored, for the next one. A move the store refuses (a cancel came between) ends
  // here. True when the job goes on.
  const auto run = [&](const char* name, absl::Status (JobStages::*stage)(const JobRecord&),
                       const std::function<JobState()>& next) {
    stages.EnterStage(job_id, name);
    if (absl::Status s = (stages.*stage)(*job); !s.ok()) {
      if (stages.Stopping()) return false;
      if (!absl::IsCancelled(s)) move_to(JobState::kFailed, absl::StrCat(name, ": ", s.message()));
      stages.CleanUp(job_id, false);
      return false;
    }
    if (!move_to(next())) {
      stages.CleanUp(job_id, false);
      return false;
    }
    return true;
  };

  if (state == JobState::kIngesting) {
    // A restart during ingest: the slices may already be stored (the crash came between
    // storing them and the move to CARVING); then carving goes on, otherwise plan again.
    absl::StatusOr<std::vector<ChunkRecord>> tasks = store.ListChunks(job_id);
    if (tasks.ok() && !tasks->empty() && !move_to(JobState::kCarving)) return state;
  }
  if (state == JobState::kQueued || state == JobState::kIngesting) {
    if (state == JobState::kQueued && !move_to(JobState::kIngesting)) return state;
    // An empty scan (no tasks) has nothing to carve.
    const auto after_ingest = [&] {
      absl::StatusOr<JobRecord> now = store.GetJob(job_id);
      return now.ok() && now->counters.chunks_total == 0 ? JobState::kMerging : JobState::kCarving;
    };
    if (!run("ingest", &JobStages::Ingest, after_ingest)) return state;
  }
  if (state == JobState::kCarving &&
      !run("carve", &JobStages::Carve, [] { return JobState::kMerging; })) {
    return state;
  }
  if (state == JobState::kMerging &&
      !run("merge", &JobStages::Merge, [] { return JobState::kSucceeded; })) {
    return state;
  }
  stages.CleanUp(job_id, state == JobState::kSucceeded);
  return state;
}

}  // namespace carvemap
