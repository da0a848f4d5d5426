// Security of the public job API and the internal carve-task API (docs/DESIGN.md §8): a
// real coordinator on 127.0.0.1:0 with bearer tokens for two tenants and a cluster secret,
// real workers where a job must run, talked to over gRPC as a client would. Every refusal is
// checked with its exact status, and its message for what it must not say: another tenant's
// job looks exactly like a job that does not exist, a path outside the tenant's folder reads
// the same whether it exists or not, no message names the server's folders. TLS and mutual
// TLS use a throw-away CA made at test time (tests/tools/make_test_pki.sh).
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "proto/carvemap/v1/jobs.grpc.pb.h"
#include "services/rpc/coordinator_service.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/grpc_status.h"
#include "services/rpc/job_client.h"
#include "services/rpc/worker_service.h"
#include "tests/support/grpc_probe.h"
#include "tests/support/thin_room_scan.h"

namespace carvemap {
namespace {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kAcme[] = "acme-token-0123456789abcdef0123";
constexpr char kBeta[] = "beta-token-0123456789abcdef0123";
constexpr char kSecret[] = "cluster-secret-0123456789abcdef";
constexpr char kGhostJob[] = "j-20991231-abcdef";  // no such job, anywhere

std::string Bearer(const std::string& token) { return "Bearer " + token; }

class SecurityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::path(::testing::TempDir()) /
            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(root_);
    for (const char* d : {"data/acme", "data/beta", "outside/dir", "out"}) {
      fs::create_directories(root_ / d);
    }
    // Junk "scans": enough for a submit (the file exists and is readable); their jobs fail
    // at ingest, which the isolation tests do not mind.
    std::ofstream(root_ / "data/acme/junk.h5") << "not hdf5";
    std::ofstream(root_ / "data/beta/junk.h5") << "not hdf5";
    std::ofstream(root_ / "data/beta/private.h5") << "beta's own scan";
    std::ofstream(root_ / "outside/secret.h5") << "outside the data root";
    std::ofstream(root_ / "outside/dir/x.h5") << "outside too";
  }
  void TearDown() override {
    if (coordinator_ != nullptr) coordinator_->Shutdown();
  }

  CoordinatorSpec Spec() {
    CoordinatorSpec spec;
    spec.data_root = (root_ / "data").string();
    spec.output_root = (root_ / "out").string();
    spec.heartbeat_interval_s = 0.5;
    spec.worker_timeout_s = 2;
    spec.tokens = {{kAcme, "acme"}, {kBeta, "beta"}};
    spec.cluster_secret = kSecret;
    spec.merge = LocalMerge();
    return spec;
  }
  void Start(CoordinatorSpec spec) {
    auto server = CoordinatorServer::Start(std::move(spec));
    ASSERT_TRUE(server.ok()) << server.status();
    coordinator_ = *std::move(server);
    address_ = "127.0.0.1:" + std::to_string(coordinator_->port());
    channel_ = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
    jobs_ = pb::JobService::NewStub(channel_);
    carve_ = pb::CarveTaskService::NewStub(channel_);
  }

  // Calls with `auth` as the authorization metadata ("" = none).
  static std::unique_ptr<grpc::ClientContext> Ctx(const std::string& auth) {
    auto ctx = std::make_unique<grpc::ClientContext>();
    ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    if (!auth.empty()) ctx->AddMetadata("authorization", auth);
    return ctx;
  }
  grpc::Status Submit(const std::string& auth, const std::string& input,
                      const std::string& output_name = "", pb::SubmitJobResponse* out = nullptr,
                      const std::string& key = "") {
    pb::SubmitJobRequest req;
    req.set_input_path(input);
    req.set_output_name(output_name);
    req.set_idempotency_key(key);
    pb::SubmitJobResponse resp;
    grpc::Status s = jobs_->SubmitJob(Ctx(auth).get(), req, &resp);
    if (out != nullptr) *out = resp;
    return s;
  }
  grpc::Status Get(const std::string& auth, const std::string& id, pb::Job* out = nullptr) {
    pb::GetJobRequest req;
    req.set_job_id(id);
    pb::Job job;
    grpc::Status s = jobs_->GetJob(Ctx(auth).get(), req, &job);
    if (out != nullptr) *out = job;
    return s;
  }
  grpc::Status Watch(const std::string& auth, const std::string& id) {
    pb::WatchJobRequest req;
    req.set_job_id(id);
    auto ctx = Ctx(auth);
    auto reader = jobs_->WatchJob(ctx.get(), req);
    pb::JobEvent e;
    while (reader->Read(&e)) {
    }
    return reader->Finish();
  }
  grpc::Status Cancel(const std::string& auth, const std::string& id) {
    pb::CancelJobRequest req;
    req.set_job_id(id);
    pb::CancelJobResponse resp;
    return jobs_->CancelJob(Ctx(auth).get(), req, &resp);
  }
  grpc::Status List(const std::string& auth, pb::ListJobsResponse* out = nullptr) {
    pb::ListJobsRequest req;
    pb::ListJobsResponse resp;
    grpc::Status s = jobs_->ListJobs(Ctx(auth).get(), req, &resp);
    if (out != nullptr) *out = resp;
    return s;
  }
  grpc::Status Fetch(const std::string& auth, const std::string& id, const std::string& name,
                     std::string* data = nullptr) {
    pb::FetchArtifactRequest req;
    req.set_job_id(id);
    req.set_name(name);
    auto ctx = Ctx(auth);
    auto reader = jobs_->FetchArtifact(ctx.get(), req);
    pb::ArtifactChunk chunk;
    std::string got;
    while (reader->Read(&chunk)) got += chunk.data();
    if (data != nullptr) *data = got;
    return reader->Finish();
  }
  grpc::Status Register(const std::string& auth) {
    pb::RegisterWorkerRequest req;
    pb::RegisterWorkerResponse resp;
    return carve_->RegisterWorker(Ctx(auth).get(), req, &resp);
  }
  std::string SubmitOk(const std::string& token, const std::string& input,
                       const std::string& output_name) {
    pb::SubmitJobResponse resp;
    grpc::Status s = Submit(Bearer(token), input, output_name, &resp);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return resp.job().job_id();
  }
  // The root of this test's files must not appear in anything a client is told.
  void ExpectNoServerPaths(const grpc::Status& s) {
    EXPECT_THAT(s.error_message(), Not(HasSubstr(root_.string()))) << s.error_message();
    EXPECT_THAT(s.error_message(), Not(HasSubstr("outside/"))) << s.error_message();
  }

  fs::path root_;
  std::unique_ptr<CoordinatorServer> coordinator_;
  std::string address_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::JobService::Stub> jobs_;
  std::unique_ptr<pb::CarveTaskService::Stub> carve_;
};

// ---- authentication

TEST_F(SecurityTest, EveryJobCallWithoutAValidTokenIsUnauthenticated) {
  Start(Spec());
  const std::string id = SubmitOk(kAcme, "junk.h5", "a");
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"", "missing bearer token"},
      {Bearer("wrong-token-0123456789abcdef0123"), "invalid bearer token"},
      {Bearer(std::string(kAcme) + "x"), "invalid bearer token"},
      {"Basic YWNtZTpwYXNzd29yZA==", "invalid bearer token"},
      {"Bearer", "invalid bearer token"},
      // The cluster secret is for workers, not a tenant's token.
      {Bearer(kSecret), "invalid bearer token"},
  };
  for (const auto& [auth, want] : bad) {
    SCOPED_TRACE(auth);
    std::vector<grpc::Status> all = {Submit(auth, "junk.h5", "b"), Get(auth, id),
                                     Watch(auth, id),              Cancel(auth, id),
                                     List(auth),                   Fetch(auth, id, "job.json")};
    for (const grpc::Status& s : all) {
      EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << s.error_message();
      EXPECT_THAT(s.error_message(), HasSubstr(want));
      EXPECT_THAT(s.error_message(), Not(HasSubstr("0123456789abcdef")));  // no token echoed
      EXPECT_THAT(s.error_message(), Not(HasSubstr(id)));
    }
  }
  // Nothing happened: no second job, the first one not cancelled.
  pb::ListJobsResponse list;
  ASSERT_TRUE(List(Bearer(kAcme), &list).ok());
  ASSERT_EQ(list.jobs_size(), 1);
  EXPECT_NE(list.jobs(0).state(), pb::JOB_STATE_CANCELLED) << list.jobs(0).error();
}

TEST_F(SecurityTest, HealthAndReflectionNeedNoToken) {
  Start(Spec());
  auto [status, response] = testing::HealthCheck(channel_);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response, testing::kHealthServing);
  EXPECT_EQ(testing::HealthCheck(channel_, "carvemap.v1.JobService").second,
            testing::kHealthServing);
  EXPECT_THAT(testing::ReflectionListServices(channel_), HasSubstr("carvemap.v1.JobService"));
}

// ---- tenants

TEST_F(SecurityTest, AnotherTenantsJobLooksExactlyLikeNoJob) {
  Start(Spec());
  const std::string id = SubmitOk(kAcme, "junk.h5", "shared-name");
  using Call = std::function<grpc::Status(const std::string&)>;
  const std::vector<std::pair<std::string, Call>> calls = {
      {"GetJob", [&](const std::string& j) { return Get(Bearer(kBeta), j); }},
      {"WatchJob", [&](const std::string& j) { return Watch(Bearer(kBeta), j); }},
      {"CancelJob", [&](const std::string& j) { return Cancel(Bearer(kBeta), j); }},
      {"FetchArtifact", [&](const std::string& j) { return Fetch(Bearer(kBeta), j, "job.json"); }},
  };
  for (const auto& [name, call] : calls) {
    SCOPED_TRACE(name);
    const grpc::Status theirs = call(id);
    const grpc::Status none = call(kGhostJob);
    EXPECT_EQ(theirs.error_code(), grpc::StatusCode::NOT_FOUND) << theirs.error_message();
    EXPECT_EQ(none.error_code(), grpc::StatusCode::NOT_FOUND) << none.error_message();
    // Byte for byte the same answer, but for the id the caller sent itself.
    EXPECT_EQ(theirs.error_message(),
              absl::StrReplaceAll(none.error_message(), {{kGhostJob, id}}));
    EXPECT_THAT(theirs.error_message(), Not(HasSubstr("acme")));
  }
  // Lists are per tenant; beta's cancel did not touch acme's job.
  pb::ListJobsResponse beta_list, acme_list;
  ASSERT_TRUE(List(Bearer(kBeta), &beta_list).ok());
  EXPECT_EQ(beta_list.jobs_size(), 0);
  ASSERT_TRUE(List(Bearer(kAcme), &acme_list).ok());
  ASSERT_EQ(acme_list.jobs_size(), 1);
  EXPECT_EQ(acme_list.jobs(0).tenant(), "acme");
  pb::Job job;
  ASSERT_TRUE(Get(Bearer(kAcme), id, &job).ok());
  EXPECT_NE(job.state(), pb::JOB_STATE_CANCELLED);
  // Output names and idempotency keys are per tenant: the same ones give beta its own job,
  // in its own folder.
  pb::SubmitJobResponse a, b;
  ASSERT_TRUE(Submit(Bearer(kAcme), "junk.h5", "keyed", &a, "same-key").ok());
  ASSERT_TRUE(Submit(Bearer(kBeta), "junk.h5", "keyed", &b, "same-key").ok());
  EXPECT_NE(a.job().job_id(), b.job().job_id());
  EXPECT_FALSE(b.deduplicated());
  ASSERT_TRUE(Submit(Bearer(kBeta), "junk.h5", "shared-name").ok());
  EXPECT_TRUE(fs::is_directory(root_ / "out/acme/shared-name"));
  EXPECT_TRUE(fs::is_directory(root_ / "out/beta/shared-name"));
}

// ---- paths

TEST_F(SecurityTest, InputPathsStayInTheTenantsFolder) {
  Start(Spec());
  const fs::path acme = root_ / "data/acme";
  fs::create_symlink(root_ / "outside/secret.h5", acme / "abs_exists.h5");
  fs::create_symlink(root_ / "outside/missing.h5", acme / "abs_missing.h5");
  fs::create_symlink("../../outside/secret.h5", acme / "rel_exists.h5");
  fs::create_symlink("../../outside/missing.h5", acme / "rel_missing.h5");
  fs::create_symlink("../beta/private.h5", acme / "sib_exists.h5");  // another tenant's
  fs::create_symlink("../beta/missing.h5", acme / "sib_missing.h5");
  fs::create_symlink(root_ / "outside/dir", acme / "dir_out");
  fs::create_symlink("junk.h5", acme / "inside_link.h5");

  // Malformed: decided from the text alone (an absolute path is refused even inside).
  for (const std::string& p :
       {std::string("../beta/private.h5"), std::string("sub/../../beta/private.h5"),
        (acme / "junk.h5").string(), std::string("/etc/passwd"), std::string(""),
        std::string(2000, 'a')}) {
    const grpc::Status s = Submit(Bearer(kAcme), p);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << p << ": " << s.error_message();
    if (p.find(root_.string()) == std::string::npos) ExpectNoServerPaths(s);
  }
  // Symlinks leading out: PERMISSION_DENIED, the same message whether the target exists.
  for (const auto& [exists, missing] :
       std::vector<std::pair<std::string, std::string>>{{"abs_exists.h5", "abs_missing.h5"},
                                                        {"rel_exists.h5", "rel_missing.h5"},
                                                        {"sib_exists.h5", "sib_missing.h5"},
                                                        {"dir_out/x.h5", "dir_out/none.h5"}}) {
    const grpc::Status a = Submit(Bearer(kAcme), exists);
    const grpc::Status b = Submit(Bearer(kAcme), missing);
    EXPECT_EQ(a.error_code(), grpc::StatusCode::PERMISSION_DENIED) << a.error_message();
    EXPECT_EQ(b.error_code(), grpc::StatusCode::PERMISSION_DENIED) << b.error_message();
    EXPECT_EQ(a.error_message(), absl::StrReplaceAll(b.error_message(), {{missing, exists}}));
    ExpectNoServerPaths(a);
    EXPECT_THAT(a.error_message(), Not(HasSubstr("beta")));
  }
  // A file of beta's, named as if it were acme's own: just not there.
  const grpc::Status theirs = Submit(Bearer(kAcme), "private.h5");
  EXPECT_EQ(theirs.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(theirs.error_message(), "input_path 'private.h5': no such file");
  // Nothing was submitted by any of these.
  pb::ListJobsResponse list;
  ASSERT_TRUE(List(Bearer(kAcme), &list).ok());
  EXPECT_EQ(list.jobs_size(), 0);
  // A link that stays inside is fine.
  EXPECT_FALSE(SubmitOk(kAcme, "inside_link.h5", "linked").empty());
}

TEST_F(SecurityTest, ArtifactsStayInTheJobsFolder) {
  Start(Spec());
  const std::string id = SubmitOk(kAcme, "junk.h5", "res");
  const fs::path out = root_ / "out/acme/res";
  ASSERT_TRUE(fs::is_directory(out));
  std::ofstream(out / "notes.txt") << "acme's notes";
  fs::create_symlink(root_ / "outside/secret.h5", out / "leak");
  fs::create_symlink(root_ / "outside/missing.h5", out / "leak_missing");
  fs::create_directories(out / ".carvemap");
  std::ofstream(out / ".carvemap/tokens") << kAcme << " acme\n";

  std::string data;
  ASSERT_TRUE(Fetch(Bearer(kAcme), id, "notes.txt", &data).ok());
  EXPECT_EQ(data, "acme's notes");
  const grpc::Status a = Fetch(Bearer(kAcme), id, "leak", &data);
  const grpc::Status b = Fetch(Bearer(kAcme), id, "leak_missing");
  EXPECT_EQ(a.error_code(), grpc::StatusCode::PERMISSION_DENIED) << a.error_message();
  EXPECT_EQ(b.error_code(), grpc::StatusCode::PERMISSION_DENIED) << b.error_message();
  EXPECT_EQ(a.error_message(), absl::StrReplaceAll(b.error_message(), {{"leak_missing", "leak"}}));
  EXPECT_TRUE(data.empty());
  ExpectNoServerPaths(a);
  for (const char* name : {"../res/notes.txt", "/etc/passwd", ".carvemap/tokens"}) {
    const grpc::Status s = Fetch(Bearer(kAcme), id, name);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << name;
    ExpectNoServerPaths(s);
  }
  EXPECT_EQ(Fetch(Bearer(kBeta), id, "notes.txt").error_code(), grpc::StatusCode::NOT_FOUND);
}

// An output folder planted as a link out of the tenant's output folder is not written to.
TEST_F(SecurityTest, OutputFolderCannotBeALinkOut) {
  Start(Spec());
  fs::create_directories(root_ / "out/acme");
  fs::create_symlink(root_ / "outside/dir", root_ / "out/acme/planted");
  const grpc::Status s = Submit(Bearer(kAcme), "junk.h5", "planted");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED) << s.error_message();
  ExpectNoServerPaths(s);
  EXPECT_FALSE(fs::exists(root_ / "outside/dir/tiles"));
}

// ---- limits

TEST_F(SecurityTest, OversizeRequestsAreResourceExhausted) {
  CoordinatorSpec spec = Spec();
  spec.max_request_bytes = 64 << 10;
  Start(spec);
  const std::string huge(100 << 10, 'a');
  for (const std::string& auth : {std::string(), Bearer(kAcme)}) {
    const grpc::Status s = Submit(auth, "junk.h5", huge);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
    EXPECT_THAT(s.error_message(), Not(HasSubstr("aaaa")));
  }
  pb::HeartbeatRequest hb;
  hb.set_worker_id("w-1");
  for (int i = 0; i < 2000; ++i) hb.add_active_lease_ids(std::string(64, 'x'));
  pb::HeartbeatResponse hr;
  EXPECT_EQ(carve_->Heartbeat(Ctx(Bearer(kSecret)).get(), hb, &hr).error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  // Under the limit the request reaches the handler, which has its own field limits.
  const grpc::Status key = Submit(Bearer(kAcme), "junk.h5", "k", nullptr, std::string(32 << 10, 'k'));
  EXPECT_EQ(key.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << key.error_message();
  pb::CancelJobRequest cancel;
  cancel.set_job_id(SubmitOk(kAcme, "junk.h5", "c"));
  cancel.set_reason(std::string(2000, 'r'));
  pb::CancelJobResponse cr;
  EXPECT_EQ(jobs_->CancelJob(Ctx(Bearer(kAcme)).get(), cancel, &cr).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(SecurityTest, UnfinishedJobsPerTenantAreLimited) {
  absl::StatusOr<std::string> scan =
      testing::SimulateThinRoomScan((root_ / "data/acme/sim").string(), 1);
  ASSERT_TRUE(scan.ok()) << scan.status();
  CoordinatorSpec spec = Spec();
  spec.max_jobs_per_tenant = 1;
  Start(spec);
  // No worker: the job stays unfinished (CARVING) until cancelled.
  const std::string first = SubmitOk(kAcme, "sim/scan.h5", "first");
  const grpc::Status second = Submit(Bearer(kAcme), "sim/scan.h5", "second");
  EXPECT_EQ(second.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << second.error_message();
  EXPECT_THAT(second.error_message(), HasSubstr("limit is 1"));
  EXPECT_THAT(second.error_message(), Not(HasSubstr(first)));
  EXPECT_FALSE(fs::exists(root_ / "out/acme/second"));  // a refused submit leaves nothing
  // Another tenant has its own allowance.
  EXPECT_FALSE(SubmitOk(kBeta, "junk.h5", "b").empty());
  // A finished job no longer counts.
  ASSERT_TRUE(Cancel(Bearer(kAcme), first).ok());
  const std::string third = SubmitOk(kAcme, "sim/scan.h5", "second");
  EXPECT_FALSE(third.empty());
  ASSERT_TRUE(Cancel(Bearer(kAcme), third).ok());
}

// ---- the internal carve-task API

TEST_F(SecurityTest, CarveTaskApiNeedsTheClusterSecret) {
  Start(Spec());
  for (const std::string& auth :
       {std::string(), Bearer(kAcme), Bearer("cluster-secret-0123456789abcdeX"),
        std::string("Basic Y2x1c3Rlcg==")}) {
    SCOPED_TRACE(auth);
    const grpc::Status reg = Register(auth);
    EXPECT_EQ(reg.error_code(), grpc::StatusCode::UNAUTHENTICATED) << reg.error_message();
    EXPECT_THAT(reg.error_message(), Not(HasSubstr(kSecret)));
    pb::HeartbeatRequest hb;
    hb.set_worker_id("w-1");
    pb::HeartbeatResponse hr;
    EXPECT_EQ(carve_->Heartbeat(Ctx(auth).get(), hb, &hr).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
    pb::LeaseChunkRequest lr;
    lr.set_worker_id("w-1");
    pb::LeaseChunkResponse lresp;
    EXPECT_EQ(carve_->LeaseChunk(Ctx(auth).get(), lr, &lresp).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
    pb::CompleteChunkRequest cr;
    cr.set_lease_id("j-x/0,0,0/1");
    pb::CompleteChunkResponse cresp;
    EXPECT_EQ(carve_->CompleteChunk(Ctx(auth).get(), cr, &cresp).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
    pb::FailChunkRequest fr;
    fr.set_lease_id("j-x/0,0,0/1");
    pb::FailChunkResponse fresp;
    EXPECT_EQ(carve_->FailChunk(Ctx(auth).get(), fr, &fresp).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  EXPECT_TRUE(Register(Bearer(kSecret)).ok());
  // A real worker with the wrong secret ends at once with the reason, instead of retrying.
  for (const std::string& secret : {std::string(), std::string("wrong-secret-0123456789abcdef")}) {
    WorkerSpec ws;
    ws.coordinator_address = address_;
    ws.listen_address = "";
    ws.security.bearer = secret;
    auto worker = WorkerServer::Start(ws);
    ASSERT_TRUE(worker.ok()) << worker.status();
    const absl::Status ended = (*worker)->Wait();
    EXPECT_EQ(ended.code(), absl::StatusCode::kUnauthenticated) << ended;
    (*worker)->Shutdown();
  }
}

// ---- start-up rules

TEST_F(SecurityTest, StartRefusesAnOpenServiceOffLoopback) {
  auto start = [&](const std::function<void(CoordinatorSpec&)>& change) {
    CoordinatorSpec spec = Spec();
    spec.listen_address = "0.0.0.0:0";
    change(spec);
    auto server = CoordinatorServer::Start(std::move(spec));
    if (server.ok()) (*server)->Shutdown();
    return server.status();
  };
  absl::Status s = start([](CoordinatorSpec& sp) { sp.tokens.clear(); });
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition) << s;
  EXPECT_THAT(s.message(), HasSubstr("--tokens"));
  EXPECT_THAT(s.message(), HasSubstr("--insecure"));
  s = start([](CoordinatorSpec& sp) { sp.cluster_secret.clear(); });
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition) << s;
  EXPECT_THAT(s.message(), HasSubstr("--cluster-secret-file"));
  EXPECT_TRUE(start([](CoordinatorSpec& sp) {
                sp.tokens.clear();
                sp.cluster_secret.clear();
                sp.insecure = true;
              }).ok());
  EXPECT_TRUE(start([](CoordinatorSpec&) {}).ok());
  // Configurations that cannot be right, anywhere.
  s = start([](CoordinatorSpec& sp) { sp.shared_dirs = true; });
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  s = start([](CoordinatorSpec& sp) { sp.cluster_secret = kBeta; });
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_THAT(s.message(), Not(HasSubstr(kBeta)));
  s = start([](CoordinatorSpec& sp) { sp.tls_client_ca_file = "/nonexistent/ca.crt"; });
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  // On loopback without tokens it runs open: every caller is tenant "default".
  CoordinatorSpec open = Spec();
  open.tokens.clear();
  open.cluster_secret.clear();
  Start(open);
  pb::SubmitJobResponse resp;
  ASSERT_TRUE(Submit("", "acme/junk.h5", "open", &resp).ok());
  EXPECT_EQ(resp.job().tenant(), "default");
  EXPECT_TRUE(fs::is_directory(root_ / "out/open"));  // shared roots
  EXPECT_TRUE(Register("").ok());
}

// ---- TLS, mutual TLS, and a whole job through them

class TlsSecurityTest : public SecurityTest {
 protected:
  void SetUp() override {
    SecurityTest::SetUp();
    pki_ = root_ / "pki";
    const std::string cmd = absl::StrCat("bash ", CARVEMAP_SOURCE_DIR,
                                         "/tests/tools/make_test_pki.sh ", pki_.string());
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  }
  std::string Pki(const char* name) { return (pki_ / name).string(); }
  CoordinatorSpec TlsSpec() {
    CoordinatorSpec spec = Spec();
    spec.tls_cert_file = Pki("server.crt");
    spec.tls_key_file = Pki("server.key");
    spec.health_listen_address = "127.0.0.1:0";
    return spec;
  }
  absl::Status ListWith(const ChannelSecurity& security, const std::string& address = "") {
    JobClient client(address.empty() ? "localhost:" + std::to_string(coordinator_->port())
                                     : address,
                     security);
    return client.List("", 10).status();
  }
  fs::path pki_;
};

TEST_F(TlsSecurityTest, TlsServesTheJobApi) {
  Start(TlsSpec());
  ChannelSecurity good;
  good.bearer = kAcme;
  good.ca_file = Pki("ca.crt");
  EXPECT_TRUE(ListWith(good).ok()) << ListWith(good);
  // By IP, with the name the certificate carries.
  ChannelSecurity named = good;
  named.server_name = "carvemap-coordinator";
  EXPECT_TRUE(ListWith(named, address_).ok()) << ListWith(named, address_);
  // Plaintext to a TLS port, or trusting another CA: no connection at all.
  ChannelSecurity plain;
  plain.bearer = kAcme;
  EXPECT_EQ(ListWith(plain).code(), absl::StatusCode::kUnavailable);
  ChannelSecurity wrong_ca = good;
  wrong_ca.ca_file = Pki("other-ca.crt");
  EXPECT_EQ(ListWith(wrong_ca).code(), absl::StatusCode::kUnavailable);
  // TLS alone is no tenant.
  ChannelSecurity anonymous = good;
  anonymous.bearer.clear();
  EXPECT_EQ(ListWith(anonymous).code(), absl::StatusCode::kUnauthenticated);
  // A bad file is named.
  ChannelSecurity missing = good;
  missing.ca_file = Pki("none.crt");
  absl::Status m = ListWith(missing);
  EXPECT_EQ(m.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(m.message(), HasSubstr("none.crt"));
  // The plaintext health port answers probes.
  ASSERT_GT(coordinator_->health_port(), 0);
  auto health = grpc::CreateChannel("127.0.0.1:" + std::to_string(coordinator_->health_port()),
                                    grpc::InsecureChannelCredentials());
  EXPECT_EQ(testing::HealthCheck(health).second, testing::kHealthServing);
}

TEST_F(TlsSecurityTest, StartNamesBadCertificateFiles) {
  CoordinatorSpec spec = TlsSpec();
  spec.tls_key_file = Pki("worker.key");  // not the certificate's key
  auto server = CoordinatorServer::Start(spec);
  ASSERT_FALSE(server.ok());
  EXPECT_THAT(server.status().message(), HasSubstr("does not belong to the certificate"));
  spec = TlsSpec();
  spec.tls_cert_file = Pki("ca.key");
  server = CoordinatorServer::Start(spec);
  ASSERT_FALSE(server.ok());
  EXPECT_THAT(server.status().message(), HasSubstr("ca.key: no PEM certificate"));
}

// Workers authenticated by client certificates instead of the secret; the job API over TLS
// with tokens; one whole job carved and merged through them, and its outputs only for acme.
TEST_F(TlsSecurityTest, AJobRunsThroughMutualTls) {
  absl::StatusOr<std::string> scan =
      testing::SimulateThinRoomScan((root_ / "data/acme/sim").string(), 2);
  ASSERT_TRUE(scan.ok()) << scan.status();
  CoordinatorSpec spec = TlsSpec();
  spec.cluster_secret.clear();
  spec.tls_client_ca_file = Pki("ca.crt");
  Start(spec);
  const std::string tls_address = "localhost:" + std::to_string(coordinator_->port());

  auto carve_stub = [&](const std::string& cert, const std::string& key) {
    ChannelSecurity s;
    s.ca_file = Pki("ca.crt");
    s.cert_file = cert;
    s.key_file = key;
    auto channel = MakeChannel(tls_address, s);
    EXPECT_TRUE(channel.ok()) << channel.status();
    return pb::CarveTaskService::NewStub(*channel);
  };
  pb::RegisterWorkerRequest req;
  pb::RegisterWorkerResponse resp;
  EXPECT_TRUE(carve_stub(Pki("worker.crt"), Pki("worker.key"))
                  ->RegisterWorker(Ctx("").get(), req, &resp)
                  .ok());
  EXPECT_EQ(carve_stub("", "")->RegisterWorker(Ctx("").get(), req, &resp).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  // A client certificate from another CA does not even get a connection.
  EXPECT_EQ(carve_stub(Pki("rogue.crt"), Pki("rogue.key"))
                ->RegisterWorker(Ctx("").get(), req, &resp)
                .error_code(),
            grpc::StatusCode::UNAVAILABLE);

  WorkerSpec ws;
  ws.coordinator_address = tls_address;
  ws.listen_address = "";
  ws.security.ca_file = Pki("ca.crt");
  ws.security.cert_file = Pki("worker.crt");
  ws.security.key_file = Pki("worker.key");
  auto worker = WorkerServer::Start(ws);
  ASSERT_TRUE(worker.ok()) << worker.status();

  ChannelSecurity acme;
  acme.bearer = kAcme;
  acme.ca_file = Pki("ca.crt");
  JobClient client(tls_address, acme);
  SubmitParams params;
  params.input_path = "sim/scan.h5";
  params.output_name = "room";
  params.object_resolution_m = 0.0625;  // no second pass: keep the test short
  auto job = client.Submit(params);
  ASSERT_TRUE(job.ok()) << job.status();
  auto done = client.Watch(job->job_id, 0.2, [](const WatchUpdate&) {});
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->state, "SUCCEEDED") << done->error;
  EXPECT_GT(done->chunks_total, 0);
  EXPECT_TRUE(fs::exists(root_ / "out/acme/room/job.json"));
  EXPECT_TRUE(fs::exists(root_ / "out/acme/room/octree.bt"));
  const fs::path fetched = root_ / "fetched.json";
  ASSERT_TRUE(client.Fetch(job->job_id, "job.json", fetched.string()).ok());
  EXPECT_EQ(fs::file_size(fetched), fs::file_size(root_ / "out/acme/room/job.json"));
  // job.json names the input as the tenant gave it, not the server's path.
  std::ifstream in(fetched);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_THAT(text, HasSubstr("\"input_path\": \"sim/scan.h5\""));
  EXPECT_THAT(text, Not(HasSubstr((root_ / "data").string())));
  ChannelSecurity beta = acme;
  beta.bearer = kBeta;
  JobClient other(tls_address, beta);
  EXPECT_EQ(other.Fetch(job->job_id, "job.json", (root_ / "stolen.json").string()).code(),
            absl::StatusCode::kNotFound);
  EXPECT_FALSE(fs::exists(root_ / "stolen.json"));
  (*worker)->Shutdown();
}

}  // namespace
}  // namespace carvemap
