#include "coordinator/lease_table.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <memory>
#include <random>
#include <set>

#include "absl/strings/str_cat.h"
#include "coordinator/fake_clock.h"

namespace carvemap {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;

constexpr int64_t kTimeoutMs = 30'000;

class LeaseTableTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    // TempDir() is private to this test process (tests/test_main.cc) and removed at exit.
    std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / info->name();
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    path_ = (dir / "jobs.db").string();
    OpenStore();
  }

  void OpenStore() {
    auto store = JobStore::Open(path_);
    ASSERT_TRUE(store.ok()) << store.status();
    store_ = std::move(*store);
    table_ = std::make_unique<LeaseTable>(*store_, clock_, options_);
  }

  // Simulates a coordinator crash/restart: everything in memory is gone.
  void Restart() {
    table_.reset();
    store_.reset();
    OpenStore();
  }

  // A CARVING job with chunks (0,0,0), (0,0,1), ..., loaded into the table.
  void AddJob(const std::string& id, int chunks) {
    JobRecord job;
    job.id = id;
    job.output_name = id;
    job.params_json = "{}";
    job.created_unix_ms = clock_.now_ms;
    ASSERT_TRUE(store_->CreateJob(job).ok());
    std::vector<ChunkRecord> records(chunks);
    // Inserted in reverse to show that the lease order is by key, not insertion.
    for (int i = 0; i < chunks; ++i) records[i].key = {0, 0, chunks - 1 - i};
    ASSERT_TRUE(store_->AddChunks(id, records).ok());
    ASSERT_TRUE(store_->TransitionJob(id, {JobState::kCarving, "", clock_.now_ms}).ok());
    ASSERT_TRUE(table_->LoadJob(id).ok());
  }

  LeaseTable::Grant MustLease(const std::string& worker) {
    auto grant = table_->Lease(worker);
    EXPECT_TRUE(grant.ok()) << grant.status();
    EXPECT_TRUE(grant.ok() && grant->has_value()) << "nothing to lease";
    return grant.ok() && grant->has_value() ? **grant : LeaseTable::Grant{};
  }

  static LeaseTable::Tile TileFor(const LeaseTable::Grant& g) {
    return {absl::StrCat(g.job_id, "/tiles/", g.chunk.x, "_", g.chunk.y, "_", g.chunk.z, ".h5"),
            1234, std::string(64, 'f')};
  }

  ChunkRecord StoredChunk(const std::string& job_id, ChunkCoord key) {
    auto chunks = store_->ListChunks(job_id);
    EXPECT_TRUE(chunks.ok());
    for (const ChunkRecord& c : *chunks) {
      if (c.key == key) return c;
    }
    ADD_FAILURE() << "no chunk";
    return {};
  }

  std::string path_;
  FakeClock clock_;
  LeaseTableOptions options_{.lease_timeout_ms = kTimeoutMs, .max_attempts = 3};
  std::unique_ptr<JobStore> store_;
  std::unique_ptr<LeaseTable> table_;
};

TEST_F(LeaseTableTest, LeasesInKeyOrderAndCompletes) {
  AddJob("j-1", 3);
  LeaseTable::Grant a = MustLease("w-1");
  LeaseTable::Grant b = MustLease("w-2");
  LeaseTable::Grant c = MustLease("w-1");
  EXPECT_EQ(a.chunk, (ChunkCoord{0, 0, 0}));
  EXPECT_EQ(b.chunk, (ChunkCoord{0, 0, 1}));
  EXPECT_EQ(c.chunk, (ChunkCoord{0, 0, 2}));
  EXPECT_EQ(a.generation, 1);
  EXPECT_EQ(a.attempt, 1);
  EXPECT_EQ(a.lease_id, "j-1/0,0,0/1");
  EXPECT_EQ(a.deadline_unix_ms, clock_.now_ms + kTimeoutMs);
  auto none = table_->Lease("w-3");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  EXPECT_THAT(table_->LeasesOf("w-1"), ElementsAre("j-1/0,0,0/1", "j-1/0,0,2/1"));

  for (const auto& g : {a, b, c}) {
    ASSERT_TRUE(table_->Complete(g.lease_id, g.generation, TileFor(g)).ok());
  }
  EXPECT_TRUE(table_->AllDone("j-1"));
  auto progress = table_->GetProgress("j-1");
  ASSERT_TRUE(progress.ok());
  EXPECT_EQ(progress->chunks_done, 3);
  EXPECT_EQ(progress->chunks_leased, 0);
  EXPECT_TRUE(table_->LeasesOf("w-1").empty());
  // The store has the same picture, counters included.
  auto job = store_->GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->counters.chunks_done, 3);
  ChunkRecord stored = StoredChunk("j-1", {0, 0, 1});
  EXPECT_EQ(stored.state, ChunkState::kDone);
  EXPECT_EQ(stored.tile_path, "j-1/tiles/0_0_1.h5");
  EXPECT_EQ(stored.worker_id, "w-2");
}

TEST_F(LeaseTableTest, SecondCompletionIsRejected) {
  AddJob("j-1", 1);
  LeaseTable::Grant g = MustLease("w-1");
  ASSERT_TRUE(table_->Complete(g.lease_id, g.generation, TileFor(g)).ok());
  absl::Status again = table_->Complete(g.lease_id, g.generation, TileFor(g));
  EXPECT_EQ(again.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(again.message(), HasSubstr("already committed"));
  EXPECT_EQ(table_->Complete(g.lease_id, 7, TileFor(g)).code(),
            absl::StatusCode::kInvalidArgument);  // generation does not match the id
  EXPECT_EQ(table_->Complete("garbage", 1, TileFor(g)).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(table_->Complete("j-9/0,0,0/1", 1, TileFor(g)).code(), absl::StatusCode::kNotFound);
}

TEST_F(LeaseTableTest, ExpiryRequeuesWithNewGeneration) {
  AddJob("j-1", 2);
  LeaseTable::Grant first = MustLease("w-1");
  clock_.AdvanceMs(kTimeoutMs - 1);
  auto expired = table_->ExpireLeases();
  ASSERT_TRUE(expired.ok());
  EXPECT_EQ(*expired, 0);  // not yet
  clock_.AdvanceMs(2);
  expired = table_->ExpireLeases();
  ASSERT_TRUE(expired.ok());
  EXPECT_EQ(*expired, 1);
  EXPECT_TRUE(table_->LeasesOf("w-1").empty());
  EXPECT_THAT(StoredChunk("j-1", first.chunk).last_error, HasSubstr("expired"));

  LeaseTable::Grant second = MustLease("w-2");
  EXPECT_EQ(second.chunk, first.chunk);  // requeued chunk comes first again (key order)
  EXPECT_EQ(second.generation, 2);
  EXPECT_EQ(second.attempt, 2);
  // The first holder is late and the chunk was leased again: stale.
  absl::Status stale = table_->Complete(first.lease_id, first.generation, TileFor(first));
  EXPECT_EQ(stale.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(stale.message(), HasSubstr("stale"));
  EXPECT_TRUE(table_->Complete(second.lease_id, second.generation, TileFor(second)).ok());
  auto progress = table_->GetProgress("j-1");
  ASSERT_TRUE(progress.ok());
  EXPECT_EQ(progress->chunk_retries, 1);
}

TEST_F(LeaseTableTest, ExpiredButNotReassignedCompletionIsAccepted) {
  AddJob("j-1", 2);
  LeaseTable::Grant a = MustLease("w-1");
  LeaseTable::Grant b = MustLease("w-1");
  clock_.AdvanceMs(kTimeoutMs + 1);
  // Past its deadline, before any sweep: accepted.
  EXPECT_TRUE(table_->Complete(a.lease_id, a.generation, TileFor(a)).ok());
  // After the sweep requeued it, but before anyone leased it again: still accepted.
  auto expired = table_->ExpireLeases();
  ASSERT_TRUE(expired.ok());
  EXPECT_EQ(*expired, 1);
  EXPECT_TRUE(table_->Complete(b.lease_id, b.generation, TileFor(b)).ok());
  EXPECT_TRUE(table_->AllDone("j-1"));
  auto none = table_->Lease("w-2");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());  // and b is no longer queued
}

TEST_F(LeaseTableTest, RequeueStartsAnotherPassThatEarlierLeasesCannotComplete) {
  AddJob("j-1", 3);
  LeaseTable::Grant a = MustLease("w-1");
  LeaseTable::Grant b = MustLease("w-1");
  LeaseTable::Grant c = MustLease("w-2");
  ASSERT_TRUE(table_->Complete(a.lease_id, a.generation, TileFor(a)).ok());
  ASSERT_TRUE(table_->Complete(b.lease_id, b.generation, TileFor(b)).ok());
  // c is still leased; a is done; b stays done (not in the pass).
  absl::Status unknown = table_->Requeue("j-1", {{0, 0, 0}, {5, 5, 5}}, "finer pass");
  EXPECT_EQ(unknown.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(StoredChunk("j-1", {0, 0, 0}).state, ChunkState::kDone);  // nothing changed
  EXPECT_EQ(table_->Requeue("j-9", {{0, 0, 0}}, "x").code(), absl::StatusCode::kNotFound);

  ASSERT_TRUE(table_->Requeue("j-1", {{0, 0, 0}, {0, 0, 2}}, "finer pass").ok());
  EXPECT_FALSE(table_->AllDone("j-1"));
  EXPECT_TRUE(table_->LeasesOf("w-2").empty());  // c's lease is void
  const ChunkRecord stored = StoredChunk("j-1", {0, 0, 0});
  EXPECT_EQ(stored.state, ChunkState::kQueued);
  EXPECT_EQ(stored.generation, 2);
  EXPECT_EQ(stored.attempts, 0);
  EXPECT_TRUE(stored.tile_path.empty());
  EXPECT_EQ(stored.last_error, "finer pass");
  // The earlier pass's lease of c, late: rejected, it belongs to the other pass.
  absl::Status late = table_->Complete(c.lease_id, c.generation, TileFor(c));
  EXPECT_EQ(late.code(), absl::StatusCode::kFailedPrecondition);

  LeaseTable::Grant a2 = MustLease("w-3");
  LeaseTable::Grant c2 = MustLease("w-3");
  EXPECT_EQ(a2.chunk, (ChunkCoord{0, 0, 0}));
  EXPECT_EQ(a2.generation, 3);
  EXPECT_EQ(a2.attempt, 1);  // a fresh attempt budget
  EXPECT_EQ(c2.chunk, (ChunkCoord{0, 0, 2}));
  EXPECT_FALSE(table_->Lease("w-3")->has_value());
  ASSERT_TRUE(table_->Complete(a2.lease_id, a2.generation, TileFor(a2)).ok());
  ASSERT_TRUE(table_->Complete(c2.lease_id, c2.generation, TileFor(c2)).ok());
  EXPECT_TRUE(table_->AllDone("j-1"));
  auto job = store_->GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->counters.chunks_done, 3);
}

// A loaded job gets more tasks (the chunks to combine once its slices are carved): queued, in
// key order with the rest, persisted (a restart finds them), never twice.
TEST_F(LeaseTableTest, AddQueuesNewChunksOfALoadedJob) {
  AddJob("j", 1);
  const LeaseTable::Grant first = MustLease("w1");
  ASSERT_TRUE(table_->Complete(first.lease_id, first.generation, TileFor(first)).ok());
  EXPECT_TRUE(table_->AllDone("j"));
  std::vector<ChunkRecord> more(2);
  more[0].key = {5, 0, 0};
  more[1].key = {-5, 1, 0};
  ASSERT_TRUE(table_->Add("j", more).ok());
  EXPECT_FALSE(table_->AllDone("j"));
  EXPECT_EQ(MustLease("w1").chunk, (ChunkCoord{-5, 1, 0}));
  EXPECT_EQ(MustLease("w2").chunk, (ChunkCoord{5, 0, 0}));
  absl::StatusOr<LeaseTable::Progress> p = table_->GetProgress("j");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->chunks_total, 3);
  EXPECT_EQ(p->chunks_leased, 2);
  EXPECT_EQ(table_->Add("j", more).code(), absl::StatusCode::kAlreadyExists);
  EXPECT_EQ(table_->Add("other", more).code(), absl::StatusCode::kNotFound);
  Restart();
  ASSERT_TRUE(table_->LoadJob("j").ok());
  p = table_->GetProgress("j");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->chunks_total, 3);
  EXPECT_EQ(p->chunks_done, 1);
  EXPECT_EQ(p->chunks_queued, 2);  // the leases of before the restart, requeued
}

// A pass's second step, held back until its first is done: counted as not done at once (so
// the job never looks finished in between), leased only after Release.
TEST_F(LeaseTableTest, HeldChunksCountButWaitForRelease) {
  AddJob("j", 2);
  for (int i = 0; i < 2; ++i) {
    const LeaseTable::Grant g = MustLease("w1");
    ASSERT_TRUE(table_->Complete(g.lease_id, g.generation, TileFor(g)).ok());
  }
  std::vector<ChunkRecord> slices(1);
  slices[0].key = {-9, 0, 0};
  ASSERT_TRUE(table_->Add("j", slices).ok());
  ASSERT_TRUE(table_->Requeue("j", {{0, 0, 1}}, "next pass", /*held=*/true).ok());
  const LeaseTable::Grant s = MustLease("w1");
  EXPECT_EQ(s.chunk, (ChunkCoord{-9, 0, 0}));
  EXPECT_FALSE(table_->Lease("w2")->has_value());  // {0,0,1} is held
  EXPECT_FALSE(table_->AllDone("j", /*except_held=*/true));
  ASSERT_TRUE(table_->Complete(s.lease_id, s.generation, TileFor(s)).ok());
  EXPECT_FALSE(table_->AllDone("j"));
  EXPECT_TRUE(table_->AllDone("j", /*except_held=*/true));
  absl::StatusOr<LeaseTable::Progress> p = table_->GetProgress("j");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->chunks_total, 3);
  EXPECT_EQ(p->chunks_done, 2);
  EXPECT_EQ(table_->Release("j", {{0, 0, 0}}).code(), absl::StatusCode::kNotFound);
  ASSERT_TRUE(table_->Release("j", {{0, 0, 1}}).ok());
  const LeaseTable::Grant c = MustLease("w2");
  EXPECT_EQ(c.chunk, (ChunkCoord{0, 0, 1}));
  ASSERT_TRUE(table_->Complete(c.lease_id, c.generation, TileFor(c)).ok());
  EXPECT_TRUE(table_->AllDone("j"));
}

TEST_F(LeaseTableTest, HeartbeatExtendsAllLeasesOfTheWorker) {
  AddJob("j-1", 3);
  MustLease("w-1");
  MustLease("w-1");
  MustLease("w-2");
  EXPECT_FALSE(table_->Heartbeat("w-9").has_value());
  clock_.AdvanceMs(20'000);
  std::optional<int64_t> deadline = table_->Heartbeat("w-1");
  ASSERT_TRUE(deadline.has_value());
  EXPECT_EQ(*deadline, clock_.now_ms + kTimeoutMs);
  clock_.AdvanceMs(20'000);  // 40 s after the leases: w-2's expired, w-1's were extended
  auto expired = table_->ExpireLeases();
  ASSERT_TRUE(expired.ok());
  EXPECT_EQ(*expired, 1);
  EXPECT_EQ(table_->LeasesOf("w-1").size(), 2u);
  EXPECT_TRUE(table_->LeasesOf("w-2").empty());
}

TEST_F(LeaseTableTest, LostWorkersChunksAreRequeued) {
  AddJob("j-1", 4);
  LeaseTable::Grant a = MustLease("w-1");
  MustLease("w-2");
  LeaseTable::Grant c = MustLease("w-1");
  auto lost = table_->WorkerLost("w-1");
  ASSERT_TRUE(lost.ok());
  EXPECT_EQ(*lost, 2);
  EXPECT_TRUE(table_->LeasesOf("w-1").empty());
  EXPECT_EQ(table_->LeasesOf("w-2").size(), 1u);
  auto progress = table_->GetProgress("j-1");
  ASSERT_TRUE(progress.ok());
  EXPECT_EQ(progress->chunks_queued, 3);
  EXPECT_EQ(progress->chunks_leased, 1);
  EXPECT_EQ(StoredChunk("j-1", a.chunk).state, ChunkState::kQueued);
  EXPECT_THAT(StoredChunk("j-1", c.chunk).last_error, HasSubstr("worker w-1 lost"));
  // Requeued chunks go out again in key order.
  EXPECT_EQ(MustLease("w-3").chunk, a.chunk);
  auto zero = table_->WorkerLost("w-1");
  ASSERT_TRUE(zero.ok());
  EXPECT_EQ(*zero, 0);
}

TEST_F(LeaseTableTest, RetryableFailureRequeuesThenMaxAttemptsFailsTheJob) {
  AddJob("j-1", 2);
  LeaseTable::Grant other = MustLease("w-2");  // chunk (0,0,0), held throughout
  for (int attempt = 1; attempt <= 3; ++attempt) {
    LeaseTable::Grant g = MustLease("w-1");
    EXPECT_EQ(g.chunk, (ChunkCoord{0, 0, 1}));
    EXPECT_EQ(g.attempt, attempt);
    auto requeued = table_->Fail(g.lease_id, g.generation, "out of memory", true);
    ASSERT_TRUE(requeued.ok()) << requeued.status();
    EXPECT_EQ(*requeued, attempt < 3) << "attempt " << attempt;
  }
  auto job = store_->GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kFailed);
  EXPECT_EQ(job->error, "chunk (0,0,1): attempt 3 of 3 failed: worker w-1: out of memory");
  EXPECT_EQ(job->finished_unix_ms, clock_.now_ms);
  auto progress = table_->GetProgress("j-1");
  ASSERT_TRUE(progress.ok());
  EXPECT_TRUE(progress->failed);
  // Nothing more to lease, and the other lease of the job is void.
  auto none = table_->Lease("w-1");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  EXPECT_EQ(table_->Complete(other.lease_id, other.generation, TileFor(other)).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(table_->LeasesOf("w-2").empty());
  // A failed job cannot be loaded again.
  Restart();
  EXPECT_EQ(table_->LoadJob("j-1").code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(LeaseTableTest, NonRetryableFailureFailsTheJobAtOnce) {
  AddJob("j-1", 2);
  LeaseTable::Grant g = MustLease("w-1");
  auto requeued = table_->Fail(g.lease_id, g.generation, "corrupt wedge record 17", false);
  ASSERT_TRUE(requeued.ok());
  EXPECT_FALSE(*requeued);
  auto job = store_->GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kFailed);
  EXPECT_THAT(job->error, HasSubstr("corrupt wedge record 17 (not retryable)"));
  // Failing a lease twice: it is no longer held.
  EXPECT_EQ(table_->Fail(g.lease_id, g.generation, "again", true).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST_F(LeaseTableTest, RepeatedExpiryCountsTowardsMaxAttempts) {
  AddJob("j-1", 1);
  for (int attempt = 1; attempt <= 3; ++attempt) {
    MustLease("w-1");
    clock_.AdvanceMs(kTimeoutMs + 1);
    ASSERT_TRUE(table_->ExpireLeases().ok());
  }
  auto job = store_->GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kFailed);
  EXPECT_THAT(job->error, HasSubstr("attempt 3 of 3 failed: lease j-1/0,0,0/3 of worker w-1 "
                                    "expired"));
}

TEST_F(LeaseTableTest, RestartRebuildsTheTable) {
  AddJob("j-1", 4);
  LeaseTable::Grant a = MustLease("w-1");
  LeaseTable::Grant b = MustLease("w-1");
  LeaseTable::Grant c = MustLease("w-2");
  ASSERT_TRUE(table_->Complete(a.lease_id, a.generation, TileFor(a)).ok());

  Restart();
  ASSERT_TRUE(table_->LoadJob("j-1").ok());
  EXPECT_EQ(table_->LoadJob("j-1").code(), absl::StatusCode::kAlreadyExists);
  auto progress = table_->GetProgress("j-1");
  ASSERT_TRUE(progress.ok());
  EXPECT_EQ(progress->chunks_total, 4);
  EXPECT_EQ(progress->chunks_done, 1);    // DONE stays done
  EXPECT_EQ(progress->chunks_leased, 0);  // LEASED went back to the queue
  EXPECT_EQ(progress->chunks_queued, 3);
  EXPECT_EQ(StoredChunk("j-1", b.chunk).state, ChunkState::kQueued);
  // The restart does not use up an attempt.
  EXPECT_EQ(StoredChunk("j-1", b.chunk).attempts, 0);

  // The old holder of c finishes before c is leased again: accepted (same generation).
  EXPECT_TRUE(table_->Complete(c.lease_id, c.generation, TileFor(c)).ok());
  // b is leased again with the next generation; its old lease is now stale.
  LeaseTable::Grant b2 = MustLease("w-3");
  EXPECT_EQ(b2.chunk, b.chunk);
  EXPECT_EQ(b2.generation, 2);
  EXPECT_NE(b2.lease_id, b.lease_id);
  EXPECT_EQ(table_->Complete(b.lease_id, b.generation, TileFor(b)).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(table_->Complete(a.lease_id, a.generation, TileFor(a)).code(),
            absl::StatusCode::kFailedPrecondition);  // committed before the restart
  ASSERT_TRUE(table_->Complete(b2.lease_id, b2.generation, TileFor(b2)).ok());
  LeaseTable::Grant d = MustLease("w-3");
  ASSERT_TRUE(table_->Complete(d.lease_id, d.generation, TileFor(d)).ok());
  EXPECT_TRUE(table_->AllDone("j-1"));

  // And once more: a finished table reloads as finished.
  Restart();
  ASSERT_TRUE(table_->LoadJob("j-1").ok());
  EXPECT_TRUE(table_->AllDone("j-1"));
}

// A crash can leave a DONE chunk's file missing or short: the restarted table queues such a
// chunk again (a new generation, its reason stored) and keeps the others done.
TEST_F(LeaseTableTest, RestartQueuesAgainDoneChunksWhoseFileFailsTheCheck) {
  AddJob("j-1", 3);
  LeaseTable::Grant a = MustLease("w-1");
  LeaseTable::Grant b = MustLease("w-1");
  MustLease("w-1");  // the third: still leased at the restart, so not checked
  ASSERT_TRUE(table_->Complete(a.lease_id, a.generation, TileFor(a)).ok());
  ASSERT_TRUE(table_->Complete(b.lease_id, b.generation, TileFor(b)).ok());

  Restart();
  std::vector<ChunkCoord> checked;
  ASSERT_TRUE(table_
                  ->LoadJob("j-1",
                            [&](const ChunkRecord& r) -> std::string {
                              checked.push_back(r.key);
                              return r.key == b.chunk ? "tile truncated (5 of 9 bytes)" : "";
                            })
                  .ok());
  std::sort(checked.begin(), checked.end());
  std::vector<ChunkCoord> done = {a.chunk, b.chunk};
  std::sort(done.begin(), done.end());
  EXPECT_EQ(checked, done);  // only DONE chunks are checked
  absl::StatusOr<LeaseTable::Progress> p = table_->GetProgress("j-1");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->chunks_done, 1);
  EXPECT_EQ(p->chunks_queued, 2);
  const ChunkRecord stored = StoredChunk("j-1", b.chunk);
  EXPECT_EQ(stored.state, ChunkState::kQueued);
  EXPECT_EQ(stored.generation, b.generation + 1);
  EXPECT_TRUE(stored.tile_path.empty());
  EXPECT_NE(stored.last_error.find("tile truncated (5 of 9 bytes)"), std::string::npos);
  EXPECT_EQ(StoredChunk("j-1", a.chunk).state, ChunkState::kDone);
  // The lease that wrote the bad file can no longer complete it.
  EXPECT_EQ(table_->Complete(b.lease_id, b.generation, TileFor(b)).code(),
            absl::StatusCode::kFailedPrecondition);
  while (!table_->AllDone("j-1")) {
    const LeaseTable::Grant g = MustLease("w-2");
    ASSERT_TRUE(table_->Complete(g.lease_id, g.generation, TileFor(g)).ok());
  }
}

TEST_F(LeaseTableTest, JobsAreServedInLoadOrderAndDropJobVoidsLeases) {
  AddJob("j-old", 1);
  AddJob("j-new", 1);
  LeaseTable::Grant first = MustLease("w-1");
  LeaseTable::Grant second = MustLease("w-1");
  EXPECT_EQ(first.job_id, "j-old");
  EXPECT_EQ(second.job_id, "j-new");
  table_->DropJob("j-old");  // e.g. cancelled
  EXPECT_EQ(table_->Complete(first.lease_id, first.generation, TileFor(first)).code(),
            absl::StatusCode::kNotFound);
  EXPECT_THAT(table_->LeasesOf("w-1"), ElementsAre(second.lease_id));
}

// The progress the table keeps as chunks change equals a recount of the store's rows (every
// change is persisted), through a long random mix of every operation, a restart included.
TEST_F(LeaseTableTest, KeptProgressEqualsARecountOfTheStore) {
  options_.max_attempts = 1000;  // retries, not failures: the job stays alive
  Restart();
  AddJob("j", 40);
  std::mt19937 rng(11);
  std::vector<LeaseTable::Grant> held;  // leases workers hold
  std::set<ChunkCoord> held_back;       // chunks Requeue(held = true) holds
  int next_key = 40;
  const auto check = [&] {
    absl::StatusOr<std::vector<ChunkRecord>> rows = store_->ListChunks("j");
    ASSERT_TRUE(rows.ok()) << rows.status();
    LeaseTable::Progress want;
    int64_t done_outside_held = 0, outside_held = 0;
    for (const ChunkRecord& c : *rows) {
      ++want.chunks_total;
      want.chunks_done += c.state == ChunkState::kDone;
      want.chunks_leased += c.state == ChunkState::kLeased;
      want.chunks_queued += c.state == ChunkState::kQueued;
      want.chunk_retries += std::max(0, c.attempts - 1);
      if (!held_back.count(c.key)) {
        ++outside_held;
        done_outside_held += c.state == ChunkState::kDone;
      }
    }
    absl::StatusOr<LeaseTable::Progress> got = table_->GetProgress("j");
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_EQ(got->chunks_total, want.chunks_total);
    EXPECT_EQ(got->chunks_done, want.chunks_done);
    EXPECT_EQ(got->chunks_leased, want.chunks_leased);
    EXPECT_EQ(got->chunks_queued, want.chunks_queued);
    EXPECT_EQ(got->chunk_retries, want.chunk_retries);
    EXPECT_EQ(table_->AllDone("j"), want.chunks_done == want.chunks_total);
    EXPECT_EQ(table_->AllDone("j", /*except_held=*/true), done_outside_held == outside_held);
  };
  for (int step = 0; step < 600; ++step) {
    switch (rng() % 8) {
      case 0:
      case 1: {  // lease
        absl::StatusOr<std::optional<LeaseTable::Grant>> g =
            table_->Lease(absl::StrCat("w-", rng() % 3));
        ASSERT_TRUE(g.ok()) << g.status();
        if (*g) held.push_back(**g);
        break;
      }
      case 2:
      case 3:  // complete
        if (!held.empty()) {
          const size_t i = rng() % held.size();
          (void)table_->Complete(held[i].lease_id, held[i].generation, TileFor(held[i]));
          held.erase(held.begin() + long(i));
        }
        break;
      case 4:  // a worker gives up
        if (!held.empty()) {
          const size_t i = rng() % held.size();
          (void)table_->Fail(held[i].lease_id, held[i].generation, "test", /*retryable=*/true);
          held.erase(held.begin() + long(i));
        }
        break;
      case 5:  // a worker is lost, or leases expire
        if (rng() % 2) {
          ASSERT_TRUE(table_->WorkerLost(absl::StrCat("w-", rng() % 3)).ok());
        } else {
          clock_.AdvanceMs(kTimeoutMs + 1);
          ASSERT_TRUE(table_->ExpireLeases().ok());
        }
        break;
      case 6: {  // another pass over some chunks, held or not; or new chunks
        if (rng() % 3 == 0) {
          ChunkRecord r;
          r.job_id = "j";
          r.key = {1, 0, next_key++};
          ASSERT_TRUE(table_->Add("j", {&r, 1}).ok());
          break;
        }
        std::vector<ChunkCoord> keys;
        for (int k = 0; k < 3; ++k) keys.push_back({0, 0, int(rng() % 40)});
        std::sort(keys.begin(), keys.end());
        keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
        const bool hold = rng() % 2;
        ASSERT_TRUE(table_->Requeue("j", keys, "again", hold).ok());
        for (const ChunkCoord& k : keys) {
          if (hold) {
            held_back.insert(k);
          } else {
            held_back.erase(k);
          }
        }
        break;
      }
      case 7:  // release what is held back; now and then a restart
        if (!held_back.empty()) {
          ASSERT_TRUE(
              table_->Release("j", std::vector<ChunkCoord>(held_back.begin(), held_back.end()))
                  .ok());
          held_back.clear();
        } else if (rng() % 4 == 0) {
          Restart();  // leases are requeued on load; held is memory only
          ASSERT_TRUE(table_->LoadJob("j").ok());
        }
        break;
    }
    check();
    if (HasFailure()) FAIL() << "at step " << step;
  }
}

TEST(LeaseTableOptionsTest, Validate) {
  EXPECT_TRUE(LeaseTableOptions{}.Validate().ok());
  EXPECT_EQ((LeaseTableOptions{.lease_timeout_ms = 0}.Validate().code()),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ((LeaseTableOptions{.max_attempts = 0}.Validate().code()),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap
