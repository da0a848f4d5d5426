#include "coordinator/coordinator_core.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <thread>

#include "absl/strings/str_cat.h"
#include "coordinator/fake_clock.h"

namespace carvemap {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;

// The service's defaults: a worker is lost before its leases expire.
constexpr int64_t kLeaseTimeoutMs = 30'000;
constexpr int64_t kWorkerTimeoutMs = 15'000;

class CoordinatorCoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    // TempDir() is private to this test process (tests/test_main.cc) and removed at exit.
    const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / info->name();
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    auto store = JobStore::Open((dir / "jobs.db").string());
    ASSERT_TRUE(store.ok()) << store.status();
    store_ = std::move(*store);
    MakeCore(kLeaseTimeoutMs);
  }

  void MakeCore(int64_t lease_timeout_ms) {
    CoordinatorCoreOptions options;
    options.leases = {.lease_timeout_ms = lease_timeout_ms, .max_attempts = 3};
    options.worker_timeout_ms = kWorkerTimeoutMs;
    options.folders = CoordinatorFolders::Of("/srv/data", "/srv/out", "", "/srv/work");
    options.instance = "t";
    core_ = std::make_unique<CoordinatorCore>(*store_, clock_, options);
  }

  // A CARVING job with tasks (0,0,0), (0,0,1), ..., loaded into the lease table.
  void AddJob(const std::string& id, int tasks) {
    JobRecord job;
    job.id = id;
    job.output_name = id;
    job.params_json = "{}";
    job.created_unix_ms = clock_.now_ms;
    ASSERT_TRUE(store_->CreateJob(job).ok());
    std::vector<ChunkRecord> records(tasks);
    for (int i = 0; i < tasks; ++i) records[i].key = {0, 0, i};
    ASSERT_TRUE(store_->AddChunks(id, records).ok());
    ASSERT_TRUE(store_->TransitionJob(id, {JobState::kCarving, "", clock_.now_ms}).ok());
    ASSERT_TRUE(core_->LoadTasks(id).ok());
  }

  CarveTask MustLease(const std::string& worker) {
    absl::StatusOr<std::optional<CarveTask>> task =
        core_->Lease(worker, absl::ZeroDuration(), nullptr);
    EXPECT_TRUE(task.ok()) << task.status();
    EXPECT_TRUE(task.ok() && task->has_value()) << "nothing to lease";
    return task.ok() && task->has_value() ? **task : CarveTask{};
  }

  absl::StatusOr<LeaseTable::Progress> Complete(const std::string& worker, const CarveTask& t,
                                                int64_t rays = 0) {
    CoordinatorCore::Completion c;
    c.worker_id = worker;
    c.lease_id = t.grant.lease_id;
    c.generation = t.grant.generation;
    c.tile = {absl::StrCat("tile_", t.grant.chunk.z, ".h5"), 100, std::string(64, 'a')};
    c.counts.rays = rays;
    c.counts.frames = rays > 0 ? 1 : 0;
    return core_->Complete(c);
  }

  FakeClock clock_;
  std::unique_ptr<JobStore> store_;
  std::unique_ptr<CoordinatorCore> core_;
};

TEST_F(CoordinatorCoreTest, LeasesCompletesAndFailsInKeyOrder) {
  AddJob("j-1", 3);
  const std::string w1 = core_->RegisterWorker(), w2 = core_->RegisterWorker();
  EXPECT_EQ(w1, "w-t-1");
  const CarveTask a = MustLease(w1), b = MustLease(w2), c = MustLease(w1);
  EXPECT_EQ(a.grant.chunk, (ChunkCoord{0, 0, 0}));
  EXPECT_EQ(b.grant.chunk, (ChunkCoord{0, 0, 1}));
  EXPECT_EQ(c.grant.chunk, (ChunkCoord{0, 0, 2}));
  EXPECT_EQ(a.grant.deadline_unix_ms, clock_.now_ms + kLeaseTimeoutMs);
  EXPECT_TRUE(std::holds_alternative<CombineWork>(a.work));
  absl::StatusOr<std::optional<CarveTask>> none = core_->Lease(w2, absl::ZeroDuration(), nullptr);
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_FALSE(none->has_value());

  absl::StatusOr<LeaseTable::Progress> p = Complete(w1, a, /*rays=*/40);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->chunks_done, 1);
  EXPECT_EQ(p->chunks_leased, 2);
  // w2 gives b up: it is requeued and leased again, a new generation and attempt.
  absl::StatusOr<bool> requeued = core_->Fail(w2, b.grant.lease_id, b.grant.generation, "oom",
                                              /*retryable=*/true);
  ASSERT_TRUE(requeued.ok()) << requeued.status();
  EXPECT_TRUE(*requeued);
  const CarveTask b2 = MustLease(w2);
  EXPECT_EQ(b2.grant.chunk, b.grant.chunk);
  EXPECT_EQ(b2.grant.generation, b.grant.generation + 1);
  EXPECT_EQ(b2.grant.attempt, 2);
  // Failing the old lease again: it is no longer held.
  EXPECT_EQ(core_->Fail(w2, b.grant.lease_id, b.grant.generation, "x", true).status().code(),
            absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(Complete(w2, b2, 60).ok());
  p = Complete(w1, c);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->chunks_done, 3);
  EXPECT_EQ(p->chunk_retries, 1);
  EXPECT_TRUE(core_->WaitForTasks("j-1").ok());  // all done: no wait
  // The slices' counts (a combine's zeros do not count as a slice).
  core_->WithRuntime("j-1", [](JobRuntime& rt) {
    EXPECT_EQ(rt.rays_carved, 100);
    EXPECT_EQ(rt.slices_counted, 2u);
    EXPECT_EQ(rt.carve_counts.value("frames", 0), 2);
  });
  // A second completion of a committed task is refused.
  EXPECT_EQ(Complete(w1, a).status().code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(CoordinatorCoreTest, LeaseErrors) {
  AddJob("j-1", 1);
  EXPECT_EQ(core_->Lease("", absl::ZeroDuration(), nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
  absl::Status unknown = core_->Lease("w-t-9", absl::ZeroDuration(), nullptr).status();
  EXPECT_EQ(unknown.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(unknown.message(), "worker w-t-9 unknown or lost: register again");
  const std::string w = core_->RegisterWorker();
  EXPECT_EQ(core_->Lease(w, absl::ZeroDuration(), [] { return true; }).status().code(),
            absl::StatusCode::kCancelled);
  MustLease(w);  // the cancelled call leased nothing
}

TEST_F(CoordinatorCoreTest, AnExpiredLeaseIsLeasedAgainAndTheStaleOneRefused) {
  MakeCore(/*lease_timeout_ms=*/5'000);  // shorter than the worker timeout
  AddJob("j-1", 1);
  const std::string w1 = core_->RegisterWorker(), w2 = core_->RegisterWorker();
  const CarveTask first = MustLease(w1);
  clock_.AdvanceMs(5'001);
  CoordinatorCore::SweepReport sweep = core_->Sweep(clock_.now_ms);
  ASSERT_TRUE(sweep.expired.ok()) << sweep.expired.status();
  EXPECT_EQ(*sweep.expired, 1);
  EXPECT_EQ(sweep.late_ms, 0);
  EXPECT_TRUE(sweep.lost.empty());  // silent for less than the worker timeout
  EXPECT_EQ(sweep.tasks_queued, 1);
  EXPECT_EQ(sweep.workers, 2);

  const CarveTask second = MustLease(w2);
  EXPECT_EQ(second.grant.chunk, first.grant.chunk);
  EXPECT_EQ(second.grant.generation, first.grant.generation + 1);
  // The first holder finishes late, after the task was leased again: refused.
  absl::Status stale = Complete(w1, first).status();
  EXPECT_EQ(stale.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(stale.message(), HasSubstr("stale lease"));
  // w1's heartbeat names the lease it still works on: revoked.
  CoordinatorCore::HeartbeatReport report{.worker_id = w1,
                                          .active_lease_ids = {first.grant.lease_id}};
  absl::StatusOr<CoordinatorCore::HeartbeatReply> reply = core_->Heartbeat(report);
  ASSERT_TRUE(reply.ok()) << reply.status();
  EXPECT_THAT(reply->revoked_lease_ids, ElementsAre(first.grant.lease_id));
  EXPECT_FALSE(reply->lease_deadline_unix_ms.has_value());
  ASSERT_TRUE(Complete(w2, second).ok());
  EXPECT_TRUE(core_->WaitForTasks("j-1").ok());
}

TEST_F(CoordinatorCoreTest, TheSweepReturnsADeadWorkersLeases) {
  AddJob("j-1", 3);
  const std::string dead = core_->RegisterWorker(), alive = core_->RegisterWorker();
  const CarveTask a = MustLease(dead), b = MustLease(dead);
  MustLease(alive);
  // `alive` heartbeats, `dead` is silent past the worker timeout (its leases have not expired).
  for (int64_t t = 0; t <= kWorkerTimeoutMs; t += 4'000) {
    clock_.AdvanceMs(4'000);
    ASSERT_TRUE(core_->Heartbeat({.worker_id = alive}).ok());
  }
  CoordinatorCore::SweepReport sweep = core_->Sweep(clock_.now_ms);
  ASSERT_TRUE(sweep.expired.ok());
  EXPECT_EQ(*sweep.expired, 0);
  ASSERT_EQ(sweep.lost.size(), 1u);
  EXPECT_EQ(sweep.lost[0].worker_id, dead);
  EXPECT_EQ(sweep.lost[0].silent_ms, 16'000);
  ASSERT_TRUE(sweep.lost[0].leases.ok());
  EXPECT_EQ(*sweep.lost[0].leases, 2);
  EXPECT_EQ(sweep.tasks_queued, 2);
  EXPECT_EQ(sweep.tasks_leased, 1);
  EXPECT_EQ(sweep.workers, 1);
  // The lost worker must register again; its tasks go to the live one, in key order.
  EXPECT_EQ(core_->Heartbeat({.worker_id = dead}).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(core_->Lease(dead, absl::ZeroDuration(), nullptr).status().code(),
            absl::StatusCode::kNotFound);
  const CarveTask a2 = MustLease(alive);
  EXPECT_EQ(a2.grant.chunk, a.grant.chunk);
  EXPECT_EQ(MustLease(alive).grant.chunk, b.grant.chunk);
  // The dead worker's result for a task leased again is stale.
  EXPECT_EQ(Complete(dead, a).status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(Complete(alive, a2).ok());
}

TEST_F(CoordinatorCoreTest, ALateSweepDoesNotCountAgainstTheWorkers) {
  AddJob("j-1", 1);
  const std::string w = core_->RegisterWorker();
  MustLease(w);
  // Due 2 s after the registration, run 16 s after it: 14 s late, credited.
  clock_.AdvanceMs(kWorkerTimeoutMs + 1'000);
  CoordinatorCore::SweepReport sweep = core_->Sweep(clock_.now_ms - 14'000);
  EXPECT_EQ(sweep.late_ms, 14'000);
  EXPECT_TRUE(sweep.lost.empty());
  EXPECT_EQ(sweep.workers, 1);
}

TEST_F(CoordinatorCoreTest, HeartbeatsShowInTheWatchSnapshot) {
  AddJob("j-1", 2);
  core_->WithRuntime("j-1", [](JobRuntime& rt) { rt.rays_to_carve = 1000; });
  core_->EnterStage("j-1", "carve");
  const std::string w = core_->RegisterWorker();
  MustLease(w);
  ASSERT_TRUE(core_->Heartbeat({.worker_id = w, .rays_carved = 300}).ok());
  clock_.AdvanceMs(10'000);
  ASSERT_TRUE(core_->Heartbeat({.worker_id = w, .rays_carved = 300}).ok());

  JobCounters counters;
  counters.chunks_total = 2;
  const CoordinatorCore::WatchSnapshot snap = core_->Watch("j-1", counters, JobState::kCarving);
  ASSERT_TRUE(snap.progress.has_value());
  EXPECT_EQ(snap.progress->rays_done, 600);
  EXPECT_EQ(snap.progress->rays_total, 1000);
  // What came after the first heartbeat over the 10 s since it.
  EXPECT_DOUBLE_EQ(snap.progress->rays_per_s, 30);
  EXPECT_DOUBLE_EQ(snap.progress->eta_s, 400.0 / 30);
  ASSERT_EQ(snap.progress->stages.size(), 1u);
  EXPECT_EQ(snap.progress->stages[0].name, "carve");
  EXPECT_DOUBLE_EQ(snap.progress->stages[0].elapsed_s, 10);
  EXPECT_EQ(snap.active_workers, 1);

  const CoordinatorCore::WatchSnapshot other = core_->Watch("j-2", counters, JobState::kCarving);
  EXPECT_FALSE(other.progress.has_value());
  EXPECT_EQ(other.active_workers, 0);
}

TEST_F(CoordinatorCoreTest, LeasesAWorkerNoLongerReportsAreGivenBack) {
  AddJob("j-1", 2);
  const std::string w = core_->RegisterWorker();
  const CarveTask a = MustLease(w), b = MustLease(w);
  clock_.AdvanceMs(1'000);
  absl::StatusOr<CoordinatorCore::HeartbeatReply> reply = core_->Heartbeat(
      {.worker_id = w, .report_leases = true, .active_lease_ids = {b.grant.lease_id}});
  ASSERT_TRUE(reply.ok()) << reply.status();
  EXPECT_TRUE(reply->revoked_lease_ids.empty());
  EXPECT_EQ(reply->lease_deadline_unix_ms, clock_.now_ms + kLeaseTimeoutMs);
  // a went back to the queue at once (not at its deadline) and is leased again.
  const CarveTask again = MustLease(w);
  EXPECT_EQ(again.grant.chunk, a.grant.chunk);
  EXPECT_EQ(again.grant.attempt, 2);
}

TEST_F(CoordinatorCoreTest, AFailureOutOfAttemptsFailsTheJobAndEndsItsWait) {
  AddJob("j-1", 1);
  const std::string w = core_->RegisterWorker();
  const CarveTask t = MustLease(w);
  absl::StatusOr<bool> requeued =
      core_->Fail(w, t.grant.lease_id, t.grant.generation, "corrupt", /*retryable=*/false);
  ASSERT_TRUE(requeued.ok()) << requeued.status();
  EXPECT_FALSE(*requeued);
  absl::StatusOr<JobRecord> job = store_->GetJob("j-1");
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kFailed);
  EXPECT_THAT(job->error, HasSubstr("worker w-t-1: corrupt (not retryable)"));
  EXPECT_EQ(core_->WaitForTasks("j-1").code(), absl::StatusCode::kCancelled);
}

// The waits end on events, not on a poll: a parked lease call when tasks are added, a job
// thread's wait when its tasks are done, both on Stop.
TEST_F(CoordinatorCoreTest, WaitsEndOnEvents) {
  AddJob("j-1", 0);
  const std::string w = core_->RegisterWorker();
  absl::StatusOr<std::optional<CarveTask>> parked;
  std::thread lease([&] { parked = core_->Lease(w, absl::Hours(1), nullptr); });
  ChunkRecord task;
  task.key = {0, 0, 7};
  ASSERT_TRUE(core_->AddTasks("j-1", {&task, 1}).ok());
  lease.join();
  // Woken by the new task (or, started after it, found it at once).
  ASSERT_TRUE(parked.ok()) << parked.status();
  if (!parked->has_value()) parked = core_->Lease(w, absl::ZeroDuration(), nullptr);
  ASSERT_TRUE(parked.ok() && parked->has_value());

  absl::Status waited = absl::UnknownError("not run");
  std::thread job([&] { waited = core_->WaitForTasks("j-1"); });
  ASSERT_TRUE(Complete(w, **parked).ok());
  job.join();
  EXPECT_TRUE(waited.ok()) << waited;

  task.key = {0, 0, 8};
  ASSERT_TRUE(core_->AddTasks("j-1", {&task, 1}).ok());
  MustLease(w);  // not done: the next wait lasts until Stop
  std::thread stopped([&] { waited = core_->WaitForTasks("j-1"); });
  core_->Stop();
  stopped.join();
  EXPECT_EQ(waited.code(), absl::StatusCode::kCancelled);
  // A stopped core parks no lease call: nothing queued, it answers at once.
  absl::StatusOr<std::optional<CarveTask>> after = core_->Lease(w, absl::Hours(1), nullptr);
  ASSERT_TRUE(after.ok());
  EXPECT_FALSE(after->has_value());
}

// A re-carve pass: its slices leased with the pass's folders and grid, its chunks held until
// released, the job's own carve back in the runtime at the end.
TEST_F(CoordinatorCoreTest, ARecarvePassHoldsItsChunksUntilItsSlicesAreCarved) {
  AddJob("j-1", 2);
  const std::string w = core_->RegisterWorker();
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(Complete(w, MustLease(w)).ok());
  core_->DropTasks("j-1");  // the carve is over
  const JobRuntime saved = core_->WithRuntime("j-1", [](JobRuntime& rt) {
    rt.params.resolution_m = 0.25;
    rt.tiles_dir = "/srv/out/j-1/tiles";
    rt.partials_dir = rt.pass_dir = "/srv/work/j-1/partials";
    rt.rays_carved = rt.rays_to_carve = 500;
    rt.slices.resize(2);
    rt.slices[1].index = 1;
    return rt;
  });
  CoordinatorCore::RecarvePass pass{.pass = 1,
                                    .resolution_m = 0.1,
                                    .grid_resolution_m = 0.125,
                                    .tiles_dir = "/srv/out/j-1/object_tiles",
                                    .pass_dir = "/srv/work/j-1/partials/p1",
                                    .regions_path = "/srv/work/j-1/partials/p1/regions.bin",
                                    .chunks = {{0, 0, 1}}};
  ASSERT_TRUE(core_->StartRecarve("j-1", pass).ok());
  std::vector<CarveTask> slices = {MustLease(w), MustLease(w)};
  for (const CarveTask& t : slices) {
    const SliceWork* work = std::get_if<SliceWork>(&t.work);
    ASSERT_NE(work, nullptr);
    EXPECT_EQ(work->pass, 1);
    EXPECT_EQ(work->regions_path, pass.regions_path);
    EXPECT_EQ(t.resolution_m, 0.125);
    EXPECT_EQ(t.tile_dir, pass.tiles_dir);
  }
  EXPECT_FALSE(core_->Lease(w, absl::ZeroDuration(), nullptr)->has_value());  // held
  for (const CarveTask& t : slices) ASSERT_TRUE(Complete(w, t, 10).ok());
  EXPECT_TRUE(core_->WaitForTasks("j-1", /*except_held=*/true).ok());
  ASSERT_TRUE(core_->ReleaseTasks("j-1", pass.chunks).ok());
  const CarveTask chunk = MustLease(w);
  EXPECT_EQ(chunk.grant.chunk, (ChunkCoord{0, 0, 1}));
  ASSERT_TRUE(Complete(w, chunk).ok());
  EXPECT_TRUE(core_->WaitForTasks("j-1").ok());
  core_->EndRecarve("j-1", saved);
  core_->WithRuntime("j-1", [&](const JobRuntime& rt) {
    EXPECT_EQ(rt.pass, 0);
    EXPECT_EQ(rt.passes, 0);  // the service counts its passes
    EXPECT_EQ(rt.params.resolution_m, 0.25);
    EXPECT_EQ(rt.tiles_dir, saved.tiles_dir);
    EXPECT_EQ(rt.pass_dir, saved.partials_dir);
    EXPECT_EQ(rt.rays_carved, 500);  // the pass's rays do not count as the job's
    EXPECT_TRUE(rt.regions_path.empty());
  });
  // The job left the lease table: a wait on it ends at once.
  EXPECT_EQ(core_->WaitForTasks("j-1").code(), absl::StatusCode::kCancelled);
}

TEST_F(CoordinatorCoreTest, TenantViewHidesTheServersFolders) {
  AddJob("j-1", 0);
  core_->WithRuntime("j-1", [](JobRuntime& rt) {
    rt.output_dir = "/srv/out/room";
    rt.tiles_dir = "/srv/out/room/tiles";
  });
  EXPECT_EQ(core_->TenantView("j-1", "/srv/out/room/tiles/x.h5: short"), "tiles/x.h5: short");
  core_->EraseRuntime("j-1");
  EXPECT_EQ(core_->TenantView("j-1", "/srv/work/j-1/partials/slice_0.part: bad"),
            "work/j-1/partials/slice_0.part: bad");
}

}  // namespace
}  // namespace carvemap
