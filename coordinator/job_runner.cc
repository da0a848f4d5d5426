#include "coordinator/job_runner.h"

#include "absl/strings/str_cat.h"

namespace carvemap {

absl::StatusOr<JobState> RunJob(const std::string& job_id, JobStore& store, JobStages& stages,
                                LeaseTable::Clock& clock) {
  absl::StatusOr<JobRecord> job = store.GetJob(job_id);
  if (!job.ok()) return job.status();
  JobState state = job->state;
  const auto move_to = [&](JobState to) {
    absl::Status s = store.TransitionJob(job_id, {to, "", clock.NowUnixMs()});
    if (s.ok()) {
      stages.Moved(job_id, state, to, "");
      state = to;
    } else {
      stages.NotMoved(job_id, to, s);
    }
    return s.ok();
  };
  const auto fail = [&](const char* stage, const absl::Status& s) {
    const std::string raw = absl::StrCat(stage, ": ", s.message());
    absl::Status t = store.TransitionJob(
        job_id, {JobState::kFailed, stages.TenantView(job_id, raw), clock.NowUnixMs()});
    if (t.ok()) {
      stages.Moved(job_id, state, JobState::kFailed, raw);
      state = JobState::kFailed;
    } else {
      stages.NotMoved(job_id, JobState::kFailed, t);
    }
  };
  // A stage's error: the job fails unless it ended meanwhile; while the coordinator stops the
  // job stays as stored, for the next one. True when the job goes on.
  const auto stage_ok = [&](const char* stage, const absl::Status& s) {
    if (s.ok()) return true;
    if (stages.Stopping()) return false;
    if (!absl::IsCancelled(s)) fail(stage, s);
    stages.CleanUp(job_id, false);
    return false;
  };

  if (state == JobState::kIngesting) {
    // A restart during ingest: the slices may already be stored (the crash came between
    // storing them and the move to CARVING); then carving goes on, otherwise plan again.
    absl::StatusOr<std::vector<ChunkRecord>> tasks = store.ListChunks(job_id);
    if (tasks.ok() && !tasks->empty() && !move_to(JobState::kCarving)) return state;
  }
  if (state == JobState::kQueued || state == JobState::kIngesting) {
    if (state == JobState::kQueued && !move_to(JobState::kIngesting)) return state;
    stages.EnterStage(job_id, "ingest");
    if (!stage_ok("ingest", stages.Ingest(*job))) return state;
    absl::StatusOr<JobRecord> now = store.GetJob(job_id);
    const bool empty = now.ok() && now->counters.chunks_total == 0;
    if (!move_to(empty ? JobState::kMerging : JobState::kCarving)) {
      stages.CleanUp(job_id, false);
      return state;
    }
  }
  if (state == JobState::kCarving) {
    stages.EnterStage(job_id, "carve");
    if (!stage_ok("carve", stages.Carve(*job))) return state;
    if (!move_to(JobState::kMerging)) {
      stages.CleanUp(job_id, false);
      return state;
    }
  }
  if (state == JobState::kMerging) {
    stages.EnterStage(job_id, "merge");
    if (!stage_ok("merge", stages.Merge(*job))) return state;
    if (!move_to(JobState::kSucceeded)) {
      stages.CleanUp(job_id, false);
      return state;
    }
  }
  stages.CleanUp(job_id, state == JobState::kSucceeded);
  return state;
}

}  // namespace carvemap
