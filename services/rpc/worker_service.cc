#include "services/rpc/worker_service.h"

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>

#include "absl/base/thread_annotations.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "absl/time/time.h"
#include "coordinator/scan_slices.h"
#include "geometry/octree_keys.h"
#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/grpc_server_common.h"
#include "services/rpc/grpc_status.h"
#include "services/rpc/process_metrics.h"
#include "services/rpc/server_log.h"
#include "services/rpc/worker_memory_policy.h"
#include "services/rpc/worker_metrics.h"
#include "services/system/process_memory.h"
#include "storage/confined_path.h"
#include "storage/file_hash.h"
#include "storage/hdf5_lock.h"
#include "storage/partial_sums.h"
#include "storage/scan_reader.h"
#include "worker/chunk_combiner.h"
#include "worker/slice_carver.h"

namespace carvemap {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;

namespace {

// How the log names a lease's task: "slice k" (of pass p for a re-carve) or "chunk (x,y,z)".
std::string TaskName(const pb::Lease& lease) {
  if (lease.has_slice()) {
    const pb::SliceTask& t = lease.slice();
    return t.pass() == 0 ? absl::StrCat("slice ", t.index())
                         : absl::StrCat("slice ", t.index(), " of pass ", t.pass());
  }
  return absl::StrCat("chunk (", lease.chunk().x(), ",", lease.chunk().y(), ",", lease.chunk().z(),
                      ")");
}

constexpr char kVersion[] = "0.1.0";
constexpr double kRpcTimeoutS = 10.0;

// A transient coordinator problem: retry, and count towards "gone for good".
bool IsTransient(const absl::Status& s) {
  return absl::IsUnavailable(s) || absl::IsDeadlineExceeded(s) || absl::IsAborted(s) ||
         absl::IsResourceExhausted(s);
}

// The indexes of partial sums files a worker combines chunks from: every chunk of a pass reads
// the same few dozen files' indexes, so they are read once (a file is written once, under its
// final name; a new pass writes other files). Thread-safe; bounded.
class PartialIndexCache {
 public:
  absl::StatusOr<PartialSumsIndex> Get(const std::string& path) {
    {
      absl::MutexLock lock(&mu_);
      if (auto it = cache_.find(path); it != cache_.end()) return it->second;
    }
    absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(path);
    if (!index.ok()) return index;
    absl::MutexLock lock(&mu_);
    if (cache_.size() >= kMaxEntries) cache_.clear();
    cache_.emplace(path, *index);
    return index;
  }

 private:
  static constexpr size_t kMaxEntries = 1024;
  absl::Mutex mu_;
  std::map<std::string, PartialSumsIndex> cache_ ABSL_GUARDED_BY(mu_);
};

std::string HostName() {
  char name[256] = {};
  if (gethostname(name, sizeof(name) - 1) != 0) return "unknown";
  return name;
}

}  // namespace

absl::Status WorkerSpec::Validate() const {
  if (coordinator_address.empty()) {
    return absl::InvalidArgumentError("worker: the coordinator address is empty");
  }
  if (threads < 1) return absl::InvalidArgumentError("worker: threads must be >= 1");
  if (!(coordinator_lost_s > 0)) {
    return absl::InvalidArgumentError("worker: coordinator_lost_s must be > 0");
  }
  if (absl::Status s = security.Validate(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("worker: ", s.message()));
  }
  return absl::OkStatus();
}

class WorkerServer::Impl {
 public:
  explicit Impl(WorkerSpec spec) : spec_(std::move(spec)) {}
  ~Impl() { Shutdown(); }

  absl::Status Start();
  void Shutdown();
  absl::Status Wait() {
    ended_.WaitForNotification();
    absl::MutexLock lock(&mu_);
    return end_status_;
  }
  int port() const { return port_; }
  int metrics_port() const { return metrics_endpoint_.port; }
  std::string worker_id() {
    absl::MutexLock lock(&mu_);
    return worker_id_;
  }

 private:
  // Registers if not registered yet. UNAVAILABLE once the coordinator has been unreachable for
  // coordinator_lost_s; CANCELLED when stopping.
  absl::StatusOr<std::string> EnsureRegistered();
  void CarveLoop();
  void HeartbeatLoop();
  // Carves one lease; returns the status to report (OK → CompleteChunk).
  absl::Status Carve(const pb::Lease& lease, pb::TileInfo& tile, pb::CarveStats& stats);
  void Report(const std::string& worker_id, const pb::Lease& lease, const absl::Status& carved,
              const pb::TileInfo& tile, const pb::CarveStats& stats);
  // Records a transient failure; returns true when the coordinator counts as gone.
  bool Unreachable();
  void Reachable() { unreachable_since_ms_ = -1; }
  void End(absl::Status status);
  // Sleeps up to `s` seconds; returns false when stopping.
  bool Sleep(double s) {
    return !stop_.WaitForNotificationWithTimeout(absl::Seconds(s));
  }
  std::unique_ptr<grpc::ClientContext> Context(double timeout_s = kRpcTimeoutS) {
    auto ctx = std::make_unique<grpc::ClientContext>();
    ctx->set_deadline(std::chrono::system_clock::now() +
                      std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
    AttachBearer(*ctx, spec_.security.bearer);
    return ctx;
  }

  const WorkerSpec spec_;
  std::unique_ptr<pb::CarveTaskService::Stub> stub_;
  std::unique_ptr<grpc::Server> health_;
  int port_ = 0;
  absl::Notification stop_;            // no new leases
  absl::Notification heartbeat_stop_;  // after the carve threads have drained
  absl::Notification ended_;
  std::vector<std::thread> threads_;   // carve threads
  std::thread heartbeat_thread_;
  std::atomic<int64_t> unreachable_since_ms_{-1};
  std::atomic<int64_t> rays_since_heartbeat_{0};
  PartialIndexCache partial_indexes_;
  WorkerMetrics metrics_;
  MetricsEndpoint metrics_endpoint_;  // spec_.metrics_listen_address
  absl::Mutex shutdown_mu_;

  absl::Mutex mu_;
  std::string worker_id_ ABSL_GUARDED_BY(mu_);
  double heartbeat_interval_s_ ABSL_GUARDED_BY(mu_) = 5.0;
  std::set<std::string> active_ ABSL_GUARDED_BY(mu_);
  // A lease call in flight, or a finished lease whose result is being reported: while one is,
  // active_ may not name every lease the coordinator counts as ours.
  int unsettled_ ABSL_GUARDED_BY(mu_) = 0;
  // A heartbeat that reports our leases is in flight: no lease call starts meanwhile, so the
  // coordinator cannot grant one that the report, arriving after it, would call abandoned.
  bool reporting_ ABSL_GUARDED_BY(mu_) = false;
  std::set<std::string> revoked_ ABSL_GUARDED_BY(mu_);
  absl::Status end_status_ ABSL_GUARDED_BY(mu_);
  bool ended_set_ ABSL_GUARDED_BY(mu_) = false;
};

int64_t SteadyMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

absl::Status WorkerServer::Impl::Start() {
  if (absl::Status s = spec_.Validate(); !s.ok()) return s;
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(spec_.coordinator_address, spec_.security);
  if (!channel.ok()) return channel.status();
  stub_ = pb::CarveTaskService::NewStub(*channel);
  if (!spec_.listen_address.empty()) {
    EnableHealthAndReflection();
    grpc::ServerBuilder builder;
    builder.AddListeningPort(spec_.listen_address, grpc::InsecureServerCredentials(), &port_);
    health_ = builder.BuildAndStart();
    if (health_ == nullptr || port_ == 0) {
      return absl::UnavailableError(
          absl::StrCat("worker: cannot listen on ", spec_.listen_address));
    }
    SetServing(*health_, "", true);
  }
  if (!spec_.metrics_listen_address.empty()) {
    absl::StatusOr<MetricsEndpoint> endpoint =
        ServeMetrics(spec_.metrics_listen_address, {metrics_.registry()}, "worker");
    if (!endpoint.ok()) return endpoint.status();
    metrics_endpoint_ = *std::move(endpoint);
  }
  heartbeat_thread_ = std::thread([this] { HeartbeatLoop(); });
  for (int i = 0; i < spec_.threads; ++i) threads_.emplace_back([this] { CarveLoop(); });
  spdlog::info("worker: started ({} thread(s)), coordinator {} ({}{}), health port {}",
               spec_.threads, spec_.coordinator_address,
               spec_.security.UsesTls() ? "TLS" : "plaintext",
               spec_.security.bearer.empty() ? "" : ", cluster secret", port_);
  return absl::OkStatus();
}

void WorkerServer::Impl::End(absl::Status status) {
  {
    absl::MutexLock lock(&mu_);
    if (ended_set_) return;
    ended_set_ = true;
    end_status_ = std::move(status);
  }
  if (!stop_.HasBeenNotified()) stop_.Notify();
  ended_.Notify();
}

void WorkerServer::Impl::Shutdown() {
  absl::MutexLock shutdown_lock(&shutdown_mu_);
  End(absl::OkStatus());
  // Drain: the carve threads take no new lease once stop_ is notified but finish (and report)
  // the chunk they hold, and the heartbeats go on meanwhile, so a worker scaled down or sent
  // SIGTERM mid-chunk is not declared lost and its chunk is not carved twice.
  for (std::thread& t : threads_) {
    if (t.joinable()) t.join();
  }
  threads_.clear();
  if (!heartbeat_stop_.HasBeenNotified()) heartbeat_stop_.Notify();
  if (heartbeat_thread_.joinable()) heartbeat_thread_.join();
  if (health_ != nullptr) {
    health_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
    health_.reset();
  }
}

bool WorkerServer::Impl::Unreachable() {
  const int64_t now = SteadyMs();
  int64_t expected = -1;
  unreachable_since_ms_.compare_exchange_strong(expected, now);
  const int64_t since = unreachable_since_ms_.load();
  if (since >= 0 && now - since > static_cast<int64_t>(spec_.coordinator_lost_s * 1000)) {
    End(absl::UnavailableError(absl::StrCat("coordinator ", spec_.coordinator_address,
                                            " unreachable for ", (now - since) / 1000, " s")));
    return true;
  }
  return false;
}

absl::StatusOr<std::string> WorkerServer::Impl::EnsureRegistered() {
  while (!stop_.HasBeenNotified()) {
    {
      absl::MutexLock lock(&mu_);
      if (!worker_id_.empty()) return worker_id_;
    }
    pb::RegisterWorkerRequest req;
    req.set_hostname(HostName());
    req.set_threads(spec_.threads);
    req.set_version(kVersion);
    req.set_has_shared_storage(true);
    pb::RegisterWorkerResponse resp;
    auto ctx = Context();
    absl::Status s = FromGrpcStatus(stub_->RegisterWorker(ctx.get(), req, &resp));
    if (s.ok()) {
      Reachable();
      absl::MutexLock lock(&mu_);
      // Another thread may have registered meanwhile; one id per process is enough.
      if (worker_id_.empty()) {
        worker_id_ = resp.worker_id();
        heartbeat_interval_s_ = resp.heartbeat_interval_s() > 0 ? resp.heartbeat_interval_s() : 5;
        active_.clear();
        spdlog::info("worker: registered as {} (heartbeat every {} s)", worker_id_,
                     heartbeat_interval_s_);
      }
      return worker_id_;
    }
    if (!IsTransient(s)) {
      End(s);
      return s;
    }
    if (Unreachable()) return absl::UnavailableError("coordinator gone");
    Sleep(0.2);
  }
  return absl::CancelledError("stopping");
}

void WorkerServer::Impl::HeartbeatLoop() {
  while (true) {
    double interval;
    {
      absl::MutexLock lock(&mu_);
      interval = heartbeat_interval_s_;
    }
    if (heartbeat_stop_.WaitForNotificationWithTimeout(absl::Seconds(interval))) return;
    std::string id;
    pb::HeartbeatRequest req;
    {
      absl::MutexLock lock(&mu_);
      id = worker_id_;
      for (const std::string& lease : active_) req.add_active_lease_ids(lease);
      // Our leases, exactly, unless a call is in flight: the coordinator then gives back any
      // other lease it counts as ours, e.g. one granted after our lease call had given up
      // waiting for it, which heartbeats would otherwise extend for ever.
      req.set_report_leases(unsettled_ == 0 && !id.empty());
      reporting_ = req.report_leases();
    }
    if (id.empty()) continue;
    req.set_worker_id(id);
    req.set_rays_carved(rays_since_heartbeat_.exchange(0));
    pb::HeartbeatResponse resp;
    auto ctx = Context();
    absl::Status s = FromGrpcStatus(stub_->Heartbeat(ctx.get(), req, &resp));
    {
      absl::MutexLock lock(&mu_);
      reporting_ = false;
    }
    if (absl::IsNotFound(s)) {
      // The coordinator declared us lost (or restarted): register again under a new id.
      spdlog::warn("worker {}: unknown to the coordinator; registering again", id);
      absl::MutexLock lock(&mu_);
      if (worker_id_ == id) worker_id_.clear();
      continue;
    }
    if (absl::IsUnauthenticated(s)) {
      End(s);  // the coordinator no longer takes our secret: nothing to wait for
      return;
    }
    if (!s.ok()) {
      spdlog::warn("worker {}: heartbeat: {}", id, s.ToString());
      if (IsTransient(s)) Unreachable();
      continue;
    }
    Reachable();
    absl::MutexLock lock(&mu_);
    for (const std::string& lease : resp.revoked_lease_ids()) revoked_.insert(lease);
  }
}

absl::Status WorkerServer::Impl::Carve(const pb::Lease& lease, pb::TileInfo& tile,
                                       pb::CarveStats& stats) {
  const auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(lease.params().resolution_m());
  if (!grid.ok()) return grid.status();  // not retryable: the lease itself is bad
  // UNSPECIFIED: a coordinator from before the fast evaluation (carve.proto).
  const CarveEvaluation evaluation = lease.params().evaluation() == pb::CARVE_EVALUATION_FAST
                                         ? CarveEvaluation::kFast
                                         : CarveEvaluation::kExact;
  std::string written;  // the file the task made
  if (lease.has_slice()) {
    const pb::SliceTask& task = lease.slice();
    ScanSlice slice;
    slice.index = task.index();
    slice.own_rays = uint64_t(task.own_rays());
    for (const pb::RowRange& r : task.own()) slice.own.push_back({r.begin(), r.end()});
    for (const pb::RowRange& r : task.read()) slice.read.push_back({r.begin(), r.end()});
    RecarveRegionMap regions;
    SliceCarveOptions options;
    options.grid = *grid;
    options.evaluation = evaluation;
    options.memory_budget_bytes = spec_.slice_memory_bytes;
    if (!task.regions_path().empty()) {
      absl::StatusOr<RecarveRegionMap> read = ReadRegionsFile(task.regions_path());
      if (!read.ok()) return read.status();
      regions = *std::move(read);
      options.regions = &regions;
    }
    // Confined to the tenant's folder as the coordinator checked it, and read through the
    // descriptor opened here (storage/confined_path.h): errors name the path as the tenant
    // gave it.
    if (task.scan_root().empty() || !fs::path(task.scan_root()).is_absolute()) {
      return absl::InvalidArgumentError("slice without an absolute scan root");
    }
    absl::StatusOr<ConfinedFile> scan =
        ConfinedFile::Open(task.scan_root(), task.scan_path(), "input_path");
    if (!scan.ok()) return scan.status();
    std::unique_ptr<ScanReader> reader;
    {
      std::lock_guard<std::mutex> lock(Hdf5Lock());
      ScanReader::OpenOptions open = SliceOpenOptions(slice);
      open.world_yaw_rad = lease.params().world_yaw_rad();  // §2.3, the job's turn to north
      absl::StatusOr<std::unique_ptr<ScanReader>> r = ScanReader::Open(scan->path(), open);
      if (!r.ok()) return scan->Rename(r.status());
      reader = *std::move(r);
    }
    fs::create_directories(fs::path(task.partial_path()).parent_path());
    // Heartbeats carry the slice's rays carved since the last one.
    uint64_t reported = 0;
    absl::StatusOr<SliceCarveStats> result = CarveSliceToFile(
        *reader, slice, options, task.partial_path(), [this, &reported](uint64_t rays) {
          rays_since_heartbeat_ += int64_t(rays - reported);
          metrics_.RaysCarved(rays - reported);
          reported = rays;
        });
    {
      std::lock_guard<std::mutex> lock(Hdf5Lock());
      reader.reset();
    }
    if (!result.ok()) return scan->Rename(result.status());
    written = task.partial_path();
    std::error_code ec;
    stats.set_rays(int64_t(result->rays));
    stats.set_frames(int64_t(result->frames));
    stats.set_returns(int64_t(result->returns));
    stats.set_wedges(int64_t(result->wedges));
    stats.set_wedge_chunk_pairs(int64_t(result->wedge_chunk_pairs));
    stats.set_leaf_updates(int64_t(result->leaf_updates));
    stats.set_partial_bytes(int64_t(fs::file_size(written, ec)));
    tile.set_path(fs::path(written).filename().string());
  } else if (lease.has_combine()) {
    const ChunkKey chunk(lease.chunk().x(), lease.chunk().y(), lease.chunk().z());
    std::vector<PartialSource> sources;
    for (const std::string& path : lease.combine().partial_paths()) {
      absl::StatusOr<PartialSumsIndex> index = partial_indexes_.Get(path);
      if (!index.ok()) return index.status();
      sources.push_back({path, *std::move(index)});
    }
    CombineChunkRequest req;
    req.job_id = lease.job_id();
    req.chunk = chunk;
    req.grid = *grid;
    req.sources = &sources;
    for (size_t i = 0; i < sources.size(); ++i) {
      const std::vector<PartialSection>& sections = sources[i].index.sections;
      for (size_t k = 0; k < sections.size(); ++k) {
        if (sections[k].chunk == chunk) req.sections.push_back({i, k});
      }
    }
    req.tiles_dir = lease.params().tile_dir();
    absl::StatusOr<CarveChunkResult> result = CombineChunkToTile(req);
    if (!result.ok()) return result.status();
    written = result->tile_path;
    stats.set_leaves(static_cast<int64_t>(result->leaves));
    tile.set_path(fs::path(written).lexically_relative(req.tiles_dir).string());
  } else {
    return absl::InvalidArgumentError("lease with neither a slice nor a chunk to combine");
  }
  absl::StatusOr<std::string> sha = Sha256HexOfFile(written);
  if (!sha.ok()) return sha.status();
  std::error_code ec;
  tile.set_size_bytes(static_cast<int64_t>(fs::file_size(written, ec)));
  tile.set_sha256_hex(*sha);
  stats.set_carve_s(
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return absl::OkStatus();
}

void WorkerServer::Impl::Report(const std::string& worker_id, const pb::Lease& lease,
                                const absl::Status& carved, const pb::TileInfo& tile,
                                const pb::CarveStats& stats) {
  // A few retries: losing a finished tile to one dropped call would cost a re-carve.
  for (int attempt = 0; attempt < 5; ++attempt) {
    absl::Status s;
    auto ctx = Context();
    if (carved.ok()) {
      pb::CompleteChunkRequest req;
      req.set_worker_id(worker_id);
      req.set_lease_id(lease.lease_id());
      req.set_generation(lease.generation());
      *req.mutable_tile() = tile;
      *req.mutable_stats() = stats;
      pb::CompleteChunkResponse resp;
      s = FromGrpcStatus(stub_->CompleteChunk(ctx.get(), req, &resp));
      if (s.ok()) {
        spdlog::info("worker {}: {} done ({} rays, {:.2f} s; {}/{} tasks of the job; lease {})",
                     worker_id, TaskName(lease), stats.rays(), stats.carve_s(),
                     resp.progress().chunks_done(), resp.progress().chunks_total(),
                     lease.lease_id());
      }
    } else {
      pb::FailChunkRequest req;
      req.set_worker_id(worker_id);
      req.set_lease_id(lease.lease_id());
      req.set_generation(lease.generation());
      req.set_reason(std::string(carved.message()));
      // Corrupt or invalid wedges never carve: fail the job at once instead of retrying.
      req.set_retryable(!absl::IsDataLoss(carved) && !absl::IsInvalidArgument(carved));
      pb::FailChunkResponse resp;
      s = FromGrpcStatus(stub_->FailChunk(ctx.get(), req, &resp));
    }
    if (s.ok()) {
      Reachable();
      return;
    }
    if (!IsTransient(s)) {
      spdlog::warn("worker {}: report of {} rejected: {}", worker_id, lease.lease_id(),
                   s.ToString());
      return;
    }
    if (Unreachable() || !Sleep(0.5 * (attempt + 1))) return;
  }
}

void WorkerServer::Impl::CarveLoop() {
  FreedMemoryPolicy freed_memory;
  while (!stop_.HasBeenNotified()) {
    absl::StatusOr<std::string> id = EnsureRegistered();
    if (!id.ok()) return;
    pb::LeaseChunkRequest req;
    req.set_worker_id(*id);
    req.set_wait_s(1.0);
    pb::LeaseChunkResponse resp;
    mu_.LockWhen(absl::Condition(
        +[](bool* reporting) { return !*reporting; }, &reporting_));
    ++unsettled_;
    mu_.Unlock();
    auto ctx = Context(kRpcTimeoutS + 2.0);
    absl::Status s = FromGrpcStatus(stub_->LeaseChunk(ctx.get(), req, &resp));
    {
      absl::MutexLock lock(&mu_);
      if (s.ok() && resp.has_lease()) active_.insert(resp.lease().lease_id());
      --unsettled_;
    }
    if (absl::IsNotFound(s)) {
      absl::MutexLock lock(&mu_);
      if (worker_id_ == *id) worker_id_.clear();
      continue;
    }
    if (absl::IsUnauthenticated(s)) {
      End(s);
      return;
    }
    if (!s.ok()) {
      if (!IsTransient(s)) spdlog::warn("worker {}: lease: {}", *id, s.ToString());
      if (Unreachable()) return;
      Sleep(0.5);
      continue;
    }
    Reachable();
    if (!resp.has_lease()) {
      if (freed_memory.WhenIdle()) ReturnFreedMemory();
      Sleep(resp.retry_after_s() > 0 ? resp.retry_after_s() : 1.0);
      continue;
    }
    const pb::Lease& lease = resp.lease();
    LogScope log_scope(LeaseLogFields(lease.lease_id(), *id));  // JSON logs: job, chunk
    pb::TileInfo tile;
    pb::CarveStats stats;
    metrics_.TaskStarted();
    const auto t0 = std::chrono::steady_clock::now();
    absl::Status carved = Carve(lease, tile, stats);
    if (freed_memory.AfterTask(lease.has_slice())) ReturnFreedMemory();
    metrics_.TaskFinished(
        lease.has_slice() ? "slice" : "combine", carved.ok(),
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
        uint64_t(tile.size_bytes()));
    if (!carved.ok()) {
      spdlog::error("worker {}: {} (lease {}): {}", *id, TaskName(lease), lease.lease_id(),
                    carved.ToString());
    }
    bool revoked;
    {
      absl::MutexLock lock(&mu_);
      active_.erase(lease.lease_id());
      revoked = revoked_.erase(lease.lease_id()) > 0;
      if (!revoked) ++unsettled_;
    }
    if (revoked) {
      spdlog::info("worker {}: lease {} was revoked; result dropped", *id, lease.lease_id());
      continue;
    }
    Report(*id, lease, carved, tile, stats);
    {
      absl::MutexLock lock(&mu_);
      --unsettled_;
    }
  }
}

// ---- public shell

WorkerServer::WorkerServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
WorkerServer::~WorkerServer() = default;

absl::StatusOr<std::unique_ptr<WorkerServer>> WorkerServer::Start(WorkerSpec spec) {
  auto impl = std::make_unique<Impl>(std::move(spec));
  if (absl::Status s = impl->Start(); !s.ok()) return s;
  return std::unique_ptr<WorkerServer>(new WorkerServer(std::move(impl)));
}

int WorkerServer::port() const { return impl_->port(); }
int WorkerServer::metrics_port() const { return impl_->metrics_port(); }
std::string WorkerServer::worker_id() const { return impl_->worker_id(); }
void WorkerServer::Shutdown() { impl_->Shutdown(); }
absl::Status WorkerServer::Wait() { return impl_->Wait(); }

}  // namespace carvemap
