#include "coordinator/job_runner.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>
#include <memory>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "coordinator/fake_clock.h"

namespace carvemap {
namespace {

using ::testing::ElementsAre;
using ::testing::IsEmpty;

// Records what the runner asks; each stage does what the test sets (default: OK, and Ingest
// stores `tasks` tasks as a real plan would).
class FakeStages final : public JobStages {
 public:
  explicit FakeStages(JobStore& store) : store_(store) {}
  absl::Status Ingest(const JobRecord& job) override {
    calls.push_back("ingest");
    if (ingest) return ingest(job);
    std::vector<ChunkRecord> records(tasks);
    for (int i = 0; i < tasks; ++i) records[i].key = SliceTaskKey(i, 0);
    return store_.AddChunks(job.id, records);
  }
  absl::Status Carve(const JobRecord& job) override {
    calls.push_back("carve");
    return carve ? carve(job) : absl::OkStatus();
  }
  absl::Status Merge(const JobRecord& job) override {
    calls.push_back("merge");
    return merge ? merge(job) : absl::OkStatus();
  }
  void EnterStage(const std::string&, const std::string& stage) override {
    entered.push_back(stage);
  }
  std::string TenantView(const std::string&, const std::string& text) override {
    return absl::StrReplaceAll(text, {{"/srv/work/j-1/partials", "partials"}});
  }
  void Moved(const std::string&, JobState from, JobState to, const std::string& reason) override {
    moves.push_back(absl::StrCat(JobStateName(from), "->", JobStateName(to),
                                 reason.empty() ? "" : ": ", reason));
  }
  void NotMoved(const std::string&, JobState to, const absl::Status& why) override {
    refused.push_back(absl::StrCat(JobStateName(to), " ", absl::StatusCodeToString(why.code())));
  }
  void CleanUp(const std::string&, bool succeeded) override { cleanups.push_back(succeeded); }
  bool Stopping() override { return stopping; }

  int tasks = 2;
  bool stopping = false;
  std::function<absl::Status(const JobRecord&)> ingest, carve, merge;
  std::vector<std::string> calls, entered, moves, refused;
  std::vector<bool> cleanups;

 private:
  JobStore& store_;
};

class JobRunnerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    // TempDir() is private to this test process (tests/test_main.cc) and removed at exit.
    const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / info->name();
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    auto store = JobStore::Open((dir / "jobs.db").string());
    ASSERT_TRUE(store.ok()) << store.status();
    store_ = *std::move(store);
    stages_ = std::make_unique<FakeStages>(*store_);
    JobRecord job;
    job.id = "j-1";
    job.output_name = "out";
    job.params_json = "{}";
    job.created_unix_ms = clock_.now_ms;
    ASSERT_TRUE(store_->CreateJob(job).ok());
  }
  JobState Run() {
    absl::StatusOr<JobState> s = RunJob("j-1", *store_, *stages_, clock_);
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? *s : JobState::kFailed;
  }
  JobRecord Stored() {
    absl::StatusOr<JobRecord> job = store_->GetJob("j-1");
    EXPECT_TRUE(job.ok()) << job.status();
    return job.ok() ? *job : JobRecord{};
  }
  void StoreState(JobState to) { ASSERT_TRUE(store_->TransitionJob("j-1", {to, "", 1}).ok()); }

  FakeClock clock_;
  std::unique_ptr<JobStore> store_;
  std::unique_ptr<FakeStages> stages_;
};

TEST_F(JobRunnerTest, ANewJobGoesThroughEveryStage) {
  clock_.now_ms += 5000;
  EXPECT_EQ(Run(), JobState::kSucceeded);
  EXPECT_THAT(stages_->calls, ElementsAre("ingest", "carve", "merge"));
  EXPECT_THAT(stages_->entered, ElementsAre("ingest", "carve", "merge"));
  EXPECT_THAT(stages_->moves, ElementsAre("QUEUED->INGESTING", "INGESTING->CARVING",
                                          "CARVING->MERGING", "MERGING->SUCCEEDED"));
  EXPECT_THAT(stages_->cleanups, ElementsAre(true));
  EXPECT_EQ(Stored().state, JobState::kSucceeded);
  EXPECT_EQ(Stored().finished_unix_ms, clock_.now_ms);
}

TEST_F(JobRunnerTest, AnEmptyScanGoesFromIngestToMerge) {
  stages_->tasks = 0;
  EXPECT_EQ(Run(), JobState::kSucceeded);
  EXPECT_THAT(stages_->calls, ElementsAre("ingest", "merge"));
  EXPECT_THAT(stages_->moves,
              ElementsAre("QUEUED->INGESTING", "INGESTING->MERGING", "MERGING->SUCCEEDED"));
}

TEST_F(JobRunnerTest, AStageErrorFailsTheJobInTheTenantsView) {
  stages_->carve = [](const JobRecord&) {
    return absl::DataLossError("slice 3: /srv/work/j-1/partials/slice_3.part: bad CRC");
  };
  EXPECT_EQ(Run(), JobState::kFailed);
  EXPECT_THAT(stages_->calls, ElementsAre("ingest", "carve"));
  EXPECT_EQ(stages_->moves.back(),
            "CARVING->FAILED: carve: slice 3: /srv/work/j-1/partials/slice_3.part: bad CRC");
  EXPECT_EQ(Stored().error, "carve: slice 3: partials/slice_3.part: bad CRC");
  EXPECT_THAT(stages_->cleanups, ElementsAre(false));
}

TEST_F(JobRunnerTest, IngestAndMergeErrorsNameTheirStage) {
  stages_->ingest = [](const JobRecord&) { return absl::NotFoundError("scan.h5: no /path"); };
  EXPECT_EQ(Run(), JobState::kFailed);
  EXPECT_EQ(Stored().error, "ingest: scan.h5: no /path");
  EXPECT_THAT(stages_->calls, ElementsAre("ingest"));

  SetUp();
  stages_->merge = [](const JobRecord&) { return absl::InternalError("planar mesh"); };
  EXPECT_EQ(Run(), JobState::kFailed);
  EXPECT_EQ(Stored().error, "merge: planar mesh");
  EXPECT_THAT(stages_->cleanups, ElementsAre(false));
}

TEST_F(JobRunnerTest, AJobCancelledDuringAStageIsNotFailed) {
  stages_->carve = [this](const JobRecord& job) {
    EXPECT_TRUE(store_->TransitionJob(job.id, {JobState::kCancelled, "by client", 2}).ok());
    return absl::CancelledError("job ended while carving");
  };
  EXPECT_EQ(Run(), JobState::kCarving);
  EXPECT_EQ(Stored().state, JobState::kCancelled);
  EXPECT_EQ(Stored().error, "by client");
  EXPECT_THAT(stages_->cleanups, ElementsAre(false));
  EXPECT_THAT(stages_->calls, ElementsAre("ingest", "carve"));
}

TEST_F(JobRunnerTest, ACancelBetweenStagesStopsAtTheRefusedMove) {
  stages_->carve = [this](const JobRecord& job) {
    EXPECT_TRUE(store_->TransitionJob(job.id, {JobState::kCancelled, "by client", 2}).ok());
    return absl::OkStatus();  // the carve ended just as the cancel came
  };
  Run();
  EXPECT_THAT(stages_->refused, ElementsAre("MERGING FAILED_PRECONDITION"));
  EXPECT_THAT(stages_->calls, ElementsAre("ingest", "carve"));
  EXPECT_THAT(stages_->cleanups, ElementsAre(false));
  EXPECT_EQ(Stored().state, JobState::kCancelled);
}

TEST_F(JobRunnerTest, AStoppingCoordinatorLeavesTheJobForTheNextOne) {
  stages_->carve = [this](const JobRecord&) {
    stages_->stopping = true;
    return absl::CancelledError("coordinator stopping");
  };
  EXPECT_EQ(Run(), JobState::kCarving);
  EXPECT_THAT(stages_->cleanups, IsEmpty());
  EXPECT_EQ(Stored().state, JobState::kCarving);
  // The next coordinator: carving goes on (no second ingest), then the merge.
  stages_ = std::make_unique<FakeStages>(*store_);
  EXPECT_EQ(Run(), JobState::kSucceeded);
  EXPECT_THAT(stages_->calls, ElementsAre("carve", "merge"));
  EXPECT_THAT(stages_->cleanups, ElementsAre(true));
}

TEST_F(JobRunnerTest, ARestartDuringIngestCarvesWhenTheTasksAreStored) {
  StoreState(JobState::kIngesting);
  ASSERT_TRUE(store_->AddChunks("j-1", std::vector<ChunkRecord>(1)).ok());
  EXPECT_EQ(Run(), JobState::kSucceeded);
  EXPECT_THAT(stages_->calls, ElementsAre("carve", "merge"));
  EXPECT_EQ(stages_->moves.front(), "INGESTING->CARVING");
}

TEST_F(JobRunnerTest, ARestartDuringIngestWithoutTasksIngestsAgain) {
  StoreState(JobState::kIngesting);
  EXPECT_EQ(Run(), JobState::kSucceeded);
  EXPECT_THAT(stages_->calls, ElementsAre("ingest", "carve", "merge"));
}

TEST_F(JobRunnerTest, ARestartDuringTheMergeMergesAgain) {
  StoreState(JobState::kMerging);
  EXPECT_EQ(Run(), JobState::kSucceeded);
  EXPECT_THAT(stages_->calls, ElementsAre("merge"));
  EXPECT_THAT(stages_->entered, ElementsAre("merge"));
}

TEST_F(JobRunnerTest, AnEndedJobIsOnlyCleanedUp) {
  StoreState(JobState::kCancelled);
  EXPECT_EQ(Run(), JobState::kCancelled);
  EXPECT_THAT(stages_->calls, IsEmpty());
  EXPECT_THAT(stages_->cleanups, ElementsAre(false));
}

TEST_F(JobRunnerTest, AnUnknownJobIsNotFound) {
  EXPECT_TRUE(absl::IsNotFound(RunJob("j-2", *store_, *stages_, clock_).status()));
  EXPECT_THAT(stages_->calls, IsEmpty());
}

}  // namespace
}  // namespace carvemap
