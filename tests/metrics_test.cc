// The coordinator's Prometheus metrics (docs/DESIGN.md §8 "expose counters") read over
// HTTP as Prometheus would: a real coordinator on 127.0.0.1:0 with --metrics-listen, a lease left
// to expire by a worker that never heartbeats, then a real worker carving a whole job. The
// counters must agree with what the job itself reports (job.json, WatchJob), and the text
// must name no job and no tenant.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "services/rpc/coordinator_service.h"
#include "services/rpc/http_get.h"
#include "services/rpc/job_client.h"
#include "services/rpc/metrics_text.h"
#include "services/rpc/worker_service.h"
#include "tests/support/thin_room_scan.h"

namespace carvemap {
namespace {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kAcme[] = "acme-token-0123456789abcdef0123";
constexpr char kSecret[] = "cluster-secret-0123456789abcdef";

class MetricsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::path(::testing::TempDir()) /
            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(root_);
    fs::create_directories(root_ / "data/acme");
    CoordinatorSpec spec;
    spec.data_root = (root_ / "data").string();
    spec.output_root = (root_ / "out").string();
    spec.tokens = {{kAcme, "acme"}};
    spec.cluster_secret = kSecret;
    spec.heartbeat_interval_s = 0.2;
    spec.worker_timeout_s = 30;  // the silent worker below loses its lease by expiry, not loss
    spec.lease_timeout_s = 1;
    spec.sweep_interval_s = 0.1;
    spec.metrics_listen_address = "127.0.0.1:0";
    spec.merge = LocalMerge();
    auto server = CoordinatorServer::Start(spec);
    ASSERT_TRUE(server.ok()) << server.status();
    coordinator_ = *std::move(server);
    ASSERT_GT(coordinator_->metrics_port(), 0);
    address_ = "127.0.0.1:" + std::to_string(coordinator_->port());
    metrics_url_ = "127.0.0.1:" + std::to_string(coordinator_->metrics_port());
  }
  void TearDown() override {
    if (coordinator_ != nullptr) coordinator_->Shutdown();
  }
  std::vector<MetricSample> Scrape() {
    absl::StatusOr<std::string> text = HttpGet(metrics_url_, 5);
    EXPECT_TRUE(text.ok()) << text.status();
    if (!text.ok()) return {};
    last_text_ = *text;
    absl::StatusOr<std::vector<MetricSample>> samples = ParsePrometheusText(*text);
    EXPECT_TRUE(samples.ok()) << samples.status();
    return samples.ok() ? *samples : std::vector<MetricSample>{};
  }
  // Polls until `done` holds for a scrape (the gauges follow the sweeper).
  bool ScrapeUntil(const std::function<bool(const std::vector<MetricSample>&)>& done,
                   double timeout_s = 20) {
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::milliseconds(static_cast<int>(timeout_s * 1000));
    while (std::chrono::steady_clock::now() < end) {
      if (done(Scrape())) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
  }

  fs::path root_;
  std::unique_ptr<CoordinatorServer> coordinator_;
  std::string address_;
  std::string metrics_url_;
  std::string last_text_;
};

TEST_F(MetricsTest, CountersFollowAJobThroughExpiryAndCompletion) {
  // Before anything: the families exist, at zero.
  std::vector<MetricSample> s = Scrape();
  EXPECT_THAT(last_text_, HasSubstr("# TYPE carvemap_lease_expiries_total counter"));
  EXPECT_EQ(SumOf(s, "carvemap_workers"), 0);
  EXPECT_EQ(SumOf(s, "carvemap_lease_expiries_total"), 0);
  EXPECT_EQ(HttpGet("127.0.0.1:" + std::to_string(coordinator_->metrics_port()) + "/nothing", 5)
                .status()
                .code(),
            absl::StatusCode::kNotFound);

  // A refused call is counted.
  auto channel = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  auto carve = pb::CarveTaskService::NewStub(channel);
  {
    grpc::ClientContext ctx;
    pb::RegisterWorkerRequest req;
    pb::RegisterWorkerResponse resp;
    ASSERT_EQ(carve->RegisterWorker(&ctx, req, &resp).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  s = Scrape();
  EXPECT_EQ(SumOf(s, "carvemap_calls_unauthenticated_total", {{"api", "carve"}}), 1);
  EXPECT_EQ(SumOf(s, "carvemap_rpc_duration_seconds_count",
                  {{"method", "RegisterWorker"}, {"code", "UNAUTHENTICATED"}}),
            1);

  absl::StatusOr<std::string> scan =
      testing::SimulateThinRoomScan((root_ / "data/acme/sim").string(), 4);
  ASSERT_TRUE(scan.ok()) << scan.status();
  ChannelSecurity acme;
  acme.bearer = kAcme;
  JobClient client(address_, acme);
  SubmitParams params;
  params.input_path = "sim/scan.h5";
  params.output_name = "room";
  params.object_resolution_m = 0.0625;  // one pass: job.json's rays_carved covers all
  auto job = client.Submit(params);
  ASSERT_TRUE(job.ok()) << job.status();

  // A worker that takes a lease and then falls silent: the lease expires after 1 s.
  auto with_secret = [] {
    auto ctx = std::make_unique<grpc::ClientContext>();
    ctx->AddMetadata("authorization", std::string("Bearer ") + kSecret);
    return ctx;
  };
  std::string silent;
  {
    pb::RegisterWorkerRequest req;
    pb::RegisterWorkerResponse resp;
    ASSERT_TRUE(carve->RegisterWorker(with_secret().get(), req, &resp).ok());
    silent = resp.worker_id();
  }
  {
    pb::LeaseChunkRequest req;
    req.set_worker_id(silent);
    req.set_wait_s(20);  // the job is ingesting; wait for its chunks
    pb::LeaseChunkResponse resp;
    ASSERT_TRUE(carve->LeaseChunk(with_secret().get(), req, &resp).ok());
    ASSERT_TRUE(resp.has_lease());
  }
  ASSERT_TRUE(ScrapeUntil([](const auto& m) {
    return SumOf(m, "carvemap_lease_expiries_total") >= 1;
  })) << last_text_;
  s = Scrape();
  EXPECT_GT(SumOf(s, "carvemap_chunks", {{"state", "queued"}}), 0);
  EXPECT_EQ(SumOf(s, "carvemap_workers"), 1);
  EXPECT_EQ(SumOf(s, "carvemap_jobs_active"), 1);

  // A real worker carves everything.
  WorkerSpec ws;
  ws.coordinator_address = address_;
  ws.listen_address = "";
  ws.security.bearer = kSecret;
  auto worker = WorkerServer::Start(ws);
  ASSERT_TRUE(worker.ok()) << worker.status();
  auto done = client.Watch(job->job_id, 0.2, [](const WatchUpdate&) {});
  ASSERT_TRUE(done.ok()) << done.status();
  ASSERT_EQ(done->state, "SUCCEEDED") << done->error;
  (*worker)->Shutdown();

  ASSERT_TRUE(ScrapeUntil([](const auto& m) { return SumOf(m, "carvemap_jobs_active") == 0; }))
      << last_text_;
  s = Scrape();
  EXPECT_EQ(SumOf(s, "carvemap_jobs_submitted_total"), 1);
  EXPECT_EQ(SumOf(s, "carvemap_jobs_finished_total", {{"state", "SUCCEEDED"}}), 1);
  EXPECT_EQ(SumOf(s, "carvemap_chunks_completed_total"), done->chunks_total);
  EXPECT_EQ(SumOf(s, "carvemap_rpc_duration_seconds_count",
                  {{"method", "CompleteChunk"}, {"code", "OK"}}),
            done->chunks_total);
  EXPECT_EQ(SumOf(s, "carvemap_chunks"), 0);  // nothing left in the lease table
  // Rays: the same sum as the job's own count in job.json.
  std::ifstream in(root_ / "out/acme/room/job.json");
  const nlohmann::json doc = nlohmann::json::parse(in, nullptr, false);
  ASSERT_TRUE(doc.is_object());
  EXPECT_EQ(SumOf(s, "carvemap_rays_carved_total"), doc.value("rays_carved", -1.0));
  EXPECT_GT(SumOf(s, "carvemap_rays_carved_total"), 0);
  // Latencies are there for what the worker called.
  EXPECT_GT(SumOf(s, "carvemap_rpc_duration_seconds_count", {{"method", "LeaseChunk"}}), 0);
  EXPECT_FALSE(std::isnan(HistogramQuantile(s, "carvemap_rpc_duration_seconds", 0.5,
                                            {{"method", "CompleteChunk"}})));
  // Aggregates only: no job, no tenant, no path.
  EXPECT_THAT(last_text_, Not(HasSubstr(job->job_id)));
  EXPECT_THAT(last_text_, Not(HasSubstr("acme")));
  EXPECT_THAT(last_text_, Not(HasSubstr(root_.string())));
  // The same registry without HTTP.
  absl::StatusOr<std::vector<MetricSample>> direct =
      ParsePrometheusText(coordinator_->MetricsText());
  ASSERT_TRUE(direct.ok()) << direct.status();
  EXPECT_EQ(SumOf(*direct, "carvemap_chunks_completed_total"), done->chunks_total);
}

}  // namespace
}  // namespace carvemap
