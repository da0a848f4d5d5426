#include "storage/job_store.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

using ::testing::HasSubstr;

// A fresh directory per test under the test's temp dir.
std::string TempPath(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  // TempDir() is private to this test process (tests/test_main.cc) and removed at exit.
  std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                              absl::StrCat(info->test_suite_name(), ".", info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

JobRecord MakeJob(const std::string& id, int64_t created_ms, const std::string& tenant = "t1") {
  JobRecord j;
  j.id = id;
  j.tenant = tenant;
  j.input_path = "scans/office2/scan.h5";
  j.output_name = absl::StrCat("out-", id);
  j.params_json = R"({"resolution_m":0.0625,"method":"PROBABILISTIC"})";
  j.created_unix_ms = created_ms;
  j.updated_unix_ms = created_ms;
  return j;
}

std::vector<ChunkRecord> MakeChunks(int n) {
  std::vector<ChunkRecord> chunks;
  for (int i = 0; i < n; ++i) {
    ChunkRecord c;
    c.key = {i % 3, i / 3, -1};
    c.wedge_count = 100 + i;
    chunks.push_back(c);
  }
  return chunks;
}

TEST(JobStoreTest, CreateCloseReopenKeepsEverything) {
  const std::string path = TempPath("jobs.db");
  {
    auto store = JobStore::Open(path);
    ASSERT_TRUE(store.ok()) << store.status();
    ASSERT_TRUE((*store)->CreateJob(MakeJob("j-1", 1000)).ok());
    ASSERT_TRUE((*store)->AddChunks("j-1", MakeChunks(4)).ok());
    auto chunks = (*store)->ListChunks("j-1");
    ASSERT_TRUE(chunks.ok());
    ChunkRecord done = (*chunks)[1];
    done.state = ChunkState::kDone;
    done.generation = 1;
    done.attempts = 1;
    done.tile_path = "j-1/tiles/c_1_0_-1.h5";
    done.tile_size_bytes = 4096;
    done.tile_sha256_hex = std::string(64, 'a');
    ASSERT_TRUE((*store)->UpdateChunks({{ChunkUpdate{done, 0}}}, 2000).ok());
  }  // closed: no explicit flush needed, commits are durable
  auto store = JobStore::Open(path, {.create_if_missing = false});
  ASSERT_TRUE(store.ok()) << store.status();
  auto job = (*store)->GetJob("j-1");
  ASSERT_TRUE(job.ok()) << job.status();
  EXPECT_EQ(job->state, JobState::kQueued);
  EXPECT_EQ(job->input_path, "scans/office2/scan.h5");
  EXPECT_EQ(job->params_json, R"({"resolution_m":0.0625,"method":"PROBABILISTIC"})");
  EXPECT_EQ(job->counters.chunks_total, 4);
  EXPECT_EQ(job->counters.chunks_done, 1);
  EXPECT_EQ(job->updated_unix_ms, 2000);
  auto chunks = (*store)->ListChunks("j-1");
  ASSERT_TRUE(chunks.ok());
  ASSERT_EQ(chunks->size(), 4u);
  // Ordered by key x, then y, then z.
  EXPECT_EQ((*chunks)[0].key, (ChunkCoord{0, 0, -1}));
  EXPECT_EQ((*chunks)[1].key, (ChunkCoord{0, 1, -1}));
  EXPECT_EQ((*chunks)[2].key, (ChunkCoord{1, 0, -1}));
  const ChunkRecord* done = nullptr;
  for (const ChunkRecord& c : *chunks) {
    if (c.state == ChunkState::kDone) done = &c;
  }
  ASSERT_NE(done, nullptr);
  EXPECT_EQ(done->tile_path, "j-1/tiles/c_1_0_-1.h5");
  EXPECT_EQ(done->tile_size_bytes, 4096);
  EXPECT_EQ(done->wedge_count, 103);  // chunk (0,1,-1) was made 4th
}

TEST(JobStoreTest, OpenWithoutCreateOnMissingFileFails) {
  auto store = JobStore::Open(TempPath("missing.db"), {.create_if_missing = false});
  ASSERT_FALSE(store.ok());
  EXPECT_THAT(store.status().message(), HasSubstr("missing.db"));
}

TEST(JobStoreTest, JobStateTransitions) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  JobStore& s = **store;
  ASSERT_TRUE(s.CreateJob(MakeJob("j-1", 1000)).ok());
  EXPECT_TRUE(s.TransitionJob("j-1", {JobState::kIngesting, "", 1100}).ok());
  EXPECT_TRUE(s.TransitionJob("j-1", {JobState::kCarving, "", 1200}).ok());
  // Backwards and self-transitions are refused.
  EXPECT_EQ(s.TransitionJob("j-1", {JobState::kIngesting, "", 1300}).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(s.TransitionJob("j-1", {JobState::kCarving, "", 1300}).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(s.TransitionJob("j-1", {JobState::kFailed, "chunk (1,2,3): boom", 1400}).ok());
  auto job = s.GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kFailed);
  EXPECT_EQ(job->error, "chunk (1,2,3): boom");
  EXPECT_EQ(job->finished_unix_ms, 1400);
  // Terminal is final.
  absl::Status again = s.TransitionJob("j-1", {JobState::kCancelled, "", 1500});
  EXPECT_EQ(again.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(again.message(), HasSubstr("FAILED to CANCELLED"));
  EXPECT_EQ(s.TransitionJob("nope", {JobState::kCarving, "", 1}).code(),
            absl::StatusCode::kNotFound);
}

TEST(JobStoreTest, AllowedTransitionTable) {
  EXPECT_TRUE(IsAllowedTransition(JobState::kQueued, JobState::kIngesting));
  EXPECT_TRUE(IsAllowedTransition(JobState::kQueued, JobState::kMerging));  // empty scan
  EXPECT_TRUE(IsAllowedTransition(JobState::kMerging, JobState::kSucceeded));
  EXPECT_TRUE(IsAllowedTransition(JobState::kCarving, JobState::kCancelled));
  EXPECT_FALSE(IsAllowedTransition(JobState::kMerging, JobState::kCarving));
  EXPECT_FALSE(IsAllowedTransition(JobState::kSucceeded, JobState::kFailed));
  EXPECT_FALSE(IsAllowedTransition(JobState::kCancelled, JobState::kCancelled));
}

TEST(JobStoreTest, UniquenessOfIdOutputAndIdempotencyKey) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  JobStore& s = **store;
  JobRecord a = MakeJob("j-1", 1000);
  a.idempotency_key = "key-1";
  ASSERT_TRUE(s.CreateJob(a).ok());
  EXPECT_EQ(s.CreateJob(a).code(), absl::StatusCode::kAlreadyExists);  // same id
  JobRecord b = MakeJob("j-2", 1001);
  b.idempotency_key = "key-1";
  EXPECT_EQ(s.CreateJob(b).code(), absl::StatusCode::kAlreadyExists);  // same key, tenant
  b.tenant = "t2";
  EXPECT_TRUE(s.CreateJob(b).ok());  // keys are per tenant
  JobRecord c = MakeJob("j-3", 1002);
  c.output_name = a.output_name;
  EXPECT_EQ(s.CreateJob(c).code(), absl::StatusCode::kAlreadyExists);  // same output name
  auto found = s.FindJobByIdempotencyKey("t1", "key-1");
  ASSERT_TRUE(found.ok());
  ASSERT_TRUE(found->has_value());
  EXPECT_EQ((*found)->id, "j-1");
  auto none = s.FindJobByIdempotencyKey("t1", "key-2");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
}

TEST(JobStoreTest, ListJobsPagesNewestFirstPerTenant) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  JobStore& s = **store;
  for (int i = 0; i < 7; ++i) {
    ASSERT_TRUE(s.CreateJob(MakeJob(absl::StrCat("j-", i), 1000 + i / 2)).ok());
  }
  ASSERT_TRUE(s.CreateJob(MakeJob("other", 5000, "t2")).ok());
  ASSERT_TRUE(s.TransitionJob("j-3", {JobState::kCancelled, "by test", 6000}).ok());
  std::vector<std::string> seen;
  ListJobsQuery q;
  q.tenant = "t1";
  q.limit = 3;
  while (true) {
    auto page = s.ListJobs(q);
    ASSERT_TRUE(page.ok()) << page.status();
    for (const JobRecord& j : *page) seen.push_back(j.id);
    if (page->size() < 3) break;
    q.before = {page->back().created_unix_ms, page->back().id};
  }
  EXPECT_EQ(seen, (std::vector<std::string>{"j-6", "j-5", "j-4", "j-3", "j-2", "j-1", "j-0"}));
  ListJobsQuery only_cancelled;
  only_cancelled.state = JobState::kCancelled;
  auto cancelled = s.ListJobs(only_cancelled);
  ASSERT_TRUE(cancelled.ok());
  ASSERT_EQ(cancelled->size(), 1u);
  EXPECT_EQ((*cancelled)[0].id, "j-3");
  ListJobsQuery empty;
  empty.limit = 0;
  EXPECT_EQ(s.ListJobs(empty).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(JobStoreTest, ChunkUpdatesAreCompareAndSetAndAtomic) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  JobStore& s = **store;
  ASSERT_TRUE(s.CreateJob(MakeJob("j-1", 1000)).ok());
  ASSERT_TRUE(s.AddChunks("j-1", MakeChunks(3)).ok());
  EXPECT_EQ(s.AddChunks("j-1", MakeChunks(1)).code(), absl::StatusCode::kAlreadyExists);
  EXPECT_EQ(s.AddChunks("nope", MakeChunks(1)).code(), absl::StatusCode::kNotFound);
  auto chunks = s.ListChunks("j-1");
  ASSERT_TRUE(chunks.ok());
  ChunkRecord a = (*chunks)[0];
  ChunkRecord b = (*chunks)[1];
  a.state = b.state = ChunkState::kLeased;
  a.generation = b.generation = 1;
  a.attempts = b.attempts = 1;
  // b's expected generation is wrong: nothing is written, not even a.
  std::vector<ChunkUpdate> bad = {{a, 0}, {b, 5}};
  absl::Status st = s.UpdateChunks(bad, 1100);
  EXPECT_EQ(st.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(st.message(), HasSubstr("generation is 0, expected 5"));
  auto after = s.ListChunks("j-1");
  ASSERT_TRUE(after.ok());
  EXPECT_EQ((*after)[0].state, ChunkState::kQueued);
  std::vector<ChunkUpdate> good = {{a, 0}, {b, 0}};
  ASSERT_TRUE(s.UpdateChunks(good, 1100).ok());
  auto job = s.GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->counters.chunks_leased, 2);
  // Requeue a with a second attempt and fail the job in the same transaction.
  a.state = ChunkState::kQueued;
  a.attempts = 2;
  a.generation = 2;
  std::vector<ChunkUpdate> fail = {{a, 1}};
  ASSERT_TRUE(s.TransitionJob("j-1", {JobState::kCarving, "", 1150}).ok());
  ASSERT_TRUE(s.UpdateChunks(fail, 1200, JobTransition{JobState::kFailed, "too many", 1200}).ok());
  job = s.GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kFailed);
  EXPECT_EQ(job->counters.chunks_leased, 1);
  EXPECT_EQ(job->counters.chunk_retries, 1);
  // A disallowed transition rolls back the chunk writes too.
  a.attempts = 3;
  std::vector<ChunkUpdate> late = {{a, 2}};
  EXPECT_EQ(s.UpdateChunks(late, 1300, JobTransition{JobState::kCancelled, "", 1300}).code(),
            absl::StatusCode::kFailedPrecondition);
  after = s.ListChunks("j-1");
  ASSERT_TRUE(after.ok());
  EXPECT_EQ((*after)[0].attempts, 2);
  // Unknown chunk.
  ChunkRecord ghost = a;
  ghost.key = {99, 99, 99};
  std::vector<ChunkUpdate> ghost_update = {{ghost, 0}};
  EXPECT_EQ(s.UpdateChunks(ghost_update, 1400).code(), absl::StatusCode::kNotFound);
}

// The job's counters follow its chunks through any sequence of updates, several to one chunk
// in one call included (they move by each update's change; AddChunks counts afresh).
TEST(JobStoreTest, CountersFollowTheChunksThroughRandomUpdates) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  JobStore& s = **store;
  ASSERT_TRUE(s.CreateJob(MakeJob("j-1", 1000)).ok());
  ASSERT_TRUE(s.AddChunks("j-1", MakeChunks(12)).ok());
  std::mt19937 rng(7);
  for (int round = 0; round < 60; ++round) {
    auto chunks = s.ListChunks("j-1");
    ASSERT_TRUE(chunks.ok());
    std::vector<ChunkUpdate> updates;
    const int n = 1 + int(rng() % 3);
    for (int k = 0; k < n; ++k) {
      ChunkRecord& c = (*chunks)[rng() % chunks->size()];
      const int64_t expected = c.generation;
      c.state = static_cast<ChunkState>(1 + rng() % 3);  // queued, leased, done
      c.attempts = int(rng() % 4);
      c.generation = expected + 1;
      updates.push_back({c, expected});  // the same chunk again: from the generation just set
    }
    ASSERT_TRUE(s.UpdateChunks(updates, 2000 + round).ok()) << round;
    auto after = s.ListChunks("j-1");
    auto job = s.GetJob("j-1");
    ASSERT_TRUE(after.ok() && job.ok());
    int64_t done = 0, leased = 0, retries = 0;
    for (const ChunkRecord& c : *after) {
      done += c.state == ChunkState::kDone;
      leased += c.state == ChunkState::kLeased;
      retries += std::max(c.attempts - 1, 0);
    }
    EXPECT_EQ(job->counters.chunks_total, 12) << round;
    EXPECT_EQ(job->counters.chunks_done, done) << round;
    EXPECT_EQ(job->counters.chunks_leased, leased) << round;
    EXPECT_EQ(job->counters.chunk_retries, retries) << round;
    EXPECT_EQ(job->updated_unix_ms, 2000 + round);
  }
}

// Two threads on one store: every write lands, none interleaves inside a transaction.
TEST(JobStoreTest, TwoThreadsOneStore) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  JobStore& s = **store;
  constexpr int kJobs = 40;
  auto work = [&s](int thread) {
    for (int i = 0; i < kJobs; ++i) {
      const std::string id = absl::StrCat("t", thread, "-", i);
      EXPECT_TRUE(s.CreateJob(MakeJob(id, i)).ok());
      EXPECT_TRUE(s.AddChunks(id, MakeChunks(5)).ok());
      auto chunks = s.ListChunks(id);
      ASSERT_TRUE(chunks.ok());
      std::vector<ChunkUpdate> updates;
      for (ChunkRecord c : *chunks) {
        c.state = ChunkState::kDone;
        c.generation = 1;
        updates.push_back({c, 0});
      }
      EXPECT_TRUE(s.UpdateChunks(updates, 10).ok());
    }
  };
  std::thread a(work, 0);
  std::thread b(work, 1);
  a.join();
  b.join();
  ListJobsQuery everything;
  everything.limit = 1000;
  auto all = s.ListJobs(everything);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 2u * kJobs);
  for (const JobRecord& j : *all) EXPECT_EQ(j.counters.chunks_done, 5) << j.id;
}

// Two connections (as two processes would have) on one file: BEGIN IMMEDIATE plus the busy
// timeout serialize the writers instead of failing with SQLITE_BUSY.
TEST(JobStoreTest, TwoConnectionsOneFile) {
  const std::string path = TempPath("jobs.db");
  auto s1 = JobStore::Open(path);
  auto s2 = JobStore::Open(path);
  ASSERT_TRUE(s1.ok() && s2.ok());
  auto work = [](JobStore& s, int thread) {
    for (int i = 0; i < 25; ++i) {
      const std::string id = absl::StrCat("c", thread, "-", i);
      EXPECT_TRUE(s.CreateJob(MakeJob(id, i)).ok());
      EXPECT_TRUE(s.TransitionJob(id, {JobState::kIngesting, "", 1}).ok());
    }
  };
  std::thread a(work, std::ref(**s1), 0);
  std::thread b(work, std::ref(**s2), 1);
  a.join();
  b.join();
  ListJobsQuery ingesting;
  ingesting.state = JobState::kIngesting;
  ingesting.limit = 1000;
  auto all = (*s1)->ListJobs(ingesting);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 50u);
}

TEST(JobStoreTest, GarbageFileIsDataLossNamingTheFile) {
  const std::string path = TempPath("corrupt.db");
  {
    std::ofstream out(path, std::ios::binary);
    for (int i = 0; i < 512; ++i) out << "this is not a sqlite database ";
  }
  auto store = JobStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), absl::StatusCode::kDataLoss) << store.status();
  EXPECT_THAT(store.status().message(), HasSubstr(path));
}

TEST(JobStoreTest, DamagedPagesAreDataLossNamingTheFile) {
  const std::string path = TempPath("damaged.db");
  {
    auto store = JobStore::Open(path);
    ASSERT_TRUE(store.ok());
    for (int i = 0; i < 50; ++i) {
      ASSERT_TRUE((*store)->CreateJob(MakeJob(absl::StrCat("j-", i), i)).ok());
      ASSERT_TRUE((*store)->AddChunks(absl::StrCat("j-", i), MakeChunks(20)).ok());
    }
  }
  // Closing the last connection checkpoints the WAL into the main file; scribble over
  // everything after the 100-byte header's first page.
  const auto size = std::filesystem::file_size(path);
  ASSERT_GT(size, 8192u);
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(4096);
    std::string junk(static_cast<size_t>(size) - 4096, '\xA5');
    f.write(junk.data(), static_cast<std::streamsize>(junk.size()));
  }
  auto store = JobStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), absl::StatusCode::kDataLoss) << store.status();
  EXPECT_THAT(store.status().message(), HasSubstr(path));
}

TEST(JobStoreTest, ForeignSqliteDatabaseIsRefused) {
  const std::string path = TempPath("other.db");
  {
    // A valid job store file whose application id we then clear, standing in for any other
    // application's database.
    auto store = JobStore::Open(path);
    ASSERT_TRUE(store.ok());
  }
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(68);  // application_id lives at byte 68 of the header
    const char zero[4] = {0, 0, 0, 0};
    f.write(zero, 4);
  }
  auto store = JobStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(store.status().message(), HasSubstr("not a carvemap job store"));
}

// A version-1 file, as carvemap wrote it before tenants (docs/JOB_STORE.md): its jobs belong
// to the default tenant after the migration and keep their files at the roots.
TEST(JobStoreTest, MigratesVersion1ToTenants) {
  const std::string path = TempPath("v1.db");
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    const char* v1 = R"sql(
      PRAGMA application_id = 1129728595;
      CREATE TABLE schema_version (version INTEGER NOT NULL);
      CREATE TABLE jobs (
        id TEXT PRIMARY KEY NOT NULL, tenant TEXT NOT NULL,
        state INTEGER NOT NULL CHECK (state BETWEEN 1 AND 7), input_path TEXT NOT NULL,
        output_name TEXT NOT NULL, params_json TEXT NOT NULL, error TEXT NOT NULL DEFAULT '',
        idempotency_key TEXT NOT NULL DEFAULT '', created_unix_ms INTEGER NOT NULL,
        updated_unix_ms INTEGER NOT NULL, finished_unix_ms INTEGER NOT NULL DEFAULT 0,
        chunks_total INTEGER NOT NULL DEFAULT 0, chunks_done INTEGER NOT NULL DEFAULT 0,
        chunks_leased INTEGER NOT NULL DEFAULT 0, chunk_retries INTEGER NOT NULL DEFAULT 0);
      CREATE UNIQUE INDEX jobs_by_output ON jobs (tenant, output_name);
      CREATE UNIQUE INDEX jobs_by_idempotency_key ON jobs (tenant, idempotency_key)
        WHERE idempotency_key <> '';
      CREATE INDEX jobs_by_created ON jobs (created_unix_ms DESC, id DESC);
      CREATE TABLE chunks (
        job_id TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE, x INTEGER NOT NULL,
        y INTEGER NOT NULL, z INTEGER NOT NULL,
        state INTEGER NOT NULL CHECK (state BETWEEN 1 AND 3), lease_id TEXT NOT NULL DEFAULT '',
        generation INTEGER NOT NULL DEFAULT 0, worker_id TEXT NOT NULL DEFAULT '',
        deadline_unix_ms INTEGER NOT NULL DEFAULT 0, attempts INTEGER NOT NULL DEFAULT 0,
        last_error TEXT NOT NULL DEFAULT '', tile_path TEXT NOT NULL DEFAULT '',
        tile_size_bytes INTEGER NOT NULL DEFAULT 0, tile_sha256_hex TEXT NOT NULL DEFAULT '',
        wedge_count INTEGER NOT NULL DEFAULT 0, PRIMARY KEY (job_id, x, y, z)) WITHOUT ROWID;
      CREATE INDEX chunks_by_state ON chunks (job_id, state);
      INSERT INTO schema_version (version) VALUES (1);
      INSERT INTO jobs (id, tenant, state, input_path, output_name, params_json,
                        idempotency_key, created_unix_ms, updated_unix_ms)
        VALUES ('j-old', '', 3, 'scans/a.h5', 'a', '{}', 'key-1', 100, 100);
      INSERT INTO chunks (job_id, x, y, z, state) VALUES ('j-old', 0, 0, 0, 1);
    )sql";
    char* err = nullptr;
    ASSERT_EQ(sqlite3_exec(db, v1, nullptr, nullptr, &err), SQLITE_OK) << (err ? err : "");
    sqlite3_close(db);
  }
  {
    auto store = JobStore::Open(path);
    ASSERT_TRUE(store.ok()) << store.status();
    auto old = (*store)->GetJob("j-old");
    ASSERT_TRUE(old.ok()) << old.status();
    EXPECT_EQ(old->tenant, "default");
    EXPECT_EQ(old->tenant_dir, "");
    EXPECT_EQ(old->state, JobState::kCarving);
    EXPECT_EQ(old->counters.chunks_total, 0);  // counters are as they were stored
    auto chunks = (*store)->ListChunks("j-old");
    ASSERT_TRUE(chunks.ok());
    EXPECT_EQ(chunks->size(), 1u);
    // The idempotency key is now the default tenant's.
    auto found = (*store)->FindJobByIdempotencyKey("default", "key-1");
    ASSERT_TRUE(found.ok());
    ASSERT_TRUE(found->has_value());
    EXPECT_EQ((*found)->id, "j-old");
    // New jobs carry their folder.
    JobRecord fresh = MakeJob("j-new", 200, "acme");
    fresh.tenant_dir = "acme";
    ASSERT_TRUE((*store)->CreateJob(fresh).ok());
  }
  // Reopened: version 2 now, nothing migrated twice.
  auto store = JobStore::Open(path);
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->GetJob("j-new")->tenant_dir, "acme");
  EXPECT_EQ((*store)->GetJob("j-old")->tenant, "default");
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT max(version), count(*) FROM schema_version", -1, &st,
                               nullptr),
            SQLITE_OK);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_EQ(sqlite3_column_int(st, 0), 2);
  EXPECT_EQ(sqlite3_column_int(st, 1), 1);
  sqlite3_finalize(st);
  sqlite3_close(db);
}

TEST(JobStoreTest, UnfinishedJobsPerTenantAreLimited) {
  auto store = JobStore::Open(TempPath("jobs.db"));
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE((*store)->CreateJob(MakeJob("a-1", 1, "acme"), 2).ok());
  ASSERT_TRUE((*store)->CreateJob(MakeJob("a-2", 2, "acme"), 2).ok());
  absl::Status third = (*store)->CreateJob(MakeJob("a-3", 3, "acme"), 2);
  EXPECT_EQ(third.code(), absl::StatusCode::kResourceExhausted) << third;
  EXPECT_THAT(third.message(), HasSubstr("limit is 2"));
  EXPECT_EQ((*store)->GetJob("a-3").status().code(), absl::StatusCode::kNotFound);
  // Another tenant is not affected; no limit: no count.
  EXPECT_TRUE((*store)->CreateJob(MakeJob("b-1", 4, "beta"), 2).ok());
  EXPECT_TRUE((*store)->CreateJob(MakeJob("a-4", 5, "acme")).ok());
  // A finished job no longer counts.
  ASSERT_TRUE((*store)->TransitionJob("a-1", {JobState::kCancelled, "x", 6}).ok());
  ASSERT_TRUE((*store)->TransitionJob("a-2", {JobState::kFailed, "x", 6}).ok());
  EXPECT_TRUE((*store)->CreateJob(MakeJob("a-5", 7, "acme"), 2).ok());
}

}  // namespace
}  // namespace carvemap
