#include "storage/job_store.h"

#include <sqlite3.h>

#include <algorithm>
#include <map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"

namespace carvemap {

std::string TaskText(const ChunkCoord& key) {
  if (IsSliceTask(key)) {
    return key.z == 0 ? absl::StrCat("slice ", key.y)
                      : absl::StrCat("slice ", key.y, " of pass ", key.z);
  }
  return absl::StrCat("chunk (", key.x, ",", key.y, ",", key.z, ")");
}
namespace {

// PRAGMA application_id marks the file as a carvemap job store ("CVJS"), so opening some other
// SQLite database by mistake is an error instead of a silent schema creation next to its tables.
constexpr int32_t kApplicationId = 0x43564a53;

constexpr char kSchemaV1[] = R"sql(
CREATE TABLE schema_version (version INTEGER NOT NULL);
CREATE TABLE jobs (
  id               TEXT PRIMARY KEY NOT NULL,
  tenant           TEXT NOT NULL,
  state            INTEGER NOT NULL CHECK (state BETWEEN 1 AND 7),
  input_path       TEXT NOT NULL,
  output_name      TEXT NOT NULL,
  params_json      TEXT NOT NULL,
  error            TEXT NOT NULL DEFAULT '',
  idempotency_key  TEXT NOT NULL DEFAULT '',
  created_unix_ms  INTEGER NOT NULL,
  updated_unix_ms  INTEGER NOT NULL,
  finished_unix_ms INTEGER NOT NULL DEFAULT 0,
  chunks_total     INTEGER NOT NULL DEFAULT 0,
  chunks_done      INTEGER NOT NULL DEFAULT 0,
  chunks_leased    INTEGER NOT NULL DEFAULT 0,
  chunk_retries    INTEGER NOT NULL DEFAULT 0
);
CREATE UNIQUE INDEX jobs_by_output ON jobs (tenant, output_name);
CREATE UNIQUE INDEX jobs_by_idempotency_key ON jobs (tenant, idempotency_key)
  WHERE idempotency_key <> '';
CREATE INDEX jobs_by_created ON jobs (created_unix_ms DESC, id DESC);
CREATE TABLE chunks (
  job_id           TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
  x                INTEGER NOT NULL,
  y                INTEGER NOT NULL,
  z                INTEGER NOT NULL,
  state            INTEGER NOT NULL CHECK (state BETWEEN 1 AND 3),
  lease_id         TEXT NOT NULL DEFAULT '',
  generation       INTEGER NOT NULL DEFAULT 0,
  worker_id        TEXT NOT NULL DEFAULT '',
  deadline_unix_ms INTEGER NOT NULL DEFAULT 0,
  attempts         INTEGER NOT NULL DEFAULT 0,
  last_error       TEXT NOT NULL DEFAULT '',
  tile_path        TEXT NOT NULL DEFAULT '',
  tile_size_bytes  INTEGER NOT NULL DEFAULT 0,
  tile_sha256_hex  TEXT NOT NULL DEFAULT '',
  wedge_count      INTEGER NOT NULL DEFAULT 0,
  PRIMARY KEY (job_id, x, y, z)
) WITHOUT ROWID;
CREATE INDEX chunks_by_state ON chunks (job_id, state);
INSERT INTO schema_version (version) VALUES (1);
)sql";

// Version 2 (tenants, docs/DESIGN.md §8): every job has a tenant, and the folder of its files.
// Jobs from before tenants existed belong to the default tenant and keep their files at the
// roots (tenant_dir '').
constexpr char kMigrateV1ToV2[] = R"sql(
ALTER TABLE jobs ADD COLUMN tenant_dir TEXT NOT NULL DEFAULT '';
UPDATE jobs SET tenant = 'default' WHERE tenant = '';
UPDATE schema_version SET version = 2;
)sql";

constexpr char kJobColumns[] =
    "id, tenant, state, input_path, output_name, params_json, error, idempotency_key, "
    "created_unix_ms, updated_unix_ms, finished_unix_ms, chunks_total, chunks_done, "
    "chunks_leased, chunk_retries, tenant_dir";
constexpr char kChunkColumns[] =
    "job_id, x, y, z, state, lease_id, generation, worker_id, deadline_unix_ms, attempts, "
    "last_error, tile_path, tile_size_bytes, tile_sha256_hex, wedge_count";

// Maps a SQLite result code to the canonical code a caller can act on.
absl::StatusCode CodeFor(int rc) {
  switch (rc & 0xff) {  // primary code; extended codes refine it
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
    case SQLITE_IOERR:
    case SQLITE_FULL:
      return absl::StatusCode::kUnavailable;  // retryable: another writer, disk full, EIO
    case SQLITE_CONSTRAINT:
      return absl::StatusCode::kAlreadyExists;
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      return absl::StatusCode::kDataLoss;
    case SQLITE_CANTOPEN:
      return absl::StatusCode::kNotFound;
    case SQLITE_READONLY:
    case SQLITE_PERM:
    case SQLITE_AUTH:
      return absl::StatusCode::kPermissionDenied;
    default:
      return absl::StatusCode::kInternal;
  }
}

// Every error names the file and the operation: "job store /var/carvemap/jobs.db: insert job
// j-1: UNIQUE constraint failed: jobs.id".
absl::Status SqliteError(const std::string& path, sqlite3* db, int rc, absl::string_view what) {
  const std::string detail = db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  const std::string generic = sqlite3_errstr(rc);
  return absl::Status(CodeFor(rc),
                      absl::StrCat("job store ", path, ": ", what, ": ", detail,
                                   detail == generic ? "" : absl::StrCat(" (", generic, ")")));
}

// A prepared statement; finalized on destruction.
class Stmt {
 public:
  Stmt(const std::string& path, sqlite3* db) : path_(path), db_(db) {}
  ~Stmt() { sqlite3_finalize(stmt_); }
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;

  // `what` names the operation in errors; default: the SQL text.
  absl::Status Prepare(absl::string_view sql, absl::string_view what = {}) {
    int rc = sqlite3_prepare_v2(db_, sql.data(), static_cast<int>(sql.size()), &stmt_, nullptr);
    if (rc != SQLITE_OK) {
      return SqliteError(path_, db_, rc, what.empty() ? absl::StrCat("prepare ", sql) : what);
    }
    return absl::OkStatus();
  }
  // Makes the statement runnable again with fresh bindings.
  void Reset() {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
    bound_ = 0;
  }
  // Binds are 1-based, in order of the `?` in the statement.
  Stmt& Text(absl::string_view s) {
    sqlite3_bind_text(stmt_, ++bound_, s.data(), static_cast<int>(s.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& Int(int64_t v) {
    sqlite3_bind_int64(stmt_, ++bound_, v);
    return *this;
  }
  // true: a row is available; false: done.
  absl::StatusOr<bool> Step(absl::string_view what) {
    int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    return SqliteError(path_, db_, rc, what);
  }
  absl::Status Run(absl::string_view what) {
    absl::StatusOr<bool> row = Step(what);
    return row.ok() ? absl::OkStatus() : row.status();
  }
  int64_t ColInt(int i) const { return sqlite3_column_int64(stmt_, i); }
  std::string ColText(int i) const {
    const unsigned char* p = sqlite3_column_text(stmt_, i);
    return p == nullptr ? std::string()
                        : std::string(reinterpret_cast<const char*>(p),
                                      static_cast<size_t>(sqlite3_column_bytes(stmt_, i)));
  }

 private:
  const std::string& path_;
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  int bound_ = 0;
};

absl::Status Exec(const std::string& path, sqlite3* db, const char* sql, absl::string_view what) {
  char* err = nullptr;
  int rc = sqlite3_exec(db, sql, nullptr, nullptr, &err);
  sqlite3_free(err);  // sqlite3_errmsg(db) carries the same text
  if (rc != SQLITE_OK) return SqliteError(path, db, rc, what);
  return absl::OkStatus();
}

// BEGIN IMMEDIATE takes the write lock up front, so two connections cannot both read and then
// deadlock upgrading to write (SQLITE_BUSY mid-transaction). Rolls back unless committed.
class Transaction {
 public:
  Transaction(const std::string& path, sqlite3* db) : path_(path), db_(db) {}
  ~Transaction() {
    if (open_) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
  }
  absl::Status Begin() {
    absl::Status s = Exec(path_, db_, "BEGIN IMMEDIATE", "begin transaction");
    open_ = s.ok();
    return s;
  }
  absl::Status Commit() {
    absl::Status s = Exec(path_, db_, "COMMIT", "commit");
    if (s.ok()) open_ = false;
    return s;
  }

 private:
  const std::string& path_;
  sqlite3* db_;
  bool open_ = false;
};

JobRecord ReadJob(const Stmt& s) {
  JobRecord j;
  j.id = s.ColText(0);
  j.tenant = s.ColText(1);
  j.state = static_cast<JobState>(s.ColInt(2));
  j.input_path = s.ColText(3);
  j.output_name = s.ColText(4);
  j.params_json = s.ColText(5);
  j.error = s.ColText(6);
  j.idempotency_key = s.ColText(7);
  j.created_unix_ms = s.ColInt(8);
  j.updated_unix_ms = s.ColInt(9);
  j.finished_unix_ms = s.ColInt(10);
  j.counters.chunks_total = s.ColInt(11);
  j.counters.chunks_done = s.ColInt(12);
  j.counters.chunks_leased = s.ColInt(13);
  j.counters.chunk_retries = s.ColInt(14);
  j.tenant_dir = s.ColText(15);
  return j;
}

ChunkRecord ReadChunk(const Stmt& s) {
  ChunkRecord c;
  c.job_id = s.ColText(0);
  c.key = {static_cast<int32_t>(s.ColInt(1)), static_cast<int32_t>(s.ColInt(2)),
           static_cast<int32_t>(s.ColInt(3))};
  c.state = static_cast<ChunkState>(s.ColInt(4));
  c.lease_id = s.ColText(5);
  c.generation = s.ColInt(6);
  c.worker_id = s.ColText(7);
  c.deadline_unix_ms = s.ColInt(8);
  c.attempts = static_cast<int32_t>(s.ColInt(9));
  c.last_error = s.ColText(10);
  c.tile_path = s.ColText(11);
  c.tile_size_bytes = s.ColInt(12);
  c.tile_sha256_hex = s.ColText(13);
  c.wedge_count = s.ColInt(14);
  return c;
}

std::string KeyText(const ChunkCoord& k) { return absl::StrCat("(", k.x, ",", k.y, ",", k.z, ")"); }

}  // namespace

absl::string_view JobStateName(JobState state) {
  switch (state) {
    case JobState::kQueued: return "QUEUED";
    case JobState::kIngesting: return "INGESTING";
    case JobState::kCarving: return "CARVING";
    case JobState::kMerging: return "MERGING";
    case JobState::kSucceeded: return "SUCCEEDED";
    case JobState::kFailed: return "FAILED";
    case JobState::kCancelled: return "CANCELLED";
  }
  return "UNKNOWN";
}

absl::string_view ChunkStateName(ChunkState state) {
  switch (state) {
    case ChunkState::kQueued: return "QUEUED";
    case ChunkState::kLeased: return "LEASED";
    case ChunkState::kDone: return "DONE";
  }
  return "UNKNOWN";
}

bool IsTerminal(JobState state) {
  return state == JobState::kSucceeded || state == JobState::kFailed ||
         state == JobState::kCancelled;
}

bool IsAllowedTransition(JobState from, JobState to) {
  if (IsTerminal(from) || from == to) return false;
  if (to == JobState::kFailed || to == JobState::kCancelled) return true;
  // The pipeline states are numbered in order; forward moves only.
  return static_cast<int>(to) > static_cast<int>(from);
}

// ---- open and schema

absl::StatusOr<std::unique_ptr<JobStore>> JobStore::Open(const std::string& path,
                                                         const Options& options) {
  sqlite3* db = nullptr;
  // FULLMUTEX (serialized) as a second line of defence; the store's own mutex is what makes
  // multi-statement transactions atomic across threads.
  int flags = SQLITE_OPEN_READWRITE | SQLITE_OPEN_FULLMUTEX;
  if (options.create_if_missing) flags |= SQLITE_OPEN_CREATE;
  int rc = sqlite3_open_v2(path.c_str(), &db, flags, nullptr);
  if (rc != SQLITE_OK) {
    absl::Status s = SqliteError(path, db, rc, "open");
    sqlite3_close(db);
    return s;
  }
  sqlite3_extended_result_codes(db, 1);
  sqlite3_busy_timeout(db, options.busy_timeout_ms);
  std::unique_ptr<JobStore> store(new JobStore(path, db));
  absl::MutexLock lock(&store->mu_);
  absl::Status s = store->InitSchema();
  if (!s.ok()) return s;  // ~JobStore closes the handle
  return store;
}

JobStore::~JobStore() {
  // sqlite3_close_v2 defers the close if a statement were still alive; none outlive a method.
  sqlite3_close_v2(db_);
}

absl::Status JobStore::InitSchema() {
  // WAL: readers do not block the writer. synchronous=FULL: every COMMIT is fsynced to the WAL
  // before it returns, so a job or a chunk commit acknowledged to a worker survives a crash or
  // power loss (NORMAL could lose the last commits). This is the first statement that reads
  // the file, so a non-database fails here with SQLITE_NOTADB.
  {
    Stmt s(path_, db_);
    if (absl::Status st = s.Prepare("PRAGMA journal_mode=WAL", "open"); !st.ok()) return st;
    absl::StatusOr<bool> row = s.Step("set journal_mode=WAL");
    if (!row.ok()) return row.status();
    if (!*row || s.ColText(0) != "wal") {
      return absl::FailedPreconditionError(
          absl::StrCat("job store ", path_, ": cannot switch to WAL journal mode (file system "
                       "without shared memory support?)"));
    }
  }
  if (absl::Status st = Exec(path_, db_, "PRAGMA synchronous=FULL; PRAGMA foreign_keys=ON",
                             "set pragmas");
      !st.ok()) {
    return st;
  }
  // quick_check reads every page once (cheap at job-store sizes) so damage is reported at open,
  // naming the file, rather than in the middle of a lease.
  {
    Stmt s(path_, db_);
    if (absl::Status st = s.Prepare("PRAGMA quick_check", "integrity check"); !st.ok()) return st;
    absl::StatusOr<bool> row = s.Step("integrity check");
    if (!row.ok()) return row.status();
    if (*row && s.ColText(0) != "ok") {
      // The report lists every bad page; the first lines are enough to identify the damage.
      const std::string report = s.ColText(0);
      std::vector<absl::string_view> lines = absl::StrSplit(report, '\n');
      if (lines.size() > 3) lines.resize(3);
      return absl::DataLossError(absl::StrCat("job store ", path_, ": integrity check failed: ",
                                              absl::StrJoin(lines, "; "),
                                              " (restore the file from a backup or remove it)"));
    }
  }
  int64_t app_id = 0;
  int64_t tables = 0;
  {
    Stmt s(path_, db_);
    if (absl::Status st = s.Prepare("SELECT (SELECT application_id FROM pragma_application_id), "
                                    "(SELECT count(*) FROM sqlite_schema WHERE type='table')");
        !st.ok()) {
      return st;
    }
    absl::StatusOr<bool> row = s.Step("read header");
    if (!row.ok()) return row.status();
    app_id = s.ColInt(0);
    tables = s.ColInt(1);
  }
  if (tables == 0) {  // a new (empty) file: version 1, then the migrations below
    Transaction tx(path_, db_);
    if (absl::Status st = tx.Begin(); !st.ok()) return st;
    if (absl::Status st = Exec(path_, db_, kSchemaV1, "create schema"); !st.ok()) return st;
    if (absl::Status st = Exec(path_, db_,
                               absl::StrCat("PRAGMA application_id=", kApplicationId).c_str(),
                               "set application_id");
        !st.ok()) {
      return st;
    }
    if (absl::Status st = tx.Commit(); !st.ok()) return st;
    app_id = kApplicationId;
  }
  if (app_id != kApplicationId) {
    return absl::FailedPreconditionError(absl::StrCat(
        "job store ", path_, ": a SQLite database but not a carvemap job store (application_id ",
        app_id, ")"));
  }
  int64_t version = 0;
  {
    Stmt s(path_, db_);
    if (absl::Status st = s.Prepare("SELECT max(version) FROM schema_version"); !st.ok()) {
      return absl::DataLossError(
          absl::StrCat("job store ", path_, ": schema_version table missing: ", st.message()));
    }
    absl::StatusOr<bool> row = s.Step("read schema version");
    if (!row.ok()) return row.status();
    version = s.ColInt(0);
  }
  if (version > kSchemaVersion) {
    return absl::FailedPreconditionError(
        absl::StrCat("job store ", path_, ": schema version ", version,
                     " was written by a newer carvemap (this build reads up to ",
                     kSchemaVersion, ")"));
  }
  if (version < 1) {
    return absl::DataLossError(
        absl::StrCat("job store ", path_, ": invalid schema version ", version));
  }
  // Migrations from version v to v+1, each in its own transaction (a crash between two
  // leaves a file of the earlier version, migrated on the next open).
  if (version == 1) {
    Transaction tx(path_, db_);
    if (absl::Status st = tx.Begin(); !st.ok()) return st;
    if (absl::Status st = Exec(path_, db_, kMigrateV1ToV2, "migrate schema 1 -> 2");
        !st.ok()) {
      return st;
    }
    if (absl::Status st = tx.Commit(); !st.ok()) return st;
    version = 2;
  }
  return absl::OkStatus();
}

// ---- jobs

absl::Status JobStore::CreateJob(const JobRecord& job, int max_unfinished_of_tenant) {
  absl::MutexLock lock(&mu_);
  Transaction tx(path_, db_);
  if (absl::Status st = tx.Begin(); !st.ok()) return st;
  if (max_unfinished_of_tenant > 0) {
    Stmt count(path_, db_);
    if (absl::Status st = count.Prepare(
            "SELECT count(*) FROM jobs WHERE tenant=? AND state NOT IN (5, 6, 7)");
        !st.ok()) {
      return st;
    }
    count.Text(job.tenant);
    absl::StatusOr<bool> row = count.Step("count unfinished jobs");
    if (!row.ok()) return row.status();
    const int64_t unfinished = count.ColInt(0);
    if (unfinished >= max_unfinished_of_tenant) {
      return absl::ResourceExhaustedError(
          absl::StrCat("tenant ", job.tenant, " has ", unfinished,
                       " unfinished job(s), the limit is ", max_unfinished_of_tenant,
                       ": wait for one to finish or cancel one"));
    }
  }
  {
    Stmt s(path_, db_);
    if (absl::Status st = s.Prepare(absl::StrCat("INSERT INTO jobs (", kJobColumns,
                                                 ") VALUES (?,?,?,?,?,?,?,?,?,?,?,0,0,0,0,?)"));
        !st.ok()) {
      return st;
    }
    s.Text(job.id).Text(job.tenant).Int(static_cast<int>(job.state)).Text(job.input_path);
    s.Text(job.output_name).Text(job.params_json).Text(job.error).Text(job.idempotency_key);
    s.Int(job.created_unix_ms).Int(job.updated_unix_ms).Int(job.finished_unix_ms);
    s.Text(job.tenant_dir);
    if (absl::Status st = s.Run(absl::StrCat("insert job ", job.id)); !st.ok()) return st;
  }
  return tx.Commit();
}

absl::StatusOr<JobRecord> JobStore::GetJobLocked(absl::string_view job_id) {
  Stmt s(path_, db_);
  if (absl::Status st = s.Prepare(absl::StrCat("SELECT ", kJobColumns, " FROM jobs WHERE id=?"));
      !st.ok()) {
    return st;
  }
  s.Text(job_id);
  absl::StatusOr<bool> row = s.Step(absl::StrCat("read job ", job_id));
  if (!row.ok()) return row.status();
  if (!*row) return absl::NotFoundError(absl::StrCat("job ", job_id, " not found"));
  return ReadJob(s);
}

absl::StatusOr<JobRecord> JobStore::GetJob(absl::string_view job_id) {
  absl::MutexLock lock(&mu_);
  return GetJobLocked(job_id);
}

absl::StatusOr<std::optional<JobRecord>> JobStore::FindJobByIdempotencyKey(
    absl::string_view tenant, absl::string_view key) {
  absl::MutexLock lock(&mu_);
  if (key.empty()) return std::nullopt;
  Stmt s(path_, db_);
  if (absl::Status st = s.Prepare(absl::StrCat("SELECT ", kJobColumns,
                                               " FROM jobs WHERE tenant=? AND idempotency_key=?"));
      !st.ok()) {
    return st;
  }
  s.Text(tenant).Text(key);
  absl::StatusOr<bool> row = s.Step("find job by idempotency key");
  if (!row.ok()) return row.status();
  if (!*row) return std::nullopt;
  return ReadJob(s);
}

absl::StatusOr<std::vector<JobRecord>> JobStore::ListJobs(const ListJobsQuery& query) {
  if (query.limit < 1 || query.limit > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("list jobs: limit ", query.limit, " outside 1..1000"));
  }
  absl::MutexLock lock(&mu_);
  // Unused filters bind values that make their clause true, so there is one statement.
  Stmt s(path_, db_);
  if (absl::Status st = s.Prepare(absl::StrCat(
          "SELECT ", kJobColumns, " FROM jobs WHERE (? OR tenant=?) AND (? OR state=?) AND "
          "(? OR created_unix_ms < ? OR (created_unix_ms = ? AND id < ?)) "
          "ORDER BY created_unix_ms DESC, id DESC LIMIT ?"));
      !st.ok()) {
    return st;
  }
  s.Int(!query.tenant).Text(query.tenant.value_or(""));
  s.Int(!query.state).Int(static_cast<int>(query.state.value_or(JobState::kQueued)));
  s.Int(!query.before).Int(query.before ? query.before->first : 0);
  s.Int(query.before ? query.before->first : 0).Text(query.before ? query.before->second : "");
  s.Int(query.limit);
  std::vector<JobRecord> jobs;
  while (true) {
    absl::StatusOr<bool> row = s.Step("list jobs");
    if (!row.ok()) return row.status();
    if (!*row) break;
    jobs.push_back(ReadJob(s));
  }
  return jobs;
}

absl::Status JobStore::TransitionLocked(absl::string_view job_id, const JobTransition& t) {
  absl::StatusOr<JobRecord> job = GetJobLocked(job_id);
  if (!job.ok()) return job.status();
  if (!IsAllowedTransition(job->state, t.to)) {
    return absl::FailedPreconditionError(absl::StrCat("job ", job_id, ": cannot go from ",
                                                      JobStateName(job->state), " to ",
                                                      JobStateName(t.to)));
  }
  Stmt s(path_, db_);
  if (absl::Status st = s.Prepare("UPDATE jobs SET state=?, error=?, updated_unix_ms=?, "
                                  "finished_unix_ms=? WHERE id=?");
      !st.ok()) {
    return st;
  }
  s.Int(static_cast<int>(t.to)).Text(t.error).Int(t.now_unix_ms);
  s.Int(IsTerminal(t.to) ? t.now_unix_ms : 0).Text(job_id);
  return s.Run(absl::StrCat("update job ", job_id));
}

absl::Status JobStore::TransitionJob(absl::string_view job_id, const JobTransition& t) {
  absl::MutexLock lock(&mu_);
  // A transaction so the read-check-write cannot interleave with another connection's write.
  Transaction tx(path_, db_);
  if (absl::Status st = tx.Begin(); !st.ok()) return st;
  if (absl::Status st = TransitionLocked(job_id, t); !st.ok()) return st;
  return tx.Commit();
}

// ---- chunks

absl::Status JobStore::RecountLocked(absl::string_view job_id, int64_t now_unix_ms) {
  Stmt s(path_, db_);
  if (absl::Status st = s.Prepare(
          "UPDATE jobs SET "
          "chunks_total = (SELECT count(*) FROM chunks WHERE job_id=?1), "
          "chunks_done = (SELECT count(*) FROM chunks WHERE job_id=?1 AND state=3), "
          "chunks_leased = (SELECT count(*) FROM chunks WHERE job_id=?1 AND state=2), "
          "chunk_retries = (SELECT coalesce(sum(max(attempts - 1, 0)), 0) FROM chunks "
          "                 WHERE job_id=?1), "
          "updated_unix_ms = max(updated_unix_ms, ?2) "
          "WHERE id=?1");
      !st.ok()) {
    return st;
  }
  s.Text(job_id).Int(now_unix_ms);
  return s.Run(absl::StrCat("recount chunks of job ", job_id));
}

absl::Status JobStore::AddChunks(absl::string_view job_id, std::span<const ChunkRecord> chunks) {
  absl::MutexLock lock(&mu_);
  Transaction tx(path_, db_);
  if (absl::Status st = tx.Begin(); !st.ok()) return st;
  if (absl::StatusOr<JobRecord> job = GetJobLocked(job_id); !job.ok()) return job.status();
  Stmt one(path_, db_);
  if (absl::Status st = one.Prepare(absl::StrCat("INSERT INTO chunks (", kChunkColumns,
                                                 ") VALUES (?,?,?,?,1,'',0,'',0,0,'','',0,'',?)"));
      !st.ok()) {
    return st;
  }
  for (const ChunkRecord& c : chunks) {
    one.Reset();
    one.Text(job_id).Int(c.key.x).Int(c.key.y).Int(c.key.z).Int(c.wedge_count);
    if (absl::Status st = one.Run(absl::StrCat("insert chunk ", KeyText(c.key), " of job ", job_id));
        !st.ok()) {
      return st;
    }
  }
  if (absl::Status st = RecountLocked(job_id, 0); !st.ok()) return st;
  return tx.Commit();
}

absl::StatusOr<std::vector<ChunkRecord>> JobStore::ListChunks(absl::string_view job_id) {
  absl::MutexLock lock(&mu_);
  Stmt s(path_, db_);
  if (absl::Status st = s.Prepare(absl::StrCat("SELECT ", kChunkColumns,
                                               " FROM chunks WHERE job_id=? ORDER BY x, y, z"));
      !st.ok()) {
    return st;
  }
  s.Text(job_id);
  std::vector<ChunkRecord> chunks;
  while (true) {
    absl::StatusOr<bool> row = s.Step(absl::StrCat("list chunks of job ", job_id));
    if (!row.ok()) return row.status();
    if (!*row) break;
    chunks.push_back(ReadChunk(s));
  }
  return chunks;
}

absl::Status JobStore::UpdateChunks(std::span<const ChunkUpdate> updates, int64_t now_unix_ms,
                                    const std::optional<JobTransition>& job_transition) {
  absl::MutexLock lock(&mu_);
  Transaction tx(path_, db_);
  if (absl::Status st = tx.Begin(); !st.ok()) return st;
  // The job's counters move by each update's change, instead of being recounted over all the
  // job's chunks: a write then costs the same in a job of 100 chunks as in one of 100,000.
  struct CounterDelta {
    int64_t done = 0, leased = 0, retries = 0;
  };
  std::map<std::string, CounterDelta> deltas;
  const auto retries_of = [](int64_t attempts) { return std::max<int64_t>(attempts - 1, 0); };
  for (const ChunkUpdate& u : updates) {
    const ChunkRecord& c = u.chunk;
    const std::string what = absl::StrCat("update chunk ", KeyText(c.key), " of job ", c.job_id);
    Stmt old(path_, db_);
    if (absl::Status st = old.Prepare("SELECT state, attempts FROM chunks "
                                      "WHERE job_id=? AND x=? AND y=? AND z=? AND generation=?");
        !st.ok()) {
      return st;
    }
    old.Text(c.job_id).Int(c.key.x).Int(c.key.y).Int(c.key.z).Int(u.expected_generation);
    absl::StatusOr<bool> found = old.Step(what);
    if (!found.ok()) return found.status();
    if (*found) {
      const int64_t old_state = old.ColInt(0), old_attempts = old.ColInt(1);
      Stmt s(path_, db_);
      if (absl::Status st = s.Prepare(
              "UPDATE chunks SET state=?, lease_id=?, generation=?, worker_id=?, "
              "deadline_unix_ms=?, attempts=?, last_error=?, tile_path=?, tile_size_bytes=?, "
              "tile_sha256_hex=?, wedge_count=? "
              "WHERE job_id=? AND x=? AND y=? AND z=? AND generation=?");
          !st.ok()) {
        return st;
      }
      s.Int(static_cast<int>(c.state)).Text(c.lease_id).Int(c.generation).Text(c.worker_id);
      s.Int(c.deadline_unix_ms).Int(c.attempts).Text(c.last_error).Text(c.tile_path);
      s.Int(c.tile_size_bytes).Text(c.tile_sha256_hex).Int(c.wedge_count);
      s.Text(c.job_id).Int(c.key.x).Int(c.key.y).Int(c.key.z).Int(u.expected_generation);
      if (absl::Status st = s.Run(what); !st.ok()) return st;
      const int64_t new_state = static_cast<int64_t>(c.state);
      const int64_t done = static_cast<int64_t>(ChunkState::kDone);
      const int64_t leased = static_cast<int64_t>(ChunkState::kLeased);
      CounterDelta& d = deltas[c.job_id];
      d.done += int64_t(new_state == done) - int64_t(old_state == done);
      d.leased += int64_t(new_state == leased) - int64_t(old_state == leased);
      d.retries += retries_of(c.attempts) - retries_of(old_attempts);
      continue;
    }
    // Nothing matched: tell "no such chunk" from "someone else changed it".
    Stmt q(path_, db_);
    if (absl::Status st = q.Prepare(
            "SELECT generation FROM chunks WHERE job_id=? AND x=? AND y=? AND z=?");
        !st.ok()) {
      return st;
    }
    q.Text(c.job_id).Int(c.key.x).Int(c.key.y).Int(c.key.z);
    absl::StatusOr<bool> row = q.Step(what);
    if (!row.ok()) return row.status();
    if (!*row) return absl::NotFoundError(absl::StrCat(what, ": no such chunk"));
    return absl::FailedPreconditionError(absl::StrCat(what, ": generation is ", q.ColInt(0),
                                                      ", expected ", u.expected_generation));
  }
  if (job_transition) {
    if (updates.empty()) {
      return absl::InvalidArgumentError("update chunks: a job transition needs a chunk update");
    }
    for (const ChunkUpdate& u : updates) {
      if (u.chunk.job_id != updates.front().chunk.job_id) {
        return absl::InvalidArgumentError(
            "update chunks: a job transition needs all updates in one job");
      }
    }
    if (absl::Status st = TransitionLocked(updates.front().chunk.job_id, *job_transition);
        !st.ok()) {
      return st;
    }
  }
  for (const auto& [job_id, d] : deltas) {
    Stmt s(path_, db_);
    if (absl::Status st = s.Prepare(
            "UPDATE jobs SET chunks_done = chunks_done + ?, chunks_leased = chunks_leased + ?, "
            "chunk_retries = chunk_retries + ?, updated_unix_ms = max(updated_unix_ms, ?) "
            "WHERE id=?");
        !st.ok()) {
      return st;
    }
    s.Int(d.done).Int(d.leased).Int(d.retries).Int(now_unix_ms).Text(job_id);
    if (absl::Status st = s.Run(absl::StrCat("count chunks of job ", job_id)); !st.ok()) return st;
  }
  return tx.Commit();
}

}  // namespace carvemap
