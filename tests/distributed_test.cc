// Cross-service test: a real coordinator, a real worker and a real merge
// service on 127.0.0.1:0 in this process, talked to over gRPC as a client would. The process-level
// behaviour (`carvemap run`, a SIGKILLed worker, bad jobs) is tests/tools/distributed_test.sh.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "proto/carvemap/v1/jobs.grpc.pb.h"
#include "services/rpc/coordinator_service.h"
#include "services/rpc/job_client.h"
#include "services/rpc/merge_client.h"
#include "services/rpc/merge_service.h"
#include "services/rpc/worker_service.h"
#include "services/sim/simulator.h"
#include "storage/tile_store.h"

namespace carvemap {
namespace {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;

class DistributedTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::path(::testing::TempDir()) /
            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(root_);
    fs::create_directories(root_ / "data");
    CoordinatorSpec spec;
    spec.data_root = (root_ / "data").string();
    spec.output_root = (root_ / "out").string();
    spec.heartbeat_interval_s = 0.5;
    spec.worker_timeout_s = 2;
    // The merge runs on a merge service (here in this process, over gRPC on loopback, as
    // `carvemap coordinator --merge-server` calls `carvemap merger`). A test may look into
    // the merge's request first (merge_hook_, on the service's side), then the real merge runs.
    MergeServerSpec merge_spec;
    merge_spec.merge = [this](const MergeJobRequest& req) -> absl::Status {
      if (merge_hook_) {
        if (absl::Status s = merge_hook_(req); !s.ok()) return s;
      }
      return LocalMerge()(req);
    };
    auto merger = MergeServer::Start(merge_spec);
    ASSERT_TRUE(merger.ok()) << merger.status();
    merger_ = *std::move(merger);
    MergeClientSpec client;
    client.addresses = {"127.0.0.1:" + std::to_string(merger_->port())};
    auto remote = RemoteMerge(client);
    ASSERT_TRUE(remote.ok()) << remote.status();
    spec.merge = *std::move(remote);
    spec.merge_in_process = false;
    auto server = CoordinatorServer::Start(spec);
    ASSERT_TRUE(server.ok()) << server.status();
    coordinator_ = *std::move(server);
    address_ = "127.0.0.1:" + std::to_string(coordinator_->port());
    channel_ = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
    jobs_ = pb::JobService::NewStub(channel_);
    carve_ = pb::CarveTaskService::NewStub(channel_);
  }

  // A small scan: the `room` preset with thinned scanners and a short walk.
  std::string SimulateScan() {
    SimulateOptions options;
    options.preset = "room";
    options.output_dir = (root_ / "data" / "sim").string();
    options.rig.rate_hz = 5;
    options.rig.beam_step_deg = 2;
    options.max_duration_s = 8;
    auto summary = Simulate(options, {});
    EXPECT_TRUE(summary.ok()) << summary.status();
    return "sim/scan.h5";
  }

  // The scan of SimulateScan as the job "room".
  static absl::StatusOr<JobInfo> SubmitRoom(JobClient& client, const std::string& scan) {
    SubmitParams params;
    params.input_path = scan;
    params.output_name = "room";
    return client.Submit(params);
  }

  fs::path root_;
  std::function<absl::Status(const MergeJobRequest&)> merge_hook_;
  std::unique_ptr<MergeServer> merger_;  // outlives the coordinator (declared first)
  std::unique_ptr<CoordinatorServer> coordinator_;
  std::string address_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::JobService::Stub> jobs_;
  std::unique_ptr<pb::CarveTaskService::Stub> carve_;
};

TEST_F(DistributedTest, SubmitValidates) {
  auto submit = [&](const std::string& path, double resolution, double object_resolution = 0,
                    const std::string& floorplan = "", double min_object_volume = 0) {
    grpc::ClientContext ctx;
    pb::SubmitJobRequest req;
    req.set_input_path(path);
    req.mutable_params()->set_resolution_m(resolution);
    req.mutable_params()->set_object_resolution_m(object_resolution);
    req.mutable_params()->set_floorplan_method(floorplan);
    req.mutable_params()->set_min_object_volume_m3(min_object_volume);
    pb::SubmitJobResponse resp;
    return jobs_->SubmitJob(&ctx, req, &resp).error_code();
  };
  EXPECT_EQ(submit("/etc/passwd", 0), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("../x.h5", 0), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("missing.h5", 0), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(submit("missing.h5", 0.1), grpc::StatusCode::INVALID_ARGUMENT);
  // §5.6.1's object resolution: 2 m / 2^k, not coarser than the job's, not below 0.78 cm.
  EXPECT_EQ(submit("missing.h5", 0.03125, 0.0625), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("missing.h5", 0, 0.02), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("missing.h5", 0, 0.00390625), grpc::StatusCode::INVALID_ARGUMENT);
  // The floor-plan method is checked at submit, not after the carving (§3.2 / §3.3 names).
  EXPECT_EQ(submit("missing.h5", 0, 0, "graphcut"), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("missing.h5", 0, 0, "eigencrust"), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(submit("missing.h5", 0, 0.0625), grpc::StatusCode::NOT_FOUND);  // = no second pass
  // §5.6's speck volume: ≥ 0 and finite.
  EXPECT_EQ(submit("missing.h5", 0, 0, "", -0.001), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("missing.h5", 0, 0, "", std::nan("")), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(submit("missing.h5", 0, 0, "", 0.01), grpc::StatusCode::NOT_FOUND);

  grpc::ClientContext ctx;
  pb::GetJobRequest get;
  get.set_job_id("j-nope");
  pb::Job job;
  EXPECT_EQ(jobs_->GetJob(&ctx, get, &job).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(DistributedTest, CarveTaskErrors) {
  {
    grpc::ClientContext ctx;
    pb::HeartbeatRequest req;
    req.set_worker_id("w-unknown");
    pb::HeartbeatResponse resp;
    EXPECT_EQ(carve_->Heartbeat(&ctx, req, &resp).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  std::string worker_id;
  {
    grpc::ClientContext ctx;
    pb::RegisterWorkerRequest req;
    pb::RegisterWorkerResponse resp;
    ASSERT_TRUE(carve_->RegisterWorker(&ctx, req, &resp).ok());
    worker_id = resp.worker_id();
    EXPECT_FALSE(worker_id.empty());
    EXPECT_DOUBLE_EQ(resp.heartbeat_interval_s(), 0.5);
  }
  {
    grpc::ClientContext ctx;
    pb::LeaseChunkRequest req;
    req.set_worker_id(worker_id);
    pb::LeaseChunkResponse resp;
    ASSERT_TRUE(carve_->LeaseChunk(&ctx, req, &resp).ok());
    EXPECT_FALSE(resp.has_lease());
    EXPECT_GT(resp.retry_after_s(), 0);
  }
  {
    grpc::ClientContext ctx;
    pb::CompleteChunkRequest req;
    req.set_worker_id(worker_id);
    req.set_lease_id("not a lease id");
    pb::CompleteChunkResponse resp;
    EXPECT_EQ(carve_->CompleteChunk(&ctx, req, &resp).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
  }
  {
    grpc::ClientContext ctx;
    pb::CompleteChunkRequest req;
    req.set_worker_id(worker_id);
    req.set_lease_id("j-nope/0,0,0/1");
    req.set_generation(1);
    pb::CompleteChunkResponse resp;
    EXPECT_EQ(carve_->CompleteChunk(&ctx, req, &resp).error_code(), grpc::StatusCode::NOT_FOUND);
  }
}

TEST_F(DistributedTest, JobRunsToSucceededWithAWorker) {
  const std::string scan = SimulateScan();
  WorkerSpec ws;
  ws.coordinator_address = address_;
  auto worker = WorkerServer::Start(ws);
  ASSERT_TRUE(worker.ok()) << worker.status();

  JobClient client(address_);
  SubmitParams params;
  params.input_path = scan;
  params.output_name = "room";
  params.idempotency_key = "k1";
  auto job = client.Submit(params);
  ASSERT_TRUE(job.ok()) << job.status();
  // The same key and request: the same job, not a new one.
  auto again = client.Submit(params);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->job_id, job->job_id);

  int updates = 0;
  auto done = client.Watch(job->job_id, 0.2, [&](const WatchUpdate&) { ++updates; });
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->state, "SUCCEEDED") << done->error;
  EXPECT_GT(done->chunks_total, 0);
  EXPECT_EQ(done->chunks_done, done->chunks_total);
  EXPECT_GE(updates, 2);
  const fs::path out = root_ / "out" / "room";
  EXPECT_TRUE(fs::exists(out / "job.json"));
  EXPECT_TRUE(fs::exists(out / "octree.bt"));
  int tiles = 0;
  for (const auto& e : fs::directory_iterator(out / "tiles")) tiles += e.path().extension() == ".h5";
  // The job's tasks: its time slices (job.json "carve"), one chunk per tile, and the slices
  // of the merge's re-carve (§5.6.1), when the merge asked for one.
  std::ifstream in(out / "job.json");
  const nlohmann::json doc = nlohmann::json::parse(in, nullptr, false);
  ASSERT_TRUE(doc.is_object());
  const int slices = doc["carve"].value("slices", -1);
  EXPECT_GE(slices, 1);
  const bool recarved = doc["counts"].value("recarved_chunks", 0) > 0;
  EXPECT_EQ(tiles + slices * (recarved ? 2 : 1), done->chunks_total);
  EXPECT_GT(doc["carve"].value("rays", 0), 0);
  EXPECT_EQ(doc["carve"].value("rays", 0), doc.value("rays_carved", -1));

  // Fetch checks the server's SHA-256.
  const fs::path fetched = root_ / "fetched.json";
  ASSERT_TRUE(client.Fetch(job->job_id, "job.json", fetched.string()).ok());
  EXPECT_EQ(fs::file_size(fetched), fs::file_size(out / "job.json"));
  // A finished job cannot be cancelled.
  EXPECT_TRUE(absl::IsFailedPrecondition(client.Cancel(job->job_id, "").status()));
  (*worker)->Shutdown();
}

// A lease the coordinator grants under a worker's id that never reaches the worker (its lease
// call gave up waiting, or the answer was lost) is given back through the worker's own
// heartbeats, which list the leases it holds; the job does not wait on it for ever.
TEST_F(DistributedTest, ALeaseTheWorkerNeverReceivedIsGivenBack) {
  const std::string scan = SimulateScan();
  JobClient client(address_);
  auto job = SubmitRoom(client, scan);
  ASSERT_TRUE(job.ok()) << job.status();
  WorkerSpec ws;
  ws.coordinator_address = address_;
  auto worker = WorkerServer::Start(ws);
  ASSERT_TRUE(worker.ok()) << worker.status();
  std::string id;
  for (int i = 0; i < 200 && id.empty(); ++i) {
    id = (*worker)->worker_id();
    if (id.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_FALSE(id.empty());
  // A task leased in the worker's name, as if its own call had timed out before the answer.
  std::string stolen;
  for (int i = 0; i < 100 && stolen.empty(); ++i) {
    pb::LeaseChunkRequest req;
    req.set_worker_id(id);
    req.set_wait_s(0.2);
    pb::LeaseChunkResponse resp;
    grpc::ClientContext ctx;
    ASSERT_TRUE(carve_->LeaseChunk(&ctx, req, &resp).ok());
    if (resp.has_lease()) stolen = resp.lease().lease_id();
  }
  ASSERT_FALSE(stolen.empty());
  // Its heartbeats extend every lease it lists; this one it does not list, so it goes back
  // to the queue at once (the lease timeout is 30 s, which heartbeats would keep pushing on).
  const auto t0 = std::chrono::steady_clock::now();
  std::string state;
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(120)) {
    auto status = client.Get(job->job_id);
    ASSERT_TRUE(status.ok()) << status.status();
    state = status->state;
    if (state == "SUCCEEDED" || state == "FAILED" || state == "CANCELLED") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  EXPECT_EQ(state, "SUCCEEDED") << "lease " << stolen << " was never given back";
  (*worker)->Shutdown();
}

// §5.6.1: during the merge, chunks go to the workers once more at a finer resolution, into
// <job dir>/object_tiles; the job's own tiles and counters are as before afterwards. The
// request goes from the merge service to the coordinator on the merge's stream and the
// answer comes back on it (MergeService's RecarveRequest/RecarveResult).
TEST_F(DistributedTest, MergeCarvesChunksAgainFinerThroughTheWorkers) {
  const std::string scan = SimulateScan();
  WorkerSpec ws;
  ws.coordinator_address = address_;
  auto worker = WorkerServer::Start(ws);
  ASSERT_TRUE(worker.ok()) << worker.status();

  // Looked at inside the merge, before the real merge's own pass replaces object_tiles.
  std::vector<RecarveChunk> again;
  absl::StatusOr<std::string> dir = absl::UnknownError("recarve not called");
  std::vector<std::pair<double, size_t>> fine_tiles;    // resolution, leaves
  std::vector<std::pair<double, size_t>> coarse_tiles;  // the job's tile of the same chunk
  std::vector<int> fine_above, coarse_above;             // leaves in the chunk's upper half
  double object_resolution = 0;
  merge_hook_ = [&](const MergeJobRequest& req) -> absl::Status {
    object_resolution = req.params.object_resolution_m;
    for (const auto& e : fs::directory_iterator(req.tiles_dir)) {
      absl::StatusOr<TileData> tile = ReadTile(e.path().string());
      if (tile.ok() && tile->chunk.z() == 0 && tile->params.num_wedges > 100 && again.size() < 3) {
        // The first two whole (the one cell of depth 0), the third only in its lower half.
        again.push_back(RecarveChunk::Of(
            tile->chunk, again.size() < 2 ? ChunkRegion(0, {{0, 0, 0}})
                                          : ChunkRegion(1, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0},
                                                            {1, 1, 0}})));
      }
    }
    if (!req.recarve) return absl::InternalError("no recarve in the merge request");
    dir = req.recarve(again, 0.03125);
    if (!dir.ok()) return absl::OkStatus();
    for (const RecarveChunk& c : again) {
      for (auto [folder, list] : {std::pair{*dir, &fine_tiles},
                                  std::pair{req.tiles_dir, &coarse_tiles}}) {
        absl::StatusOr<TileData> t =
            ReadTile((fs::path(folder) / TileFileName(c.chunk)).string());
        if (!t.ok()) continue;
        list->emplace_back(t->grid.resolution_m(), t->leaves.size());
        // Observed leaves above the region's half (local z ≥ 1 m).
        int above = 0;
        for (const TileLeaf& leaf : t->leaves) {
          above += NodeBox(t->grid, c.chunk, leaf.node).min().z() >= c.chunk.z() * 2.0 + 1.0;
        }
        (list == &fine_tiles ? fine_above : coarse_above).push_back(above);
      }
    }
    return absl::OkStatus();
  };
  JobClient client(address_);
  auto job = SubmitRoom(client, scan);
  ASSERT_TRUE(job.ok()) << job.status();
  auto done = client.Watch(job->job_id, 0.2, [](const WatchUpdate&) {});
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->state, "SUCCEEDED") << done->error;
  EXPECT_DOUBLE_EQ(object_resolution, 0.03125);  // the default: half of 6.25 cm
  ASSERT_TRUE(dir.ok()) << dir.status();
  EXPECT_EQ(fs::path(*dir), root_ / "out" / "room" / "object_tiles");
  ASSERT_EQ(again.size(), 3u);
  ASSERT_EQ(fine_tiles.size(), 3u);
  ASSERT_EQ(coarse_tiles.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_DOUBLE_EQ(fine_tiles[i].first, 0.03125);
    EXPECT_DOUBLE_EQ(coarse_tiles[i].first, 0.0625);  // the job's tiles stay
  }
  // Whole chunks: more leaves at the finer grid. The third: nothing carved above its region.
  EXPECT_GT(fine_tiles[0].second, coarse_tiles[0].second);
  EXPECT_GT(fine_tiles[1].second, coarse_tiles[1].second);
  EXPECT_GT(coarse_above[2], 0);
  EXPECT_EQ(fine_above[2], 0);
  EXPECT_GT(fine_tiles[2].second, 0u);
  EXPECT_EQ(done->chunks_done, done->chunks_total);
  (*worker)->Shutdown();
}

}  // namespace
}  // namespace carvemap
