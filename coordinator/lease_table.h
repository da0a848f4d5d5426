// The coordinator's chunk scheduling (docs/DESIGN.md §5, §8): which chunk goes to which worker,
// with leases that expire, retries with a bound, and a chunk committed exactly once.
//
// Plain code: no RPC, no threads, no sleeping. Time comes from an injected Clock. Every change
// is written through the JobStore before it takes effect in memory, so a coordinator that
// restarts rebuilds the same table with LoadJob (DONE chunks stay done, LEASED ones are
// requeued). The rules are written out in docs/RPC.md ("Leases").
//
// Thread-compatible: one LeaseTable is used under the caller's lock (coordinator/
// coordinator_core.h holds its mutex around every call).
#ifndef CARVEMAP_COORDINATOR_LEASE_TABLE_H_
#define CARVEMAP_COORDINATOR_LEASE_TABLE_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "storage/job_store.h"

namespace carvemap {

struct LeaseTableOptions {
  // A lease not extended by a heartbeat within this time expires. Default 30 s = six missed
  // heartbeats at the 5 s interval of RegisterWorkerResponse.
  int64_t lease_timeout_ms = 30'000;
  // Leases a chunk may get before the job fails. Every lease counts, whether it ended in
  // FailChunk(retryable), expiry or a lost worker: a chunk that kills its worker (out of
  // memory) must not loop forever. Default 3.
  int32_t max_attempts = 3;

  absl::Status Validate() const;
};

class LeaseTable {
 public:
  // Milliseconds since the UNIX epoch. Tests use a fake.
  class Clock {
   public:
    virtual ~Clock() = default;
    virtual int64_t NowUnixMs() = 0;
    // Monotonic time, for rates and stage timings (the wall clock may jump). A fake that
    // measures them overrides it.
    virtual std::chrono::steady_clock::time_point SteadyNow() {
      return std::chrono::steady_clock::now();
    }
    // The system clock (std::chrono::system_clock).
    static Clock& System();
  };

  // A lease handed to a worker (carve.proto Lease, without the task: the service adds the
  // carve parameters and the slice or chunk the key names).
  struct Grant {
    std::string job_id;
    ChunkCoord chunk;
    std::string lease_id;
    int64_t generation = 0;
    int64_t deadline_unix_ms = 0;
    int32_t attempt = 0;  // 1-based
    int64_t wedge_count = 0;
  };

  struct Tile {
    std::string path;  // relative to the tiles root
    int64_t size_bytes = 0;
    std::string sha256_hex;
  };

  struct Progress {
    int64_t chunks_total = 0;
    int64_t chunks_done = 0;
    int64_t chunks_leased = 0;
    int64_t chunks_queued = 0;
    int64_t chunk_retries = 0;  // leases beyond each chunk's first
    bool failed = false;        // the table failed the job (max attempts or a fatal failure)
    std::string error;          // why, when failed
  };

  // `store` and `clock` are borrowed and must outlive the table.
  // REQUIRES: options.Validate().ok() (asserted in debug builds).
  LeaseTable(JobStore& store, Clock& clock, LeaseTableOptions options = {});
  LeaseTable(const LeaseTable&) = delete;
  LeaseTable& operator=(const LeaseTable&) = delete;

  // Why a DONE chunk's output cannot be trusted after a restart ("" = it can): its file
  // missing or not the size the store recorded, as a crash can leave it.
  using DoneCheck = std::function<std::string(const ChunkRecord&)>;

  // Loads a job's chunks from the store and starts leasing them. Chunks the store has as
  // LEASED (a previous coordinator's leases) are requeued and persisted as QUEUED, keeping
  // their generation so a late completion of such a lease can still be matched. DONE chunks
  // that `check` (if set) finds wanting are queued again as by Requeue, its reason stored.
  // FAILED_PRECONDITION if the job is terminal; ALREADY_EXISTS if already loaded.
  absl::Status LoadJob(absl::string_view job_id, const DoneCheck& check = nullptr);
  // Forgets a job (cancelled, failed, or finished carving). Its outstanding leases become
  // unknown: completing them is NOT_FOUND. No store write: the job's state is the caller's.
  void DropJob(absl::string_view job_id);

  // Adds new chunks (tasks) to a loaded job, queued: one store transaction (JobStore::AddChunks).
  // ALREADY_EXISTS naming the key if the job has one of them already (nothing changes then);
  // NOT_FOUND if the job is not loaded.
  absl::Status Add(absl::string_view job_id, std::span<const ChunkRecord> chunks);

  // Puts chunks of a loaded job back in the queue for another pass over them (§5.6.1: the
  // object chunks carved again at a finer resolution), whatever their state, with a fresh
  // attempt budget. Their generation is raised by one, so no lease of an earlier pass can
  // complete them. `reason` is stored as last_error. One store transaction. NOT_FOUND if the
  // job is not loaded or a key is not one of its chunks (then nothing changes).
  // held: the chunks count as not done from now on but are not leased until Release: a pass
  // whose second step must wait for its first (slices, then the chunks they feed) shows its
  // whole size at once, never "all done" in between. Held is memory only: LoadJob queues them.
  absl::Status Requeue(absl::string_view job_id, const std::vector<ChunkCoord>& keys,
                       absl::string_view reason, bool held = false);
  // Makes held chunks leasable. NOT_FOUND if the job is not loaded or a key is not held.
  absl::Status Release(absl::string_view job_id, const std::vector<ChunkCoord>& keys);

  // The next QUEUED chunk for `worker_id`, or nullopt if nothing is queued. Jobs in load order
  // (oldest first), chunks by key (x, y, z): deterministic. The chunk becomes LEASED with
  // generation + 1 and deadline now + lease_timeout.
  absl::StatusOr<std::optional<Grant>> Lease(absl::string_view worker_id);

  // Extends every lease of `worker_id` to now + lease_timeout and returns the new deadline;
  // nullopt if the worker holds no lease. Not written to the store: after a restart all leases
  // are requeued anyway, so persisted deadlines would buy nothing for an fsync per heartbeat.
  std::optional<int64_t> Heartbeat(absl::string_view worker_id);

  // Commits the chunk of `lease_id` with `tile`. Accepted when `generation` is the chunk's
  // current generation and the chunk is not DONE, including when the lease has expired (or its
  // worker was declared lost) but the chunk has not been leased again: a carve of a chunk
  // gives the same bytes whoever does it (docs/DESIGN.md §5), so the late result is as good as a
  // new one and saves a re-carve. Errors: NOT_FOUND (unknown lease or job not loaded),
  // FAILED_PRECONDITION (already committed, stale generation, job failed), INVALID_ARGUMENT
  // (malformed lease id or generation not matching the id).
  absl::Status Complete(absl::string_view lease_id, int64_t generation, const Tile& tile);

  // The worker gave up on the lease. retryable: the chunk is requeued unless it has used
  // max_attempts, in which case the job fails. Not retryable: the job fails at once.
  // Returns true if the chunk was requeued, false if the job failed. Only the current holder
  // can fail a lease: FAILED_PRECONDITION if it expired or was reassigned.
  absl::StatusOr<bool> Fail(absl::string_view lease_id, int64_t generation,
                            absl::string_view reason, bool retryable);

  // Requeues every lease whose deadline is before now (a lease whose chunk is out of
  // attempts fails its job instead). Returns how many leases expired.
  absl::StatusOr<int> ExpireLeases();

  // Requeues every lease of a worker that stopped heartbeating or re-registered. Returns how
  // many leases it held.
  absl::StatusOr<int> WorkerLost(absl::string_view worker_id);

  // NOT_FOUND if the job is not loaded.
  absl::StatusOr<Progress> GetProgress(absl::string_view job_id) const;
  // True when every chunk of the job is DONE (also for a job with no chunks); with
  // `except_held`, every chunk but the held ones.
  [[nodiscard]] bool AllDone(absl::string_view job_id, bool except_held = false) const;
  // The lease ids a worker holds, in key order.
  [[nodiscard]] std::vector<std::string> LeasesOf(absl::string_view worker_id) const;


 private:
  struct JobEntry {
    std::string id;
    std::map<ChunkCoord, ChunkRecord> chunks;
    std::set<ChunkCoord> queued;  // ordered: the lease order
    std::set<ChunkCoord> held;    // QUEUED but not leased until Release
    bool failed = false;
    std::string error;
    // The chunks by state and their retries, kept as chunks change (SetChunk), so that
    // GetProgress and AllDone, asked at every completion, cost nothing per chunk.
    int64_t done = 0, leased = 0, queued_state = 0, retries = 0;
  };
  using LeaseRef = std::pair<std::string, ChunkCoord>;  // job id, chunk

  // Requeues the given LEASED chunks of `job`, each with its reason (stored as last_error),
  // in one store transaction; fails the job in that same transaction if `force_fail` or a
  // chunk has used max_attempts.
  absl::Status RequeueOrFail(JobEntry& job,
                             const std::vector<std::pair<ChunkCoord, std::string>>& what,
                             bool force_fail);
  // Removes the chunk's lease from leases_by_worker_ (memory only).
  void ForgetLease(const ChunkRecord& chunk);
  // Every change of a chunk goes through here: it keeps the job's counts.
  static void SetChunk(JobEntry& job, ChunkRecord chunk);

  JobStore& store_;
  Clock& clock_;
  const LeaseTableOptions options_;
  std::map<std::string, JobEntry, std::less<>> jobs_;
  std::vector<std::string> job_order_;  // load order
  std::map<std::string, std::set<LeaseRef>, std::less<>> leases_by_worker_;
};

}  // namespace carvemap

#endif  // CARVEMAP_COORDINATOR_LEASE_TABLE_H_
