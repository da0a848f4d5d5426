// The job store: jobs and their chunk states in an embedded SQLite database, so a restarted
// coordinator resumes where it stopped (docs/DESIGN.md §8). Schema and durability:
// docs/JOB_STORE.md.
//
// Plain structs in, plain structs out; every method returns absl::Status(Or). The store does
// not read the clock: callers pass times (UNIX epoch milliseconds), so tests control them.
// Nothing here knows about RPC or about scheduling policy (coordinator/lease_table.h).
#ifndef CARVEMAP_STORAGE_JOB_STORE_H_
#define CARVEMAP_STORAGE_JOB_STORE_H_

#include <compare>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/synchronization/mutex.h"

struct sqlite3;

namespace carvemap {

// Stored as these integers; never renumber (the values are on disk). Same numbers as
// carvemap.v1.JobState in proto/carvemap/v1/jobs.proto.
enum class JobState : int {
  kQueued = 1,
  kIngesting = 2,
  kCarving = 3,
  kMerging = 4,
  kSucceeded = 5,
  kFailed = 6,
  kCancelled = 7,
};
[[nodiscard]] absl::string_view JobStateName(JobState state);  // "QUEUED", ...
[[nodiscard]] bool IsTerminal(JobState state);
// Forward along QUEUED → INGESTING → CARVING → MERGING → SUCCEEDED (steps may be skipped, e.g.
// an empty scan goes straight to MERGING), or to FAILED/CANCELLED from any non-terminal state.
// Nothing leaves a terminal state; a state never moves to itself.
[[nodiscard]] bool IsAllowedTransition(JobState from, JobState to);

// Stored as these integers; never renumber.
enum class ChunkState : int {
  kQueued = 1,  // waiting for a worker (never leased, or requeued)
  kLeased = 2,  // a worker holds a lease on it
  kDone = 3,    // tile committed; final
};
[[nodiscard]] absl::string_view ChunkStateName(ChunkState state);

// A 2 m chunk: floor(x / 2 m) per axis (geometry/octree_keys.h ChunkKey, kept
// independent of Eigen here). Ordered x, then y, then z: the lease order.
struct ChunkCoord {
  int32_t x = 0;
  int32_t y = 0;
  int32_t z = 0;
  auto operator<=>(const ChunkCoord&) const = default;
};

// A job's tasks are stored as chunk rows: a chunk to combine under its key, and slice k of
// carve pass p (docs/RPC.md "Slices") under {kSliceTaskX, k, p}. No chunk has that x: world
// coordinates are bounded by ±1000 km, chunk keys by ±500 000.
inline constexpr int32_t kSliceTaskX = std::numeric_limits<int32_t>::min();
inline ChunkCoord SliceTaskKey(uint32_t index, int pass) {
  return {kSliceTaskX, static_cast<int32_t>(index), pass};
}
inline bool IsSliceTask(const ChunkCoord& key) { return key.x == kSliceTaskX; }
// "chunk (x,y,z)" or "slice k" / "slice k of pass p": how errors name a task.
std::string TaskText(const ChunkCoord& key);

// Counters derived from the chunk rows, kept on the job row in the same transaction as every
// chunk change (so GetJob is one row read).
struct JobCounters {
  int64_t chunks_total = 0;
  int64_t chunks_done = 0;
  int64_t chunks_leased = 0;
  // Leases beyond each chunk's first: SUM(MAX(attempts - 1, 0)).
  int64_t chunk_retries = 0;
};

struct JobRecord {
  std::string id;      // primary key; chosen by the caller
  std::string tenant;  // from the caller's bearer token; "default" without tokens
  JobState state = JobState::kQueued;
  std::string input_path;   // relative to the data root
  std::string output_name;  // unique per tenant
  // The folder under the coordinator's data root and output root that holds this job's input
  // and output ("" = the roots themselves; the tenant's name when tenants have their own
  // folders). Kept with the job so a restart with other flags still finds its files.
  std::string tenant_dir;
  std::string params_json;  // the resolved JobParams as JSON text; the store does not parse it
  std::string error;        // set with FAILED/CANCELLED
  std::string idempotency_key;  // "" = none; unique per tenant otherwise
  int64_t created_unix_ms = 0;
  int64_t updated_unix_ms = 0;
  int64_t finished_unix_ms = 0;  // 0 until terminal
  JobCounters counters;          // read-only: maintained by the store
};

struct ChunkRecord {
  std::string job_id;
  ChunkCoord key;
  ChunkState state = ChunkState::kQueued;
  // The latest lease. Kept when the chunk is requeued, so a late completion of that lease can
  // still be matched (coordinator/lease_table.h decides whether to accept it).
  std::string lease_id;
  int64_t generation = 0;  // 0 = never leased; +1 on every lease (and LeaseTable::Requeue)
  std::string worker_id;
  int64_t deadline_unix_ms = 0;  // deadline of the lease as first granted (see JOB_STORE.md)
  int32_t attempts = 0;          // how often the chunk has been leased
  std::string last_error;        // last failure reason (FailChunk, expiry, lost worker)
  std::string tile_path;         // set when DONE
  int64_t tile_size_bytes = 0;
  std::string tile_sha256_hex;
  int64_t wedge_count = 0;  // wedges binned into this chunk
};

// One conditional chunk write: applied only if the stored generation equals
// `expected_generation` (compare-and-set).
struct ChunkUpdate {
  ChunkRecord chunk;
  int64_t expected_generation = 0;
};

// A job state change made together with chunk writes.
struct JobTransition {
  JobState to = JobState::kFailed;
  std::string error;
  int64_t now_unix_ms = 0;
};

struct ListJobsQuery {
  std::optional<std::string> tenant;  // nullopt = all tenants (admin tools)
  std::optional<JobState> state;      // nullopt = all states
  int limit = 50;                     // rows to return, 1..1000
  // Keyset cursor: only jobs strictly older than (created_unix_ms, id) of the last row seen.
  std::optional<std::pair<int64_t, std::string>> before;
};

class JobStore {
 public:
  struct Options {
    // Create the file and the schema if the file does not exist.
    bool create_if_missing = true;
    // How long a write waits for another connection's lock before failing UNAVAILABLE.
    int busy_timeout_ms = 5000;
  };

  // The schema version this build writes (docs/JOB_STORE.md). Opening a file of a newer
  // version is FAILED_PRECONDITION; an older one is migrated in place.
  static constexpr int kSchemaVersion = 2;

  // Opens (or creates) the store at `path`. A file that is not a SQLite database, or whose
  // schema is damaged, is DATA_LOSS with `path` in the message.
  static absl::StatusOr<std::unique_ptr<JobStore>> Open(const std::string& path,
                                                        const Options& options);
  static absl::StatusOr<std::unique_ptr<JobStore>> Open(const std::string& path) {
    return Open(path, Options());
  }

  JobStore(const JobStore&) = delete;
  JobStore& operator=(const JobStore&) = delete;
  ~JobStore();  // closes the database; committed writes are on disk already

  [[nodiscard]] const std::string& path() const { return path_; }

  // ---- jobs. All methods are thread-safe (one connection behind a mutex).

  // Inserts a new job. ALREADY_EXISTS if the id, the (tenant, output_name) or the non-empty
  // (tenant, idempotency_key) is taken. `job.counters` is ignored. With
  // `max_unfinished_of_tenant` > 0: RESOURCE_EXHAUSTED (nothing written) when the tenant
  // already has that many jobs not in a terminal state; counted and inserted in one
  // transaction, so concurrent submits cannot both slip under the limit.
  absl::Status CreateJob(const JobRecord& job, int max_unfinished_of_tenant = 0);
  // NOT_FOUND if unknown.
  absl::StatusOr<JobRecord> GetJob(absl::string_view job_id);
  // The tenant's job with this idempotency key, or nullopt.
  absl::StatusOr<std::optional<JobRecord>> FindJobByIdempotencyKey(absl::string_view tenant,
                                                                   absl::string_view key);
  // Newest first (created_unix_ms, then id, descending).
  absl::StatusOr<std::vector<JobRecord>> ListJobs(const ListJobsQuery& query);
  // Moves a job to `t.to`, storing `t.error` (FAILED/CANCELLED) and finished_unix_ms when the
  // new state is terminal. FAILED_PRECONDITION if IsAllowedTransition says no.
  absl::Status TransitionJob(absl::string_view job_id, const JobTransition& t);

  // ---- chunks

  // Inserts the chunks of a job (state QUEUED, generation 0) in one transaction and updates
  // chunks_total. ALREADY_EXISTS if a chunk key repeats; NOT_FOUND if the job does not exist.
  absl::Status AddChunks(absl::string_view job_id, std::span<const ChunkRecord> chunks);
  // All chunks of a job, ordered by key (x, y, z).
  absl::StatusOr<std::vector<ChunkRecord>> ListChunks(absl::string_view job_id);
  // Applies all updates (and the optional transition of their job, which then must be the
  // same for all updates) in one transaction: every row is written or none.
  // FAILED_PRECONDITION (nothing written) if any generation does not match or the transition
  // is not allowed; NOT_FOUND if a chunk does not exist. Recomputes the job counters and sets
  // the job's updated_unix_ms to `now_unix_ms` (if later).
  absl::Status UpdateChunks(std::span<const ChunkUpdate> updates, int64_t now_unix_ms,
                            const std::optional<JobTransition>& job_transition = std::nullopt);

 private:
  JobStore(std::string path, sqlite3* db) : path_(std::move(path)), db_(db) {}

  absl::Status InitSchema() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  absl::Status TransitionLocked(absl::string_view job_id, const JobTransition& t)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  absl::Status RecountLocked(absl::string_view job_id, int64_t now_unix_ms)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  absl::StatusOr<JobRecord> GetJobLocked(absl::string_view job_id)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const std::string path_;
  absl::Mutex mu_;
  // A SQLite connection is used by one transaction at a time; the mutex makes each method
  // (and each BEGIN…COMMIT) atomic with respect to other threads.
  sqlite3* const db_ ABSL_PT_GUARDED_BY(mu_);
};

}  // namespace carvemap

#endif  // CARVEMAP_STORAGE_JOB_STORE_H_
