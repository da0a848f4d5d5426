#include "coordinator/coordinator_core.h"

#include <filesystem>
#include <set>

#include "absl/strings/str_cat.h"
#include "coordinator/job_plan.h"
#include "coordinator/lease_id.h"

namespace carvemap {
namespace fs = std::filesystem;

CoordinatorCore::CoordinatorCore(JobStore& store, LeaseTable::Clock& clock,
                                 CoordinatorCoreOptions options)
    : store_(store),
      clock_(clock),
      options_(std::move(options)),
      table_(store, clock, options_.leases),
      workers_(options_.instance) {}

// ---- the workers' side

std::string CoordinatorCore::RegisterWorker() {
  absl::MutexLock lock(&mu_);
  return workers_.Register(clock_.NowUnixMs());
}

absl::StatusOr<CoordinatorCore::HeartbeatReply> CoordinatorCore::Heartbeat(
    const HeartbeatReport& report) {
  const std::string& worker = report.worker_id;
  if (worker.empty()) return absl::InvalidArgumentError("empty worker id");
  absl::MutexLock lock(&mu_);
  if (!workers_.Touch(worker, clock_.NowUnixMs())) {
    return absl::NotFoundError(absl::StrCat("worker ", worker, " unknown or lost: register again"));
  }
  if (report.rays_carved > 0) {
    // The wedges carved since the worker's last heartbeat belong to the job of its latest
    // lease (a worker carves one job's chunks at a time; a lease finished since is that job's).
    if (const std::string job = workers_.JobOf(worker); !job.empty()) {
      if (auto rt = runtime_.find(job); rt != runtime_.end()) {
        rt->second.carve_rate.Add(clock_.SteadyNow(), double(report.rays_carved));
      }
    }
  }
  std::vector<std::string> held = table_.LeasesOf(worker);
  const std::set<std::string> reported(report.active_lease_ids.begin(),
                                       report.active_lease_ids.end());
  if (report.report_leases) {
    // Leases the worker no longer reports are abandoned: give them back now rather than at
    // the lease deadline.
    for (const std::string& lease : held) {
      if (reported.count(lease)) continue;
      if (absl::StatusOr<LeaseId> id = LeaseId::Parse(lease); id.ok()) {
        (void)table_.Fail(lease, id->generation, absl::StrCat("abandoned by worker ", worker),
                          /*retryable=*/true);
        WorkMayBeQueued();
        TasksChanged();
      }
    }
    held = table_.LeasesOf(worker);
  }
  HeartbeatReply reply;
  const std::set<std::string> held_set(held.begin(), held.end());
  for (const std::string& lease : reported) {
    if (!held_set.count(lease)) reply.revoked_lease_ids.push_back(lease);
  }
  reply.lease_deadline_unix_ms = table_.Heartbeat(worker);
  return reply;
}

absl::StatusOr<std::optional<CarveTask>> CoordinatorCore::Lease(
    const std::string& worker_id, absl::Duration wait, const std::function<bool()>& gave_up) {
  if (worker_id.empty()) return absl::InvalidArgumentError("empty worker id");
  absl::MutexLock lock(&mu_);
  if (!workers_.Touch(worker_id, clock_.NowUnixMs())) {
    return absl::NotFoundError(
        absl::StrCat("worker ", worker_id, " unknown or lost: register again"));
  }
  if (gave_up && gave_up()) return absl::CancelledError("lease call cancelled by the worker");
  absl::StatusOr<std::optional<LeaseTable::Grant>> grant = table_.Lease(worker_id);
  if (!grant.ok()) return grant.status();
  if (*grant) {
    workers_.SetJob(worker_id, (*grant)->job_id);
    const JobRuntime& rt = runtime_[(*grant)->job_id];
    absl::StatusOr<CarveTask> task = CarveTaskOf(
        **grant, rt,
        fs::absolute(options_.folders.DataDir(rt.tenant_dir)).lexically_normal().string());
    if (!task.ok()) return task.status();
    return std::optional<CarveTask>(*std::move(task));
  }
  // Parked until work may have been queued or the caller's wait is up.
  if (!stopping_ && wait > absl::ZeroDuration()) work_cv_.WaitWithTimeout(&mu_, wait);
  return std::nullopt;
}

absl::StatusOr<LeaseTable::Progress> CoordinatorCore::Complete(const Completion& completion) {
  absl::MutexLock lock(&mu_);
  workers_.Touch(completion.worker_id, clock_.NowUnixMs());
  if (absl::Status s = table_.Complete(completion.lease_id, completion.generation, completion.tile);
      !s.ok()) {
    return s;
  }
  TasksChanged();
  const std::string job_id = LeaseId::Parse(completion.lease_id)->job_id;  // Complete parsed it
  JobRuntime& rt = runtime_[job_id];
  const TaskCounts& counts = completion.counts;
  rt.rays_carved += counts.rays;
  rt.task_rate.Add(clock_.SteadyNow(), 1);
  if (rt.pass == 0 && counts.rays > 0) {
    // A slice of the job's carve: its counts for job.json "carve".
    for (const auto& [name, value] : {std::pair{"frames", counts.frames},
                                      {"rays", counts.rays},
                                      {"returns", counts.returns},
                                      {"wedges", counts.wedges},
                                      {"wedge_chunk_pairs", counts.wedge_chunk_pairs},
                                      {"leaf_updates", counts.leaf_updates},
                                      {"partial_bytes", counts.partial_bytes}}) {
      rt.carve_counts[name] = rt.carve_counts.value(name, int64_t{0}) + value;
    }
    ++rt.slices_counted;
  }
  return table_.GetProgress(job_id);
}

absl::StatusOr<bool> CoordinatorCore::Fail(const std::string& worker_id,
                                           const std::string& lease_id, int64_t generation,
                                           const std::string& reason, bool retryable) {
  absl::MutexLock lock(&mu_);
  workers_.Touch(worker_id, clock_.NowUnixMs());  // an unknown worker: its result still counts
  absl::StatusOr<LeaseId> id = LeaseId::Parse(lease_id);
  if (!id.ok()) return id.status();
  // The table prefixes "worker <id>: " itself; the reason may become the job's error.
  absl::StatusOr<bool> requeued =
      table_.Fail(lease_id, generation, TenantViewLocked(id->job_id, reason), retryable);
  if (!requeued.ok()) return requeued.status();
  if (*requeued) WorkMayBeQueued();
  TasksChanged();  // or the job failed
  return *requeued;
}

CoordinatorCore::SweepReport CoordinatorCore::Sweep(int64_t due_unix_ms) {
  SweepReport report;
  absl::MutexLock lock(&mu_);
  // Measured once the lock is held: heartbeats wait for the same lock (a job-store fsync
  // behind the writeback of a freshly written scan held it for seconds).
  if (const int64_t late = clock_.NowUnixMs() - due_unix_ms; late > 0) {
    report.late_ms = late;
    workers_.CreditLateness(late, clock_.NowUnixMs());
    if (late > 1000) {
      for (const std::string& id : workers_.Ids()) (void)table_.Heartbeat(id);
    }
  }
  report.expired = table_.ExpireLeases();
  if (report.expired.ok() && *report.expired > 0) {
    WorkMayBeQueued();
    TasksChanged();  // a task out of attempts fails its job
  }
  const int64_t now = clock_.NowUnixMs();
  for (const auto& [id, silent_ms] : workers_.RemoveSilent(now, options_.worker_timeout_ms)) {
    report.lost.push_back({id, silent_ms, table_.WorkerLost(id)});
    WorkMayBeQueued();
    TasksChanged();
  }
  for (const auto& [job_id, rt] : runtime_) {
    if (!rt.stages.running().empty()) ++report.active_jobs;
    absl::StatusOr<LeaseTable::Progress> p = table_.GetProgress(job_id);
    if (!p.ok()) continue;
    report.tasks_queued += p->chunks_queued;
    report.tasks_leased += p->chunks_leased;
    report.tasks_done += p->chunks_done;
  }
  report.workers = static_cast<int64_t>(workers_.size());
  return report;
}

CoordinatorCore::WatchSnapshot CoordinatorCore::Watch(const std::string& job_id,
                                                      const JobCounters& counters, JobState state) {
  WatchSnapshot snapshot;
  absl::MutexLock lock(&mu_);
  if (auto rt = runtime_.find(job_id); rt != runtime_.end()) {
    snapshot.progress = ProgressOf(rt->second, counters, state, clock_.SteadyNow());
  }
  std::set<std::string> active;
  for (const std::string& worker : workers_.Ids()) {
    for (const std::string& lease : table_.LeasesOf(worker)) {
      absl::StatusOr<LeaseId> id = LeaseId::Parse(lease);
      if (id.ok() && id->job_id == job_id) active.insert(worker);
    }
  }
  snapshot.active_workers = static_cast<int32_t>(active.size());
  return snapshot;
}

// ---- the job threads' side

void CoordinatorCore::EnterStage(const std::string& job_id, const std::string& stage) {
  absl::MutexLock lock(&mu_);
  runtime_[job_id].stages.Enter(stage, clock_.SteadyNow());
}

std::string CoordinatorCore::TenantView(const std::string& job_id, std::string text) {
  absl::MutexLock lock(&mu_);
  return TenantViewLocked(job_id, std::move(text));
}

std::string CoordinatorCore::TenantViewLocked(const std::string& job_id, std::string text) const {
  // No runtime entry is made for an ended job here: its text still has the work folder hidden.
  static const JobRuntime kEnded;
  const auto it = runtime_.find(job_id);
  const JobRuntime& rt = it != runtime_.end() ? it->second : kEnded;
  return carvemap::TenantView(std::move(text),
                              JobFolders{rt.output_dir, rt.tiles_dir, rt.partials_dir},
                              options_.folders.work_dir);
}

void CoordinatorCore::EraseRuntime(const std::string& job_id) {
  absl::MutexLock lock(&mu_);
  runtime_.erase(job_id);
}

absl::Status CoordinatorCore::LoadTasks(const std::string& job_id,
                                        const LeaseTable::DoneCheck& check) {
  absl::MutexLock lock(&mu_);
  if (absl::Status s = table_.LoadJob(job_id, check); !s.ok() && !absl::IsAlreadyExists(s)) {
    return s;
  }
  WorkMayBeQueued();
  return absl::OkStatus();
}

absl::Status CoordinatorCore::AddTasks(const std::string& job_id,
                                       std::span<const ChunkRecord> tasks) {
  absl::MutexLock lock(&mu_);
  if (absl::Status s = table_.Add(job_id, tasks); !s.ok()) return s;
  WorkMayBeQueued();
  return absl::OkStatus();
}

absl::Status CoordinatorCore::ReleaseTasks(const std::string& job_id,
                                           const std::vector<ChunkCoord>& keys) {
  absl::MutexLock lock(&mu_);
  absl::Status s = table_.Release(job_id, keys);
  WorkMayBeQueued();
  return s;
}

void CoordinatorCore::DropTasks(const std::string& job_id) {
  absl::MutexLock lock(&mu_);
  table_.DropJob(job_id);
  TasksChanged();
}

absl::Status CoordinatorCore::WaitForTasks(const std::string& job_id, bool except_held) {
  absl::MutexLock lock(&mu_);
  while (!stopping_) {
    absl::StatusOr<LeaseTable::Progress> p = table_.GetProgress(job_id);
    if (!p.ok() || p->failed) return absl::CancelledError("job ended while carving");
    if (table_.AllDone(job_id, except_held)) return absl::OkStatus();
    // Every change that can end this wait signals done_cv_ (TasksChanged, Stop).
    done_cv_.Wait(&mu_);
  }
  return absl::CancelledError("coordinator stopping");
}

absl::Status CoordinatorCore::StartRecarve(const std::string& job_id, const RecarvePass& pass) {
  absl::MutexLock lock(&mu_);
  if (absl::Status s = table_.LoadJob(job_id); !s.ok() && !absl::IsAlreadyExists(s)) return s;
  JobRuntime& rt = runtime_[job_id];
  // The pass's slices: tasks of their own, or those of an earlier pass of this number (a
  // merge retried) put back in the queue.
  std::vector<ChunkRecord> fresh;
  std::vector<ChunkCoord> again;
  std::set<ChunkCoord> existing;
  if (absl::StatusOr<std::vector<ChunkRecord>> stored = store_.ListChunks(job_id); stored.ok()) {
    for (const ChunkRecord& c : *stored) existing.insert(c.key);
  }
  for (ChunkRecord& r : SliceTasks(job_id, rt.slices, pass.pass)) {
    if (existing.count(r.key)) {
      again.push_back(r.key);
    } else {
      fresh.push_back(std::move(r));
    }
  }
  absl::Status s = table_.Add(job_id, fresh);
  if (s.ok() && !again.empty()) {
    s = table_.Requeue(job_id, again, absl::StrCat("queued again: re-carve pass ", pass.pass));
  }
  // The chunks, combined from this pass's sums once the slices are carved: held until then,
  // but counted now, so the pass never looks done in between.
  if (s.ok()) {
    s = table_.Requeue(job_id, pass.chunks,
                       absl::StrCat("queued again: objects at ", pass.resolution_m, " m (§5.6.1)"),
                       /*held=*/true);
  }
  if (!s.ok()) {
    table_.DropJob(job_id);
    return s;
  }
  // Leases of this pass carry the finer grid, read the regions and write into the pass's
  // tiles folder (Lease reads these; none is handed out before the lock is released). Set
  // only once the pass is queued, so that a pass that could not start leaves the runtime as
  // it was.
  rt.params.resolution_m = pass.grid_resolution_m;
  rt.tiles_dir = pass.tiles_dir;
  rt.pass = pass.pass;
  rt.pass_dir = pass.pass_dir;
  rt.regions_path = pass.regions_path;
  rt.pass_chunks = pass.chunks;
  rt.rays_carved = 0;
  rt.carve_rate = RateWindow();
  rt.task_rate = RateWindow();
  WorkMayBeQueued();
  return absl::OkStatus();
}

void CoordinatorCore::EndRecarve(const std::string& job_id, const JobRuntime& saved) {
  absl::MutexLock lock(&mu_);
  table_.DropJob(job_id);
  TasksChanged();
  JobRuntime& rt = runtime_[job_id];
  rt.params = saved.params;
  rt.tiles_dir = saved.tiles_dir;
  rt.rays_carved = saved.rays_carved;
  rt.rays_to_carve = saved.rays_to_carve;
  rt.carve_rate = saved.carve_rate;
  rt.task_rate = saved.task_rate;
  rt.pass = 0;
  rt.pass_dir = saved.partials_dir;
  rt.regions_path.clear();
  rt.pass_chunks.clear();
}

void CoordinatorCore::Stop() {
  absl::MutexLock lock(&mu_);
  stopping_ = true;
  WorkMayBeQueued();
  TasksChanged();
}

}  // namespace carvemap
