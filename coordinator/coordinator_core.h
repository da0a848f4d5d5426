// The coordinator's shared state and the rules of the carve-task API (docs/RPC.md
// RegisterWorker, Heartbeat, LeaseChunk, CompleteChunk, FailChunk, WatchJob): the lease table,
// the workers it knows and the running jobs' runtimes, under one mutex, with the waits of the
// job threads and of the parked lease calls on events. Plain structs in and out; no RPC, no
// logging: the service converts the messages, logs and counts from what these return.
//
// Thread-safe. Time comes from the injected clock (tests use a fake): wall time for leases and
// heartbeats, its monotonic time for rates and stage timings.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/time.h"
#include "coordinator/carve_task.h"
#include "coordinator/job_folders.h"
#include "coordinator/job_runtime.h"
#include "coordinator/lease_table.h"
#include "coordinator/worker_registry.h"
#include "storage/job_store.h"

namespace carvemap {

struct CoordinatorCoreOptions {
  LeaseTableOptions leases;
  // A worker not heard from for longer is lost: its leases are requeued by the next sweep.
  int64_t worker_timeout_ms = 15'000;
  CoordinatorFolders folders;
  // Tells this coordinator's worker ids from a previous one's (WorkerRegistry).
  std::string instance;
};

class CoordinatorCore {
 public:
  // `store` and `clock` are borrowed and must outlive the core.
  // REQUIRES: options.leases.Validate().ok().
  CoordinatorCore(JobStore& store, LeaseTable::Clock& clock, CoordinatorCoreOptions options);
  CoordinatorCore(const CoordinatorCore&) = delete;
  CoordinatorCore& operator=(const CoordinatorCore&) = delete;

  // ---- the workers' side

  // A new worker id, heard from now.
  std::string RegisterWorker();

  struct HeartbeatReport {
    std::string worker_id;
    int64_t rays_carved = 0;  // since the worker's last heartbeat, mid-task too
    // With report_leases, the worker's leases not in active_lease_ids are given back.
    bool report_leases = false;
    std::vector<std::string> active_lease_ids = {};
  };
  struct HeartbeatReply {
    std::vector<std::string> revoked_lease_ids;     // reported but no longer the worker's, sorted
    std::optional<int64_t> lease_deadline_unix_ms;  // of its leases, when it holds any
  };
  // INVALID_ARGUMENT for an empty id; NOT_FOUND for a worker unknown or lost (it must
  // register again). The rays count for the job of the worker's latest lease.
  absl::StatusOr<HeartbeatReply> Heartbeat(const HeartbeatReport& report);

  // The next task for the worker, or nullopt when none is queued; then the call waits up to
  // `wait` for work to be queued (or Stop) before it returns nullopt, so that the caller can
  // ask again. NOT_FOUND for a worker unknown or lost; CANCELLED when `gave_up` (checked
  // before leasing: a caller that left would never learn of its lease); the lease table's
  // errors; INTERNAL when the task cannot be made (CarveTaskOf).
  absl::StatusOr<std::optional<CarveTask>> Lease(const std::string& worker_id, absl::Duration wait,
                                                 const std::function<bool()>& gave_up);

  // What a slice measured (job.json "carve"); a combine reports only zeros.
  struct TaskCounts {
    int64_t frames = 0, rays = 0, returns = 0, wedges = 0, wedge_chunk_pairs = 0, leaf_updates = 0,
            partial_bytes = 0;
  };
  struct Completion {
    std::string worker_id;  // an unknown worker's result still counts
    std::string lease_id;
    int64_t generation = 0;
    LeaseTable::Tile tile;
    TaskCounts counts;
  };
  // Commits the task (LeaseTable::Complete, whose errors it returns) and returns its job's
  // progress after it.
  absl::StatusOr<LeaseTable::Progress> Complete(const Completion& completion);

  // The worker gave the lease up (LeaseTable::Fail; `reason` is stored in the tenant's view).
  // True: the task was requeued; false: the job failed.
  absl::StatusOr<bool> Fail(const std::string& worker_id, const std::string& lease_id,
                            int64_t generation, const std::string& reason, bool retryable);

  struct SweepReport {
    int64_t late_ms = 0;              // how late the sweep ran (credited to the workers)
    absl::StatusOr<int> expired = 0;  // leases past their deadline, requeued
    struct LostWorker {
      std::string worker_id;
      int64_t silent_ms = 0;
      absl::StatusOr<int> leases = 0;  // requeued
    };
    std::vector<LostWorker> lost;  // in id order
    // Gauges: the tasks of every job in the lease table, the workers, the jobs in a stage.
    int64_t tasks_queued = 0, tasks_leased = 0, tasks_done = 0;
    int64_t workers = 0, active_jobs = 0;
  };
  // One sweep, due at `due_unix_ms`: expired leases requeued, silent workers forgotten and
  // their leases requeued. The time it ran late (for the lock or for a core) the coordinator
  // could not hear heartbeats either: it is credited to the workers and, past a second, their
  // leases are extended.
  SweepReport Sweep(int64_t due_unix_ms);

  // What WatchJob's progress shows besides the store's counters.
  struct WatchSnapshot {
    std::optional<JobProgress> progress;  // none when the job has no runtime here
    int32_t active_workers = 0;           // workers holding a lease of the job
  };
  [[nodiscard]] WatchSnapshot Watch(const std::string& job_id, const JobCounters& counters,
                                    JobState state);

  // ---- the job threads' side

  // Runs f(JobRuntime&) under the lock on the job's runtime (made empty if it has none) and
  // returns what f returns. For the job threads' own fields: folders, plan, pass, merge counts.
  template <typename F>
  decltype(auto) WithRuntime(const std::string& job_id, F&& f) {
    absl::MutexLock lock(&mu_);
    return std::forward<F>(f)(runtime_[job_id]);
  }
  // Starts the job's stage `stage` ("" = none) now.
  void EnterStage(const std::string& job_id, const std::string& stage);
  // `text` as the job's tenant may read it (coordinator/job_folders.h TenantView). A job with
  // no runtime (ended) still has the work folder hidden.
  std::string TenantView(const std::string& job_id, std::string text);
  // Forgets the job's runtime (the job ended).
  void EraseRuntime(const std::string& job_id);

  // The job's tasks loaded into the lease table from the store (LeaseTable::LoadJob; loaded
  // already is fine), `check` called under the lock for each done task.
  absl::Status LoadTasks(const std::string& job_id, const LeaseTable::DoneCheck& check = nullptr);
  absl::Status AddTasks(const std::string& job_id, std::span<const ChunkRecord> tasks);
  absl::Status ReleaseTasks(const std::string& job_id, const std::vector<ChunkCoord>& keys);
  // The job leaves the lease table (carved, cancelled or ended): its leases are void.
  void DropTasks(const std::string& job_id);
  // Until every task of the job is committed (with except_held, every task not held).
  // CANCELLED when the job failed or left the lease table meanwhile, or on Stop.
  absl::Status WaitForTasks(const std::string& job_id, bool except_held = false);

  // §5.6.1's re-carve of object chunks: pass `pass` of a job whose plan is made.
  struct RecarvePass {
    int pass = 0;
    double resolution_m = 0;       // as the merge asked for it
    double grid_resolution_m = 0;  // its octree grid's, which the leases carry
    std::string tiles_dir, pass_dir, regions_path;
    std::vector<ChunkCoord> chunks;
  };
  // Loads the job's tasks, points its runtime at the pass (the leases read it) and queues the
  // pass's slices (new tasks, or an earlier pass of this number's again), with its chunks
  // held until ReleaseTasks. On an error the job leaves the lease table and its runtime is as
  // it was.
  absl::Status StartRecarve(const std::string& job_id, const RecarvePass& pass);
  // The job leaves the lease table and its runtime is `saved`'s again (the job's own carve,
  // its parameters, rays and rates), keeping what changed since (stages, merge counts, passes).
  void EndRecarve(const std::string& job_id, const JobRuntime& saved);

  // Wakes every wait for good: a stopping coordinator.
  void Stop();

 private:
  // Parked Lease calls: tasks may have been queued.
  void WorkMayBeQueued() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { work_cv_.SignalAll(); }
  // WaitForTasks: tasks were done, failed or dropped.
  void TasksChanged() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { done_cv_.SignalAll(); }
  std::string TenantViewLocked(const std::string& job_id, std::string text) const
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  JobStore& store_;
  LeaseTable::Clock& clock_;
  const CoordinatorCoreOptions options_;

  absl::Mutex mu_;
  absl::CondVar work_cv_;  // WorkMayBeQueued
  absl::CondVar done_cv_;  // TasksChanged
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  LeaseTable table_ ABSL_GUARDED_BY(mu_);
  WorkerRegistry workers_ ABSL_GUARDED_BY(mu_);
  std::map<std::string, JobRuntime> runtime_ ABSL_GUARDED_BY(mu_);
};

}  // namespace carvemap
