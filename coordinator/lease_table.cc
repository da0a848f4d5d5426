#include "coordinator/lease_table.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <utility>

#include "absl/strings/str_cat.h"
#include "coordinator/lease_id.h"

namespace carvemap {
namespace {

class SystemClock final : public LeaseTable::Clock {
 public:
  int64_t NowUnixMs() override {
    return std::chrono::duration_cast<std::chrono::milliseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  }
};

}  // namespace

absl::Status LeaseTableOptions::Validate() const {
  if (lease_timeout_ms <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("lease table: lease_timeout_ms must be > 0, got ", lease_timeout_ms));
  }
  if (max_attempts < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("lease table: max_attempts must be >= 1, got ", max_attempts));
  }
  return absl::OkStatus();
}

LeaseTable::Clock& LeaseTable::Clock::System() {
  static SystemClock* clock = new SystemClock();  // never destroyed: usable at exit
  return *clock;
}

LeaseTable::LeaseTable(JobStore& store, Clock& clock, LeaseTableOptions options)
    : store_(store), clock_(clock), options_(options) {
  assert(options_.Validate().ok());
}

namespace {

// The counts of one chunk in its job's (JobEntry::done, ...), `sign` +1 to add it, −1 to take
// it out.
template <typename Job>
void CountChunk(Job& job, const ChunkRecord& c, int sign) {
  job.done += sign * (c.state == ChunkState::kDone);
  job.leased += sign * (c.state == ChunkState::kLeased);
  job.queued_state += sign * (c.state == ChunkState::kQueued);
  job.retries += sign * std::max(0, c.attempts - 1);
}

}  // namespace

void LeaseTable::SetChunk(JobEntry& job, ChunkRecord chunk) {
  auto [it, inserted] = job.chunks.try_emplace(chunk.key);
  if (!inserted) CountChunk(job, it->second, -1);
  it->second = std::move(chunk);
  CountChunk(job, it->second, +1);
}

// ---- jobs

namespace {

// `chunk` queued for another lease: a new generation (no earlier lease can complete it), a
// fresh attempt budget, no tile.
ChunkUpdate QueuedAgain(const ChunkRecord& chunk, std::string reason) {
  ChunkUpdate u{chunk, chunk.generation};
  u.chunk.state = ChunkState::kQueued;
  u.chunk.generation += 1;
  u.chunk.attempts = 0;
  u.chunk.deadline_unix_ms = 0;
  u.chunk.worker_id.clear();
  u.chunk.last_error = std::move(reason);
  u.chunk.tile_path.clear();
  u.chunk.tile_size_bytes = 0;
  u.chunk.tile_sha256_hex.clear();
  return u;
}

}  // namespace

absl::Status LeaseTable::LoadJob(absl::string_view job_id, const DoneCheck& check) {
  if (jobs_.find(job_id) != jobs_.end()) {
    return absl::AlreadyExistsError(absl::StrCat("lease table: job ", job_id, " already loaded"));
  }
  absl::StatusOr<JobRecord> record = store_.GetJob(job_id);
  if (!record.ok()) return record.status();
  if (IsTerminal(record->state)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "lease table: job ", job_id, " is ", JobStateName(record->state), ", nothing to lease"));
  }
  absl::StatusOr<std::vector<ChunkRecord>> chunks = store_.ListChunks(job_id);
  if (!chunks.ok()) return chunks.status();

  // Leases of a previous coordinator: their workers do not know us (they must register again),
  // so the chunks go back to the queue. The attempt is given back, since the lease ended
  // without a verdict on the chunk; generation and lease id stay, so the old holder can still
  // complete it until it is leased again.
  const int64_t now = clock_.NowUnixMs();
  std::vector<ChunkUpdate> requeue;
  JobEntry job;
  job.id = std::string(job_id);
  for (ChunkRecord& c : *chunks) {
    if (c.state == ChunkState::kLeased) {
      ChunkUpdate u{c, c.generation};
      u.chunk.state = ChunkState::kQueued;
      u.chunk.deadline_unix_ms = 0;
      u.chunk.attempts = std::max(0, c.attempts - 1);
      u.chunk.last_error = "requeued: coordinator restarted while leased";
      requeue.push_back(u);
      c = u.chunk;
    } else if (c.state == ChunkState::kDone && check) {
      if (std::string why = check(c); !why.empty()) {
        // A new generation: nothing of the lease that made the bad file counts any more.
        requeue.push_back(QueuedAgain(c, absl::StrCat("queued again at restart: ", why)));
        c = requeue.back().chunk;
      }
    }
    if (c.state == ChunkState::kQueued) job.queued.insert(c.key);
    SetChunk(job, std::move(c));
  }
  if (!requeue.empty()) {
    if (absl::Status s = store_.UpdateChunks(requeue, now); !s.ok()) return s;
  }
  job_order_.push_back(job.id);
  jobs_.emplace(job.id, std::move(job));
  return absl::OkStatus();
}

void LeaseTable::DropJob(absl::string_view job_id) {
  auto it = jobs_.find(job_id);
  if (it == jobs_.end()) return;
  for (auto& [key, chunk] : it->second.chunks) {
    if (chunk.state == ChunkState::kLeased) ForgetLease(chunk);
  }
  jobs_.erase(it);
  std::erase(job_order_, std::string(job_id));
}

void LeaseTable::ForgetLease(const ChunkRecord& chunk) {
  auto w = leases_by_worker_.find(chunk.worker_id);
  if (w == leases_by_worker_.end()) return;
  w->second.erase({chunk.job_id, chunk.key});
  if (w->second.empty()) leases_by_worker_.erase(w);
}

// ---- leasing

absl::StatusOr<std::optional<LeaseTable::Grant>> LeaseTable::Lease(absl::string_view worker_id) {
  if (worker_id.empty()) return absl::InvalidArgumentError("lease: empty worker id");
  const int64_t now = clock_.NowUnixMs();
  for (const std::string& job_id : job_order_) {
    JobEntry& job = jobs_.at(job_id);
    if (job.failed || job.queued.empty()) continue;
    const ChunkCoord key = *job.queued.begin();
    const ChunkRecord& current = job.chunks.at(key);
    ChunkRecord next = current;
    next.state = ChunkState::kLeased;
    next.generation = current.generation + 1;
    next.lease_id = LeaseId{std::string(job_id), key, next.generation}.ToString();
    next.worker_id = std::string(worker_id);
    next.deadline_unix_ms = now + options_.lease_timeout_ms;
    next.attempts = current.attempts + 1;
    // Persist first: if the write fails the table is unchanged and the chunk stays queued.
    const ChunkUpdate update{next, current.generation};
    if (absl::Status s = store_.UpdateChunks({&update, 1}, now); !s.ok()) return s;
    job.queued.erase(key);
    leases_by_worker_[next.worker_id].insert({job_id, key});
    Grant grant{
        job_id,          key, next.lease_id, next.generation, next.deadline_unix_ms, next.attempts,
        next.wedge_count};
    SetChunk(job, std::move(next));
    return grant;
  }
  return std::nullopt;
}

std::optional<int64_t> LeaseTable::Heartbeat(absl::string_view worker_id) {
  auto w = leases_by_worker_.find(worker_id);
  if (w == leases_by_worker_.end()) return std::nullopt;
  const int64_t deadline = clock_.NowUnixMs() + options_.lease_timeout_ms;
  for (const LeaseRef& ref : w->second) {
    jobs_.at(ref.first).chunks.at(ref.second).deadline_unix_ms = deadline;
  }
  return deadline;
}

absl::Status LeaseTable::Add(absl::string_view job_id, std::span<const ChunkRecord> chunks) {
  auto it = jobs_.find(job_id);
  if (it == jobs_.end())
    return absl::NotFoundError(absl::StrCat("add: job ", job_id, " is not loaded"));
  JobEntry& job = it->second;
  for (const ChunkRecord& c : chunks) {
    if (job.chunks.count(c.key)) {
      return absl::AlreadyExistsError(
          absl::StrCat("add: job ", job.id, " has ", TaskText(c.key), " already"));
    }
  }
  if (absl::Status s = store_.AddChunks(job_id, chunks); !s.ok()) return s;
  for (const ChunkRecord& c : chunks) {
    ChunkRecord record = c;
    record.job_id = job.id;
    record.state = ChunkState::kQueued;
    job.queued.insert(record.key);
    SetChunk(job, std::move(record));
  }
  return absl::OkStatus();
}

absl::Status LeaseTable::Requeue(absl::string_view job_id, const std::vector<ChunkCoord>& keys,
                                 absl::string_view reason, bool held) {
  auto it = jobs_.find(job_id);
  if (it == jobs_.end()) {
    return absl::NotFoundError(absl::StrCat("requeue: job ", job_id, " is not loaded"));
  }
  JobEntry& job = it->second;
  std::vector<ChunkUpdate> updates;
  updates.reserve(keys.size());
  for (const ChunkCoord& key : keys) {
    auto c = job.chunks.find(key);
    if (c == job.chunks.end()) {
      return absl::NotFoundError(absl::StrCat("requeue: job ", job.id, " has no ", TaskText(key)));
    }
    updates.push_back(QueuedAgain(c->second, std::string(reason)));
  }
  if (absl::Status s = store_.UpdateChunks(updates, clock_.NowUnixMs()); !s.ok()) return s;
  for (const ChunkUpdate& u : updates) {
    const ChunkRecord& current = job.chunks.at(u.chunk.key);
    if (current.state == ChunkState::kLeased) ForgetLease(current);
    if (held) {
      job.queued.erase(u.chunk.key);
      job.held.insert(u.chunk.key);
    } else {
      job.held.erase(u.chunk.key);
      job.queued.insert(u.chunk.key);
    }
    SetChunk(job, u.chunk);
  }
  return absl::OkStatus();
}

absl::Status LeaseTable::Release(absl::string_view job_id, const std::vector<ChunkCoord>& keys) {
  auto it = jobs_.find(job_id);
  if (it == jobs_.end()) {
    return absl::NotFoundError(absl::StrCat("release: job ", job_id, " is not loaded"));
  }
  JobEntry& job = it->second;
  for (const ChunkCoord& key : keys) {
    if (!job.held.count(key)) {
      return absl::NotFoundError(
          absl::StrCat("release: job ", job.id, " holds no ", TaskText(key)));
    }
  }
  for (const ChunkCoord& key : keys) {
    job.held.erase(key);
    job.queued.insert(key);
  }
  return absl::OkStatus();
}

absl::Status LeaseTable::Complete(absl::string_view lease_id, int64_t generation,
                                  const Tile& tile) {
  absl::StatusOr<LeaseId> parsed = LeaseId::Parse(lease_id);
  if (!parsed.ok()) return parsed.status();
  if (parsed->generation != generation) {
    return absl::InvalidArgumentError(absl::StrCat("complete ", lease_id, ": generation ",
                                                   generation, " does not match the lease id"));
  }
  auto it = jobs_.find(parsed->job_id);
  if (it == jobs_.end()) {
    return absl::NotFoundError(
        absl::StrCat("complete ", lease_id, ": job ", parsed->job_id, " is not being carved"));
  }
  JobEntry& job = it->second;
  if (job.failed) {
    return absl::FailedPreconditionError(
        absl::StrCat("complete ", lease_id, ": job ", job.id, " failed: ", job.error));
  }
  auto c = job.chunks.find(parsed->chunk);
  if (c == job.chunks.end()) {
    return absl::NotFoundError(
        absl::StrCat("complete ", lease_id, ": job ", job.id, " has no ", TaskText(parsed->chunk)));
  }
  const ChunkRecord& current = c->second;
  if (current.state == ChunkState::kDone) {
    return absl::FailedPreconditionError(
        absl::StrCat("complete ", lease_id, ": ", TaskText(current.key),
                     " already committed by lease ", current.lease_id));
  }
  if (current.generation != generation) {
    return absl::FailedPreconditionError(
        absl::StrCat("complete ", lease_id, ": stale lease, ", TaskText(current.key),
                     " was leased again (generation ", current.generation, ")"));
  }
  // Same generation: either still LEASED (in time or past its deadline) or QUEUED after expiry
  // and not yet leased again. Both are accepted; see the header.
  ChunkRecord next = current;
  next.state = ChunkState::kDone;
  next.deadline_unix_ms = 0;
  next.tile_path = tile.path;
  next.tile_size_bytes = tile.size_bytes;
  next.tile_sha256_hex = tile.sha256_hex;
  const ChunkUpdate update{next, current.generation};
  if (absl::Status s = store_.UpdateChunks({&update, 1}, clock_.NowUnixMs()); !s.ok()) return s;
  if (current.state == ChunkState::kLeased) ForgetLease(current);
  job.queued.erase(current.key);
  SetChunk(job, std::move(next));
  return absl::OkStatus();
}

absl::StatusOr<bool> LeaseTable::Fail(absl::string_view lease_id, int64_t generation,
                                      absl::string_view reason, bool retryable) {
  absl::StatusOr<LeaseId> parsed = LeaseId::Parse(lease_id);
  if (!parsed.ok()) return parsed.status();
  auto it = jobs_.find(parsed->job_id);
  if (it == jobs_.end()) {
    return absl::NotFoundError(
        absl::StrCat("fail ", lease_id, ": job ", parsed->job_id, " is not being carved"));
  }
  JobEntry& job = it->second;
  auto c = job.chunks.find(parsed->chunk);
  if (job.failed || c == job.chunks.end() || c->second.state != ChunkState::kLeased ||
      c->second.generation != generation || parsed->generation != generation) {
    return absl::FailedPreconditionError(
        absl::StrCat("fail ", lease_id, ": the lease is no longer held"));
  }
  const std::string worker = c->second.worker_id;
  std::vector<std::pair<ChunkCoord, std::string>> what = {
      {parsed->chunk, absl::StrCat("worker ", worker, ": ", reason)}};
  if (absl::Status s = RequeueOrFail(job, what, /*force_fail=*/!retryable); !s.ok()) return s;
  return !job.failed;
}

// ---- expiry and lost workers

absl::StatusOr<int> LeaseTable::ExpireLeases() {
  const int64_t now = clock_.NowUnixMs();
  std::map<std::string, std::vector<std::pair<ChunkCoord, std::string>>> by_job;
  int expired = 0;
  for (const auto& [worker, refs] : leases_by_worker_) {
    for (const LeaseRef& ref : refs) {
      const ChunkRecord& c = jobs_.at(ref.first).chunks.at(ref.second);
      if (c.deadline_unix_ms < now) {
        by_job[ref.first].push_back(
            {ref.second,
             absl::StrCat("lease ", c.lease_id, " of worker ", worker, " expired (deadline passed ",
                          now - c.deadline_unix_ms, " ms ago)")});
        ++expired;
      }
    }
  }
  for (const auto& [job_id, what] : by_job) {
    if (absl::Status s = RequeueOrFail(jobs_.at(job_id), what, false); !s.ok()) return s;
  }
  return expired;
}

absl::StatusOr<int> LeaseTable::WorkerLost(absl::string_view worker_id) {
  auto w = leases_by_worker_.find(worker_id);
  if (w == leases_by_worker_.end()) return 0;
  std::map<std::string, std::vector<std::pair<ChunkCoord, std::string>>> by_job;
  const std::set<LeaseRef> refs = w->second;  // RequeueOrFail edits the map
  for (const LeaseRef& ref : refs) {
    by_job[ref.first].push_back({ref.second, absl::StrCat("worker ", worker_id, " lost")});
  }
  for (const auto& [job_id, what] : by_job) {
    if (absl::Status s = RequeueOrFail(jobs_.at(job_id), what, false); !s.ok()) return s;
  }
  return static_cast<int>(refs.size());
}

absl::Status LeaseTable::RequeueOrFail(JobEntry& job,
                                       const std::vector<std::pair<ChunkCoord, std::string>>& what,
                                       bool force_fail) {
  const int64_t now = clock_.NowUnixMs();
  std::vector<ChunkUpdate> updates;
  std::optional<JobTransition> fail;
  for (const auto& [key, why] : what) {
    const ChunkRecord& current = job.chunks.at(key);
    assert(current.state == ChunkState::kLeased);
    ChunkUpdate u{current, current.generation};
    u.chunk.state = ChunkState::kQueued;
    u.chunk.deadline_unix_ms = 0;
    u.chunk.last_error = why;
    updates.push_back(u);
    if (!fail && (force_fail || current.attempts >= options_.max_attempts)) {
      fail =
          JobTransition{JobState::kFailed,
                        force_fail ? absl::StrCat(TaskText(key), ": ", why, " (not retryable)")
                                   : absl::StrCat(TaskText(key), ": attempt ", current.attempts,
                                                  " of ", options_.max_attempts, " failed: ", why),
                        now};
    }
  }
  // One transaction: the requeues and the job failure land together or not at all.
  if (absl::Status s = store_.UpdateChunks(updates, now, fail); !s.ok()) return s;
  for (ChunkUpdate& u : updates) {
    ForgetLease(job.chunks.at(u.chunk.key));
    job.queued.insert(u.chunk.key);
    SetChunk(job, std::move(u.chunk));
  }
  if (fail) {
    job.failed = true;
    job.error = fail->error;
    // The job's other leases are void: completing them is FAILED_PRECONDITION, and they no
    // longer expire or extend. The store keeps them as they are; a FAILED job is never loaded.
    for (auto& [key, chunk] : job.chunks) {
      if (chunk.state == ChunkState::kLeased) ForgetLease(chunk);
    }
  }
  return absl::OkStatus();
}

// ---- reporting

absl::StatusOr<LeaseTable::Progress> LeaseTable::GetProgress(absl::string_view job_id) const {
  auto it = jobs_.find(job_id);
  if (it == jobs_.end()) {
    return absl::NotFoundError(absl::StrCat("lease table: job ", job_id, " not loaded"));
  }
  const JobEntry& job = it->second;
  Progress p;
  p.failed = job.failed;
  p.error = job.error;
  p.chunks_total = int64_t(job.chunks.size());
  p.chunks_done = job.done;
  p.chunks_leased = job.leased;
  p.chunks_queued = job.queued_state;
  p.chunk_retries = job.retries;
  return p;
}

bool LeaseTable::AllDone(absl::string_view job_id, bool except_held) const {
  auto it = jobs_.find(job_id);
  if (it == jobs_.end() || it->second.failed) return false;
  // Held chunks are QUEUED (Requeue raised their generation: no earlier lease completes them).
  const JobEntry& job = it->second;
  const int64_t need = int64_t(job.chunks.size()) - (except_held ? int64_t(job.held.size()) : 0);
  return job.done == need;
}

std::vector<std::string> LeaseTable::LeasesOf(absl::string_view worker_id) const {
  std::vector<std::string> ids;
  auto w = leases_by_worker_.find(worker_id);
  if (w == leases_by_worker_.end()) return ids;
  for (const LeaseRef& ref : w->second) {
    ids.push_back(jobs_.at(ref.first).chunks.at(ref.second).lease_id);
  }
  return ids;
}

}  // namespace carvemap
