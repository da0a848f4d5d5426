// The merge service and the coordinator's client of it (services/rpc/merge_service.h,
// merge_client.h; proto/carvemap/v1/merge.proto): real servers on 127.0.0.1:0, driven by
// RemoteMerge exactly as the coordinator drives them, with merge functions that stand in for
// RunMerge where a test needs to control the merge (its progress, its re-carve requests, when
// it ends). The whole job through real processes, with the service SIGKILLed mid-merge, is
// tests/tools/fault_test.py's merge-kill.
#include "services/rpc/merge_service.h"

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/notification.h"
#include "absl/time/time.h"
#include "proto/carvemap/v1/merge.grpc.pb.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/merge_client.h"
#include "tests/support/grpc_probe.h"

namespace carvemap {
namespace {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kSecret[] = "cluster-secret-0123456789abcdef";

std::string Address(const MergeServer& server) {
  return "127.0.0.1:" + std::to_string(server.port());
}

// A request as the coordinator makes it; progress collects the stages it is told.
struct Recorder {
  std::mutex mu;
  std::vector<std::string> stages;
  std::atomic<int> calls{0};
  bool Progress(const std::string& stage) {
    ++calls;
    std::lock_guard<std::mutex> lock(mu);
    if (stages.empty() || stages.back() != stage) stages.push_back(stage);
    return true;
  }
  std::vector<std::string> Stages() {
    std::lock_guard<std::mutex> lock(mu);
    return stages;
  }
};

MergeJobRequest Request(const fs::path& out, Recorder* recorder = nullptr) {
  MergeJobRequest req;
  req.job_id = "j-test";
  req.tiles_dir = (out / "tiles").string();
  req.output_dir = out.string();
  req.params = {.resolution_m = 0.0625,
                .object_resolution_m = 0.03125,
                .floorplan_method = "eigencrust",
                .trimmed_points = true,
                .min_object_volume_m3 = 0.002,
                .world_yaw_rad = -0.25};
  req.job_json = R"({"job_id": "j-test"})";
  if (recorder != nullptr) {
    req.progress = [recorder](const std::string& stage, uint64_t, uint64_t) {
      return recorder->Progress(stage);
    };
  }
  return req;
}

MergeFunction Remote(std::vector<std::string> addresses, const std::string& secret = kSecret,
                     int attempts = 3, double connect_timeout_s = 10, double retry_delay_s = 0) {
  MergeClientSpec spec;
  spec.addresses = std::move(addresses);
  spec.security.bearer = secret;
  spec.attempts = attempts;
  spec.connect_timeout_s = connect_timeout_s;
  spec.retry_delay_s = retry_delay_s;
  absl::StatusOr<MergeFunction> f = RemoteMerge(spec);
  EXPECT_TRUE(f.ok()) << f.status();
  return f.ok() ? *f : MergeFunction();
}

// A region of depth 7 (the largest, 256 KiB encoded) with cells set in a pattern of `seed`.
ChunkRegion PatternRegion(int seed) {
  std::vector<Eigen::Vector3i> cells;
  for (int i = 0; i < 2000; ++i) {
    cells.emplace_back((i * 7 + seed) % 128, (i * 13 + 3 * seed) % 128, (i * 31 + seed) % 128);
  }
  return ChunkRegion(7, cells);
}

class MergeServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::path(::testing::TempDir()) /
            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(root_);
    fs::create_directories(root_ / "out");
  }
  std::unique_ptr<MergeServer> Start(MergeFunction merge, const std::string& secret = kSecret) {
    MergeServerSpec spec;
    spec.cluster_secret = secret;
    spec.merge = std::move(merge);
    absl::StatusOr<std::unique_ptr<MergeServer>> server = MergeServer::Start(spec);
    EXPECT_TRUE(server.ok()) << server.status();
    return server.ok() ? *std::move(server) : nullptr;
  }
  fs::path root_;
};

// ---- security

// A raw call with `auth` ("" = none): the status the stream ends with, and whether a
// MergeResult came.
std::pair<grpc::Status, bool> RawCall(const std::string& address, const std::string& auth) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  auto stub = pb::MergeService::NewStub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  if (!auth.empty()) ctx.AddMetadata("authorization", auth);
  auto stream = stub->Merge(&ctx);
  pb::MergeClientMessage start;
  start.mutable_start()->set_job_id("j-raw");
  start.mutable_start()->set_tiles_dir("/nonexistent/tiles");
  start.mutable_start()->set_output_dir("/nonexistent/out");
  stream->Write(start);
  stream->WritesDone();
  bool result = false;
  pb::MergeServerMessage msg;
  while (stream->Read(&msg)) result = result || msg.has_result();
  return {stream->Finish(), result};
}

TEST_F(MergeServiceTest, TheClusterSecretIsRequired) {
  std::atomic<int> merges{0};
  auto server = Start([&](const MergeJobRequest&) {
    ++merges;
    return absl::OkStatus();
  });
  ASSERT_NE(server, nullptr);
  for (const std::string& auth :
       {std::string(""), std::string("Bearer wrong-secret-0123456789abcdef"),
        std::string("Bearer ") + kSecret + "x", std::string("Basic ") + kSecret}) {
    SCOPED_TRACE(auth);
    auto [status, result] = RawCall(Address(*server), auth);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED) << status.error_message();
    EXPECT_THAT(status.error_message(), HasSubstr("cluster secret"));
    EXPECT_THAT(status.error_message(), Not(HasSubstr("0123456789abcdef")));  // not echoed
    EXPECT_FALSE(result);
  }
  EXPECT_EQ(merges, 0);
  auto [status, result] = RawCall(Address(*server), std::string("Bearer ") + kSecret);
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_TRUE(result);
  EXPECT_EQ(merges, 1);

  // The coordinator's side with a wrong secret: refused at once, not retried, the reason kept.
  const auto t0 = std::chrono::steady_clock::now();
  absl::Status s = Remote({Address(*server)}, "wrong-secret-0123456789abcdef", /*attempts=*/3,
                          /*connect_timeout_s=*/10, /*retry_delay_s=*/20)(Request(root_ / "out"));
  EXPECT_EQ(s.code(), absl::StatusCode::kUnauthenticated) << s;
  EXPECT_THAT(s.message(), HasSubstr("refused the merge"));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(15));  // no retry delay
  EXPECT_EQ(merges, 1);
}

TEST_F(MergeServiceTest, HealthAndReflectionNeedNoSecret) {
  auto server = Start([](const MergeJobRequest&) { return absl::OkStatus(); });
  ASSERT_NE(server, nullptr);
  auto channel = grpc::CreateChannel(Address(*server), grpc::InsecureChannelCredentials());
  auto [status, response] = testing::HealthCheck(channel);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response, testing::kHealthServing);
  EXPECT_EQ(testing::HealthCheck(channel, "carvemap.v1.MergeService").second,
            testing::kHealthServing);
  EXPECT_THAT(testing::ReflectionListServices(channel), HasSubstr("carvemap.v1.MergeService"));
}

TEST_F(MergeServiceTest, StartRefusesAnOpenServiceOffLoopback) {
  MergeServerSpec spec;
  spec.listen_address = "0.0.0.0:0";
  absl::StatusOr<std::unique_ptr<MergeServer>> server = MergeServer::Start(spec);
  ASSERT_FALSE(server.ok());
  EXPECT_EQ(server.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(server.status().message(), HasSubstr("--cluster-secret-file"));
  spec.cluster_secret = "short";
  EXPECT_EQ(MergeServer::Start(spec).status().code(), absl::StatusCode::kInvalidArgument);
  spec.cluster_secret = kSecret;
  server = MergeServer::Start(spec);
  EXPECT_TRUE(server.ok()) << server.status();
}

TEST_F(MergeServiceTest, MutualTlsAuthenticatesTheCoordinator) {
  const fs::path pki = root_ / "pki";
  const std::string cmd = absl::StrCat("bash ", CARVEMAP_SOURCE_DIR,
                                       "/tests/tools/make_test_pki.sh ", pki.string());
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::atomic<int> merges{0};
  MergeServerSpec spec;
  spec.tls_cert_file = (pki / "server.crt").string();
  spec.tls_key_file = (pki / "server.key").string();
  spec.tls_client_ca_file = (pki / "ca.crt").string();
  spec.merge = [&](const MergeJobRequest&) {
    ++merges;
    return absl::OkStatus();
  };
  absl::StatusOr<std::unique_ptr<MergeServer>> server = MergeServer::Start(spec);
  ASSERT_TRUE(server.ok()) << server.status();
  auto merge_with = [&](const std::string& cert) {
    MergeClientSpec c;
    c.addresses = {"localhost:" + std::to_string((*server)->port())};
    c.security.ca_file = (pki / "ca.crt").string();
    if (!cert.empty()) {
      c.security.cert_file = (pki / (cert + ".crt")).string();
      c.security.key_file = (pki / (cert + ".key")).string();
    }
    c.attempts = 1;
    c.connect_timeout_s = 5;
    absl::StatusOr<MergeFunction> f = RemoteMerge(c);
    if (!f.ok()) return f.status();
    return (*f)(Request(root_ / "out"));
  };
  EXPECT_TRUE(merge_with("worker").ok());  // a client certificate of the cluster's CA
  EXPECT_EQ(merges, 1);
  absl::Status s = merge_with("");  // TLS without a certificate or a secret
  EXPECT_EQ(s.code(), absl::StatusCode::kUnauthenticated) << s;
  EXPECT_EQ(merges, 1);
}

// ---- the merge over the stream

TEST_F(MergeServiceTest, ProgressFlowsAndTheMergesOwnFailureIsFinal) {
  std::atomic<int> merges{0};
  MergeJobRequest seen;
  auto server = Start([&](const MergeJobRequest& req) -> absl::Status {
    ++merges;
    seen = req;
    for (const char* stage : {"boundary_faces", "planar_regions", "dense_mesh"}) {
      for (int i = 0; i <= 3; ++i) {
        if (!req.progress(stage, i, 3)) return absl::CancelledError("stop");
      }
    }
    return absl::DataLossError("merge dense_mesh: tiles/c_0_0_0.h5: corrupt");
  });
  ASSERT_NE(server, nullptr);
  Recorder recorder;
  MergeJobRequest req = Request(root_ / "out", &recorder);
  req.scan_root = (root_ / "data").string();
  req.scan_input = "sim/scan.h5";
  absl::Status s = Remote({Address(*server)})(req);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_EQ(s.message(), "merge dense_mesh: tiles/c_0_0_0.h5: corrupt");
  EXPECT_EQ(merges, 1);  // a verdict is not retried
  // Before the service's stages: "connect" while the client reaches it.
  EXPECT_THAT(recorder.Stages(),
              ElementsAre("connect", "boundary_faces", "planar_regions", "dense_mesh"));
  // What the service got is what the coordinator sent.
  EXPECT_EQ(seen.job_id, "j-test");
  EXPECT_EQ(seen.tiles_dir, req.tiles_dir);
  EXPECT_EQ(seen.output_dir, req.output_dir);
  EXPECT_EQ(seen.scan_root, req.scan_root);
  EXPECT_EQ(seen.scan_input, "sim/scan.h5");
  EXPECT_EQ(seen.params, req.params);  // every parameter across the wire
  EXPECT_EQ(seen.job_json, req.job_json);
  EXPECT_EQ(seen.attempt, 1);
  EXPECT_FALSE(seen.recarve);  // the request offered none
}

TEST_F(MergeServiceTest, CancellingTheCallStopsTheMerge) {
  absl::Notification stopped;
  std::atomic<int> steps{0};
  auto server = Start([&](const MergeJobRequest& req) -> absl::Status {
    // A long stage reporting every 20 ms; it runs until told to stop.
    for (int i = 0; i < 100000; ++i) {
      if (!req.progress("dense_mesh", i, 100000)) {
        stopped.Notify();
        return absl::CancelledError("merge cancelled during dense_mesh");
      }
      ++steps;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return absl::OkStatus();
  });
  ASSERT_NE(server, nullptr);
  // The job is cancelled 0.5 s after the merge started (as the coordinator's progress says
  // once the job is terminal).
  std::atomic<bool> cancel{false};
  MergeJobRequest req = Request(root_ / "out");
  req.progress = [&](const std::string& stage, uint64_t, uint64_t) {
    return !cancel.load();
  };
  std::thread canceller([&] {
    while (steps < 5) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    cancel = true;
  });
  const auto t0 = std::chrono::steady_clock::now();
  absl::Status s = Remote({Address(*server)})(req);
  canceller.join();
  EXPECT_EQ(s.code(), absl::StatusCode::kCancelled) << s;
  // The service's merge saw the stop within a few of its steps.
  EXPECT_TRUE(stopped.WaitForNotificationWithTimeout(absl::Seconds(10)));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
}

TEST_F(MergeServiceTest, CancellingAlsoWorksBetweenReports) {
  // The merge reports once, then works for a long time without a report (a stage without
  // progress calls): the client's own ticks still cancel the call, and the merge stops at its
  // next report.
  absl::Notification reported, stopped;
  auto server = Start([&](const MergeJobRequest& req) -> absl::Status {
    req.progress("planar_regions", 0, 1);
    reported.Notify();
    const auto start = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - start < std::chrono::seconds(3)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (!req.progress("planar_regions", 1, 1)) {
      stopped.Notify();
      return absl::CancelledError("stopped");
    }
    return absl::OkStatus();
  });
  ASSERT_NE(server, nullptr);
  MergeJobRequest req = Request(root_ / "out");
  req.progress = [&](const std::string&, uint64_t, uint64_t) {
    return !reported.HasBeenNotified();
  };
  const auto t0 = std::chrono::steady_clock::now();
  absl::Status s = Remote({Address(*server)})(req);
  EXPECT_EQ(s.code(), absl::StatusCode::kCancelled) << s;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(2500));
  EXPECT_TRUE(stopped.WaitForNotificationWithTimeout(absl::Seconds(10)));
}

// §5.6.1 across the stream: the service's request (12 chunks at the finest region depth,
// 3 MiB: several parts) reaches the coordinator's `recarve` intact; its answer, or its
// failure, comes back to the merge.
TEST_F(MergeServiceTest, RecarveRoundTrip) {
  std::vector<RecarveChunk> asked;
  for (int i = 0; i < 12; ++i) {
    asked.push_back(RecarveChunk::Of(ChunkKey(i, -i, 2 * i), PatternRegion(i)));
  }
  absl::StatusOr<std::string> first = absl::UnknownError("not called");
  absl::StatusOr<std::string> second = absl::UnknownError("not called");
  auto server = Start([&](const MergeJobRequest& req) -> absl::Status {
    if (!req.recarve) return absl::InternalError("no recarve");
    first = req.recarve(asked, 0.0078125);
    second = req.recarve({asked[0]}, 0.015625);
    return absl::OkStatus();
  });
  ASSERT_NE(server, nullptr);
  std::vector<std::pair<std::vector<RecarveChunk>, double>> got;
  MergeJobRequest req = Request(root_ / "out");
  req.recarve = [&](const std::vector<RecarveChunk>& chunks,
                    double resolution_m) -> absl::StatusOr<std::string> {
    got.emplace_back(chunks, resolution_m);
    if (got.size() == 1) return (root_ / "out" / "object_tiles").string();
    return absl::NotFoundError("chunk (0,0,0): attempt 3 of 3 failed: worker w-1: no tile");
  };
  absl::Status s = Remote({Address(*server)})(req);
  ASSERT_TRUE(s.ok()) << s;
  ASSERT_EQ(got.size(), 2u);
  ASSERT_EQ(got[0].first.size(), asked.size());
  EXPECT_DOUBLE_EQ(got[0].second, 0.0078125);
  for (size_t i = 0; i < asked.size(); ++i) {
    EXPECT_EQ(got[0].first[i].chunk, asked[i].chunk);
    EXPECT_EQ(got[0].first[i].depth, 7);
    EXPECT_EQ(got[0].first[i].cells, asked[i].cells);
  }
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_EQ(*first, (root_ / "out" / "object_tiles").string());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(second.status().message(), HasSubstr("attempt 3 of 3 failed"));
}

// A region whose bits do not fit their depth is refused where it arrives, naming its chunk,
// and never reaches the coordinator's `recarve`.
TEST_F(MergeServiceTest, RecarveRefusesARegionThatDoesNotDecode) {
  std::vector<RecarveChunk> asked = {RecarveChunk::Of(ChunkKey(1, 2, 0), PatternRegion(1)),
                                     RecarveChunk::Of(ChunkKey(3, -4, 5), PatternRegion(2))};
  asked[1].cells.resize(asked[1].cells.size() / 2);
  absl::StatusOr<std::string> answer = absl::UnknownError("not called");
  auto server = Start([&](const MergeJobRequest& req) -> absl::Status {
    answer = req.recarve(asked, 0.0078125);
    return absl::OkStatus();
  });
  ASSERT_NE(server, nullptr);
  int called = 0;
  MergeJobRequest req = Request(root_ / "out");
  req.recarve = [&](const std::vector<RecarveChunk>&, double) -> absl::StatusOr<std::string> {
    ++called;
    return (root_ / "out" / "object_tiles").string();
  };
  absl::Status s = Remote({Address(*server)})(req);
  ASSERT_TRUE(s.ok()) << s;
  EXPECT_EQ(called, 0);
  EXPECT_EQ(answer.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(answer.status().message(), HasSubstr("RecarveRequest chunk (3,-4,5)"));
  EXPECT_THAT(answer.status().message(), HasSubstr("bytes for depth 7"));
}

// A merge service lost mid-merge (here shut down; tests/tools/fault_test.py SIGKILLs one):
// the merge runs again on the next service, and the object chunks already carved again for
// the lost attempt are not carved a second time.
TEST_F(MergeServiceTest, ALostServiceIsRetriedOnTheNext) {
  const std::vector<RecarveChunk> asked = {RecarveChunk::Of(ChunkKey(1, 2, 0), PatternRegion(1)),
                                           RecarveChunk::Of(ChunkKey(2, 2, 0), PatternRegion(2))};
  absl::Notification in_first;
  std::atomic<int> first_attempt{0}, second_attempt{0};
  auto a = Start([&](const MergeJobRequest& req) -> absl::Status {
    first_attempt = req.attempt;
    absl::StatusOr<std::string> dir = req.recarve(asked, 0.03125);
    if (!dir.ok()) return dir.status();
    in_first.Notify();
    while (req.progress("object_mesh", 0, 1)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return absl::CancelledError("merge cancelled during object_mesh");
  });
  auto b = Start([&](const MergeJobRequest& req) -> absl::Status {
    second_attempt = req.attempt;
    absl::StatusOr<std::string> dir = req.recarve(asked, 0.03125);
    if (!dir.ok()) return dir.status();
    req.progress("job_json", 1, 1);
    return absl::OkStatus();
  });
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  std::thread killer([&] {
    in_first.WaitForNotification();
    a->Shutdown();
  });
  std::atomic<int> recarves{0};
  Recorder recorder;
  MergeJobRequest req = Request(root_ / "out", &recorder);
  req.recarve = [&](const std::vector<RecarveChunk>&, double) -> absl::StatusOr<std::string> {
    ++recarves;
    return (root_ / "out" / "object_tiles").string();
  };
  absl::Status s = Remote({Address(*a), Address(*b)})(req);
  killer.join();
  EXPECT_TRUE(s.ok()) << s;
  EXPECT_EQ(first_attempt, 1);
  EXPECT_EQ(second_attempt, 2);
  EXPECT_EQ(recarves, 1);
  const std::vector<std::string> stages = recorder.Stages();
  EXPECT_NE(std::find(stages.begin(), stages.end(), "reconnect"), stages.end());
  EXPECT_EQ(stages.back(), "job_json");
}

TEST_F(MergeServiceTest, NoServiceLeftFailsWithTheReasonAndNoTemporaryFiles) {
  // A port nobody serves: a server started and stopped.
  std::string address;
  {
    auto gone = Start([](const MergeJobRequest&) { return absl::OkStatus(); });
    ASSERT_NE(gone, nullptr);
    address = Address(*gone);
  }
  // What an interrupted merge leaves: complete files, temporary ones, its scratch folder.
  const fs::path out = root_ / "out";
  fs::create_directories(out / "mesh");
  fs::create_directories(out / ".segment" / "objects");
  std::ofstream(out / "levels.json") << "[]\n";
  std::ofstream(out / "mesh" / "dense.ply.partial") << "half";
  std::ofstream(out / ".segment" / "objects" / "c_0_0_0.h5") << "scratch";
  absl::Status s =
      Remote({address}, kSecret, /*attempts=*/2, /*connect_timeout_s=*/0.5)(Request(out));
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << s;
  EXPECT_THAT(s.message(), HasSubstr("lost 2 time(s)"));
  EXPECT_THAT(s.message(), HasSubstr("not reachable within 0.5 s"));
  EXPECT_THAT(s.message(), HasSubstr("no job.json"));
  EXPECT_TRUE(fs::exists(out / "levels.json"));
  EXPECT_FALSE(fs::exists(out / "mesh" / "dense.ply.partial"));
  EXPECT_FALSE(fs::exists(out / ".segment"));
}

TEST_F(MergeServiceTest, OneMergeAtATime) {
  std::atomic<int> running{0}, most{0};
  absl::Notification release;
  auto server = Start([&](const MergeJobRequest& req) -> absl::Status {
    const int now = ++running;
    most = std::max(most.load(), now);
    while (!release.WaitForNotificationWithTimeout(absl::Milliseconds(20))) {
      if (!req.progress("dense_mesh", 0, 1)) break;
    }
    --running;
    return absl::OkStatus();
  });
  ASSERT_NE(server, nullptr);
  MergeFunction merge = Remote({Address(*server)});
  Recorder r1, r2;
  absl::Status s1, s2;
  std::thread t1([&] { s1 = merge(Request(root_ / "out", &r1)); });
  std::thread t2([&] { s2 = merge(Request(root_ / "out2", &r2)); });
  // One of the two waits, and says so.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  auto queued = [](Recorder& r) {
    const auto s = r.Stages();
    return std::find(s.begin(), s.end(), "queued") != s.end();
  };
  while (!queued(r1) && !queued(r2) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(queued(r1) || queued(r2));
  release.Notify();
  t1.join();
  t2.join();
  EXPECT_TRUE(s1.ok()) << s1;
  EXPECT_TRUE(s2.ok()) << s2;
  EXPECT_EQ(most, 1);
}

}  // namespace
}  // namespace carvemap
