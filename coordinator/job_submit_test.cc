#include "coordinator/job_submit.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/match.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

class JobSubmitTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    root_ = (fs::path(::testing::TempDir()) / ("job_submit_" + std::string(info->name()))).string();
    fs::remove_all(root_);
    fs::create_directories(root_ + "/data/acme");
    fs::create_directories(root_ + "/data/beta");
    std::ofstream(root_ + "/data/acme/scan.h5") << "a scan";
    auto store = JobStore::Open(root_ + "/jobs.db");
    ASSERT_TRUE(store.ok()) << store.status();
    store_ = *std::move(store);
  }
  SubmitContext Context() {
    return {.store = store_.get(),
            .folders = CoordinatorFolders::Of(root_ + "/data", root_ + "/out", "", root_ + "/work"),
            .max_jobs_per_tenant = 2,
            .now_unix_ms = 1'700'000'000'000,
            .new_job_id = [this] { return "j-new-" + std::to_string(++ids_); },
            .server_note = [this](const std::string& note) { notes_.push_back(note); }};
  }
  static SubmitRequest Request(const std::string& input = "scan.h5") {
    return {.tenant = "acme", .tenant_dir = "acme", .input_path = input};
  }
  std::string root_;
  std::unique_ptr<JobStore> store_;
  int ids_ = 0;
  std::vector<std::string> notes_;
};

TEST_F(JobSubmitTest, StoresAQueuedJobWithItsFoldersMade) {
  SubmitRequest req = Request();
  req.output_name = "office";
  absl::StatusOr<SubmitOutcome> out = SubmitJob(req, Context());
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_FALSE(out->deduplicated);
  EXPECT_EQ(out->job.id, "j-new-1");
  EXPECT_EQ(out->job.state, JobState::kQueued);
  EXPECT_EQ(out->job.tenant, "acme");
  EXPECT_EQ(out->job.output_name, "office");
  EXPECT_EQ(out->job.created_unix_ms, 1'700'000'000'000);
  EXPECT_TRUE(absl::StrContains(out->job.params_json, "0.0625"));  // the resolved default
  EXPECT_TRUE(fs::is_directory(root_ + "/out/acme/office"));
  // Without a name the output folder is the job's id.
  absl::StatusOr<SubmitOutcome> second = SubmitJob(Request(), Context());
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_EQ(second->job.output_name, second->job.id);
}

TEST_F(JobSubmitTest, BadRequestsAreRefusedBeforeAnythingIsMade) {
  const auto code = [&](const SubmitRequest& req) { return SubmitJob(req, Context()).status(); };
  EXPECT_TRUE(absl::IsInvalidArgument(code(Request("../beta/scan.h5"))));
  EXPECT_TRUE(absl::IsInvalidArgument(code(Request("/etc/passwd"))));
  EXPECT_TRUE(absl::IsInvalidArgument(code(Request(".uploads/u-1.partial"))));
  EXPECT_TRUE(absl::IsNotFound(code(Request("missing.h5"))));
  SubmitRequest req = Request();
  req.output_name = "a/b";
  EXPECT_TRUE(absl::IsInvalidArgument(code(req)));
  req = Request();
  req.params.resolution_m = 0.1;
  EXPECT_TRUE(absl::IsInvalidArgument(code(req)));
  req = Request();
  req.idempotency_key = std::string(129, 'k');
  EXPECT_TRUE(absl::IsInvalidArgument(code(req)));
  EXPECT_FALSE(fs::exists(root_ + "/out"));
}

TEST_F(JobSubmitTest, AKeyGivesTheFirstJobBackOrRefusesAnotherRequest) {
  SubmitRequest req = Request();
  req.idempotency_key = "run-1";
  absl::StatusOr<SubmitOutcome> first = SubmitJob(req, Context());
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_EQ(first->job.id.rfind("j-", 0), 0u);
  EXPECT_NE(first->job.id, "j-new-1");  // derived from the tenant and the key
  absl::StatusOr<SubmitOutcome> again = SubmitJob(req, Context());
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->deduplicated);
  EXPECT_EQ(again->job.id, first->job.id);
  req.params.resolution_m = 0.03125;
  EXPECT_TRUE(absl::IsAlreadyExists(SubmitJob(req, Context()).status()));
  // The same key of another tenant is another job.
  std::ofstream(root_ + "/data/beta/scan.h5") << "b";
  SubmitRequest beta = Request();
  beta.tenant = beta.tenant_dir = "beta";
  beta.idempotency_key = "run-1";
  absl::StatusOr<SubmitOutcome> other = SubmitJob(beta, Context());
  ASSERT_TRUE(other.ok()) << other.status();
  EXPECT_NE(other->job.id, first->job.id);
}

TEST_F(JobSubmitTest, ATakenNameOrTheTenantsLimitLeavesNoFolderBehind) {
  SubmitRequest req = Request();
  req.output_name = "office";
  ASSERT_TRUE(SubmitJob(req, Context()).ok());
  absl::StatusOr<SubmitOutcome> taken = SubmitJob(req, Context());
  EXPECT_TRUE(absl::IsAlreadyExists(taken.status())) << taken.status();
  EXPECT_TRUE(absl::StrContains(taken.status().message(), "used by another job"));
  req.output_name = "second";
  ASSERT_TRUE(SubmitJob(req, Context()).ok());
  req.output_name = "third";  // max_jobs_per_tenant 2
  EXPECT_TRUE(absl::IsResourceExhausted(SubmitJob(req, Context()).status()));
  EXPECT_FALSE(fs::exists(root_ + "/out/acme/third"));
}

TEST_F(JobSubmitTest, AnOutputRootThatCannotBeMadeIsSaidToTheServerOnly) {
  fs::create_directories(root_ + "/out");
  std::ofstream(root_ + "/out/acme") << "a file where the tenant's folder goes";
  absl::StatusOr<SubmitOutcome> out = SubmitJob(Request(), Context());
  EXPECT_TRUE(absl::IsFailedPrecondition(out.status())) << out.status();
  EXPECT_EQ(out.status().message(), "the output root is not writable");
  ASSERT_EQ(notes_.size(), 1u);
  EXPECT_TRUE(absl::StrContains(notes_[0], root_ + "/out/acme")) << notes_[0];
}

}  // namespace
}  // namespace carvemap
