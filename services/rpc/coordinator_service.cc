#include "services/rpc/coordinator_service.h"

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <random>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "absl/base/thread_annotations.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "coordinator/carve_task.h"
#include "coordinator/coordinator_core.h"
#include "coordinator/job_folders.h"
#include "coordinator/job_params.h"
#include "coordinator/job_plan.h"
#include "coordinator/job_runner.h"
#include "coordinator/job_runtime.h"
#include "coordinator/job_submit.h"
#include "coordinator/lease_id.h"
#include "coordinator/lease_table.h"
#include "coordinator/scan_north.h"
#include "coordinator/scan_slices.h"
#include "geometry/octree_keys.h"
#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "proto/carvemap/v1/jobs.grpc.pb.h"
#include "services/rpc/bearer_tokens.h"
#include "services/rpc/coordinator_metrics.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/grpc_server_common.h"
#include "services/rpc/grpc_status.h"
#include "services/rpc/process_metrics.h"
#include "services/rpc/server_log.h"
#include "storage/confined_path.h"
#include "storage/file_hash.h"
#include "storage/hdf5_lock.h"
#include "storage/job_store.h"
#include "storage/partial_sums.h"
#include "storage/scan_reader.h"
#include "storage/upload_store.h"

namespace carvemap {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;

namespace {

int64_t NowMs() { return LeaseTable::Clock::System().NowUnixMs(); }

JobParamsRequest FromProto(const pb::JobParams& in) {
  return {.resolution_m = in.resolution_m(),
          .method = static_cast<int>(in.method()),
          .workers_hint = in.workers_hint(),
          .object_resolution_m = in.object_resolution_m(),
          .floorplan_method = in.floorplan_method(),
          .trimmed_points = in.trimmed_points(),
          .min_object_volume_m3 = in.min_object_volume_m3(),
          .evaluation = static_cast<int>(in.evaluation()),
          .north = in.north(),
          .location = in.location(),
          .survey_date = in.survey_date()};
}

pb::CarveEvaluation ToProto(CarveEvaluation e) {
  return e == CarveEvaluation::kExact ? pb::CARVE_EVALUATION_EXACT : pb::CARVE_EVALUATION_FAST;
}

void ToProto(const JobRecord& r, pb::Job& out) {
  out.set_job_id(r.id);
  out.set_tenant(r.tenant);
  out.set_state(static_cast<pb::JobState>(static_cast<int>(r.state)));
  out.set_input_path(r.input_path);
  out.set_output_name(r.output_name);
  const JobParams p = JobParams::FromJson(r.params_json);
  out.mutable_params()->set_resolution_m(p.resolution_m);
  out.mutable_params()->set_method(static_cast<pb::CarveMethod>(static_cast<int>(p.method)));
  out.mutable_params()->set_workers_hint(p.workers_hint);
  out.mutable_params()->set_object_resolution_m(p.object_resolution_m);
  out.mutable_params()->set_floorplan_method(p.floorplan_method);
  out.mutable_params()->set_trimmed_points(p.trimmed_points);
  out.mutable_params()->set_min_object_volume_m3(p.min_object_volume_m3);
  out.mutable_params()->set_evaluation(ToProto(p.evaluation));
  out.mutable_params()->set_north(NorthModeName(p.north));
  out.mutable_params()->set_location(p.location);
  out.mutable_params()->set_survey_date(p.survey_date);
  out.set_error(r.error);
  out.set_created_unix_ms(r.created_unix_ms);
  out.set_updated_unix_ms(r.updated_unix_ms);
  out.set_finished_unix_ms(r.finished_unix_ms);
  out.set_idempotency_key(r.idempotency_key);
  auto* pr = out.mutable_progress();
  pr->set_chunks_total(r.counters.chunks_total);
  pr->set_chunks_done(r.counters.chunks_done);
  pr->set_chunks_leased(r.counters.chunks_leased);
  pr->set_chunk_retries(r.counters.chunk_retries);
}

absl::StatusOr<std::string> JobOfLease(absl::string_view lease_id) {
  absl::StatusOr<LeaseId> id = LeaseId::Parse(lease_id);
  if (!id.ok()) return id.status();
  return std::move(id->job_id);
}

bool ValidRelativePath(const std::string& path) {
  if (path.empty() || path.front() == '/') return false;
  for (const auto& part : fs::path(path)) {
    if (part == "..") return false;
  }
  return true;
}

std::string RandomHex(int digits) {
  static std::mt19937_64 rng(std::random_device{}());
  static absl::Mutex mu;
  absl::MutexLock lock(&mu);
  std::string s;
  for (int i = 0; i < digits; ++i) s.push_back("0123456789abcdef"[rng() % 16]);
  return s;
}

std::string NewJobId() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char day[16];
  std::strftime(day, sizeof(day), "%Y%m%d", &tm);
  return absl::StrCat("j-", day, "-", RandomHex(6));
}

void ToProto(const CarveTask& t, pb::Lease& lease) {
  lease.set_job_id(t.grant.job_id);
  lease.mutable_chunk()->set_x(t.grant.chunk.x);
  lease.mutable_chunk()->set_y(t.grant.chunk.y);
  lease.mutable_chunk()->set_z(t.grant.chunk.z);
  lease.set_lease_id(t.grant.lease_id);
  lease.set_generation(t.grant.generation);
  lease.set_deadline_unix_ms(t.grant.deadline_unix_ms);
  lease.set_attempt(t.grant.attempt);
  pb::CarveParams& params = *lease.mutable_params();
  params.set_resolution_m(t.resolution_m);
  params.set_method(static_cast<pb::CarveMethod>(static_cast<int>(t.method)));
  params.set_leaf_depth(t.leaf_depth);
  params.set_tile_dir(t.tile_dir);
  params.set_evaluation(ToProto(t.evaluation));
  params.set_world_yaw_rad(t.world_yaw_rad);
  if (const SliceWork* slice = std::get_if<SliceWork>(&t.work)) {
    pb::SliceTask& task = *lease.mutable_slice();
    task.set_index(slice->index);
    task.set_pass(slice->pass);
    task.set_scan_root(slice->scan_root);
    task.set_scan_path(slice->scan_path);
    for (const ScanReader::RowRange& r : slice->own) {
      pb::RowRange* o = task.add_own();
      o->set_begin(r.begin);
      o->set_end(r.end);
    }
    for (const ScanReader::RowRange& r : slice->read) {
      pb::RowRange* o = task.add_read();
      o->set_begin(r.begin);
      o->set_end(r.end);
    }
    task.set_own_rays(int64_t(slice->own_rays));
    task.set_partial_path(slice->partial_path);
    task.set_regions_path(slice->regions_path);
  } else {
    pb::CombineTask& task = *lease.mutable_combine();
    for (const std::string& p : std::get<CombineWork>(t.work).partial_paths) {
      task.add_partial_paths(p);
    }
  }
}

void ToProto(const UploadState& u, pb::Upload& out) {
  out.set_upload_id(u.id);
  out.set_name(u.name);
  out.set_input_path(u.input_path);
  out.set_size_bytes(u.size_bytes);
  out.set_sha256_hex(u.sha256_hex);
  out.set_received_bytes(u.received_bytes);
  out.set_complete(u.complete);
}

}  // namespace

absl::Status CoordinatorSpec::Validate() const {
  if (listen_address.empty()) return absl::InvalidArgumentError("listen address is empty");
  if (data_root.empty()) return absl::InvalidArgumentError("data root is empty");
  if (output_root.empty()) return absl::InvalidArgumentError("output root is empty");
  if (!(heartbeat_interval_s > 0) || !(worker_timeout_s > heartbeat_interval_s)) {
    return absl::InvalidArgumentError(
        "need heartbeat_interval_s > 0 and worker_timeout_s > heartbeat_interval_s");
  }
  if (!(lease_timeout_s > 0) || !(sweep_interval_s > 0)) {
    return absl::InvalidArgumentError("lease_timeout_s and sweep_interval_s must be > 0");
  }
  if (max_attempts < 1) return absl::InvalidArgumentError("max_attempts must be >= 1");
  // ---- security
  if (tls_cert_file.empty() != tls_key_file.empty()) {
    return absl::InvalidArgumentError("TLS needs both --tls-cert and --tls-key");
  }
  if (!tls_client_ca_file.empty() && tls_cert_file.empty()) {
    return absl::InvalidArgumentError(
        "--tls-client-ca (mutual TLS) needs the server's own --tls-cert and --tls-key");
  }
  absl::StatusOr<TokenTable> table = TokenTable::Build(tokens);
  if (!table.ok()) return table.status();
  if (!cluster_secret.empty()) {
    if (absl::Status s = ValidateSecret(cluster_secret, "cluster secret"); !s.ok()) return s;
    // A tenant holding it could act as a worker: commit tiles into any job.
    if (table->Lookup(cluster_secret).has_value()) {
      return absl::InvalidArgumentError("the cluster secret is also a tenant's token");
    }
  }
  if (shared_dirs && table->tenants().size() > 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--shared-dirs: the tokens belong to ", table->tenants().size(),
        " tenants, whose inputs and outputs would mix; shared folders need a single tenant"));
  }
  if (max_jobs_per_tenant < 0) return absl::InvalidArgumentError("max_jobs_per_tenant < 0");
  if (upload_quota_bytes < 0) {
    return absl::InvalidArgumentError("upload quota must not be negative");
  }
  if (max_request_bytes < 4096) {
    return absl::InvalidArgumentError("max_request_bytes must be >= 4096");
  }
  if (!IsLoopbackAddress(listen_address) && !insecure) {
    if (tokens.empty()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "listening on ", listen_address, " (not loopback) without bearer tokens: anyone who "
          "reaches it could submit jobs and fetch every output. Give --tokens FILE (or "
          "CARVEMAP_TOKENS), or --insecure to serve it open anyway"));
    }
    if (cluster_secret.empty() && tls_client_ca_file.empty()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "listening on ", listen_address, " (not loopback) with an open carve-task API: "
          "anyone who reaches it could act as a worker. Give --cluster-secret-file FILE (or "
          "CARVEMAP_CLUSTER_SECRET), or --tls-client-ca for mutual TLS, or --insecure"));
    }
  }
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------------------------

class CoordinatorServer::Impl final : public JobStages {
 public:
  explicit Impl(CoordinatorSpec spec) : spec_(std::move(spec)) {}
  ~Impl() { Shutdown(); }

  absl::Status Start();
  void Shutdown();
  void Wait() { shutdown_done_.WaitForNotification(); }
  int port() const { return servers_.port; }
  int health_port() const { return servers_.health_port; }
  int metrics_port() const { return metrics_endpoint_.port; }
  CoordinatorMetrics& metrics() { return metrics_; }

  // Who is calling the job API: the tenant of the bearer token, and the folder under the
  // roots that holds its files ("" = the roots).
  struct Caller {
    std::string tenant;
    std::string tenant_dir;
  };
  // UNAUTHENTICATED without a known bearer token (when the coordinator has tokens).
  absl::StatusOr<Caller> AuthenticateTenant(const grpc::ServerContext& ctx);
  // The carve-task API: the cluster secret or a verified client certificate, if either is
  // configured; UNAUTHENTICATED otherwise.
  absl::Status AuthenticatePeer(const grpc::ServerContext& ctx);

  // ---- JobService
  absl::Status SubmitJob(const Caller& caller, const pb::SubmitJobRequest& req,
                         pb::SubmitJobResponse& resp);
  absl::Status GetJob(const Caller& caller, const pb::GetJobRequest& req, pb::Job& resp);
  absl::Status WatchJob(const Caller& caller, grpc::ServerContext& ctx,
                        const pb::WatchJobRequest& req, grpc::ServerWriter<pb::JobEvent>& writer);
  // One Progress event of WatchJob; false when the client is gone.
  bool WriteProgress(grpc::ServerWriter<pb::JobEvent>& writer, pb::JobEvent e, const JobRecord& job,
                     JobState state);
  absl::Status CancelJob(const Caller& caller, const pb::CancelJobRequest& req,
                         pb::CancelJobResponse& resp);
  absl::Status ListJobs(const Caller& caller, const pb::ListJobsRequest& req,
                        pb::ListJobsResponse& resp);
  absl::Status FetchArtifact(const Caller& caller, grpc::ServerContext& ctx,
                             const pb::FetchArtifactRequest& req,
                             grpc::ServerWriter<pb::ArtifactChunk>& writer);
  absl::Status StartUpload(const Caller& caller, const pb::StartUploadRequest& req,
                           pb::Upload& resp);
  absl::Status UploadScan(const Caller& caller, grpc::ServerReader<pb::UploadScanRequest>& reader,
                          pb::Upload& resp);

  // ---- CarveTaskService
  absl::Status RegisterWorker(grpc::ServerContext& ctx, const pb::RegisterWorkerRequest& req,
                              pb::RegisterWorkerResponse& resp);
  absl::Status Heartbeat(const pb::HeartbeatRequest& req, pb::HeartbeatResponse& resp);
  absl::Status LeaseChunk(grpc::ServerContext& ctx, const pb::LeaseChunkRequest& req,
                          pb::LeaseChunkResponse& resp);
  absl::Status CompleteChunk(const pb::CompleteChunkRequest& req,
                             pb::CompleteChunkResponse& resp);
  absl::Status FailChunk(const pb::FailChunkRequest& req, pb::FailChunkResponse& resp);

 private:
  // The caller's job, or NOT_FOUND with the same message whether the id is unknown or
  // another tenant's: ids of others do not leak.
  absl::StatusOr<JobRecord> OwnJob(const Caller& caller, const std::string& job_id);

  // A job's thread is joined soon after it ends (by the next start or the sweeper), not kept
  // to the coordinator's shutdown: each kept one would hold its stack's mappings for ever.
  void StartJobThread(const std::string& job_id) {
    ReapJobThreads();
    absl::MutexLock lock(&threads_mu_);
    const uint64_t key = ++job_thread_seq_;
    job_threads_.emplace(key, std::thread([this, job_id, key] {
                           RunJob(job_id);
                           absl::MutexLock done_lock(&threads_mu_);
                           ended_job_threads_.push_back(key);
                         }));
  }
  void ReapJobThreads() {
    std::vector<std::thread> ended;
    {
      absl::MutexLock lock(&threads_mu_);
      for (uint64_t key : ended_job_threads_) {
        auto it = job_threads_.find(key);
        if (it == job_threads_.end()) continue;
        ended.push_back(std::move(it->second));
        job_threads_.erase(it);
      }
      ended_job_threads_.clear();
    }
    for (std::thread& t : ended) t.join();  // each has left RunJob: the join is immediate
  }
  // A job's thread: its runtime, then coordinator/job_runner.h's RunJob over the stages below.
  void RunJob(const std::string& job_id);
  // ---- JobStages (coordinator/job_runner.h)
  absl::Status Ingest(const JobRecord& job) override { return PlanStage(job); }
  absl::Status Carve(const JobRecord& job) override { return CarveStage(job.id); }
  absl::Status Merge(const JobRecord& job) override { return MergeStage(job); }
  void EnterStage(const std::string& job_id, const std::string& stage) override;
  std::string TenantView(const std::string& job_id, const std::string& text) override {
    return core_->TenantView(job_id, text);
  }
  void Moved(const std::string& job_id, JobState from, JobState to,
             const std::string& reason) override;
  void NotMoved(const std::string& job_id, JobState to, const absl::Status& why) override;
  void CleanUp(const std::string& job_id, bool succeeded) override;
  bool Stopping() override { return stopping_; }
  absl::Status MergeStage(const JobRecord& job);
  // INGESTING: the scan checked (every row) and cut into time slices, one task each.
  absl::Status PlanStage(const JobRecord& job);
  // The plan of a job again, for a coordinator that resumes it (the same slices: PlanSlices
  // depends on the scan and the parameters only).
  absl::Status EnsurePlan(const JobRecord& job);
  // The slices carved, then every chunk they touched combined into its tile. OK: go on to
  // merge; CANCELLED: the job is already terminal (cancelled or failed by the lease table) or
  // the coordinator stops.
  absl::Status CarveStage(const std::string& job_id);
  // Removes the partial sums in `dir` once nothing will read them (the files; with
  // files_only false the folder and its subfolders too), unless the coordinator keeps them.
  void RemovePartials(const std::string& job_id, const std::string& dir, bool files_only);
  // The chunks the pass's slices carved into, from their partial sums' indexes.
  absl::StatusOr<std::vector<ChunkCoord>> ChunksOfPass(const std::string& job_id);
  // §5.6.1, called by the merge: `chunks` leased to the workers once more, at `resolution_m`,
  // into <job dir>/object_tiles; returns that directory once every one is committed.
  absl::StatusOr<std::string> RecarveStage(const std::string& job_id,
                                           const std::vector<RecarveChunk>& chunks,
                                           double resolution_m);
  // The sweeper's thread: a sweep every sweep_interval_s until the coordinator stops.
  void SweepLoop();
  // The job a lease's id names, which must exist and not be terminal (FailedPrecondition
  // otherwise, with the job, so that a caller can clean up after it); shared by CompleteChunk
  // and FailChunk, which check the store before the lease table (the table has forgotten
  // cancelled jobs).
  absl::Status CheckLeaseJob(absl::string_view lease_id, JobRecord* job = nullptr);
  // Wakes the WatchJob streams: a job's state may have changed (a transition, a job failed by
  // the lease table), or the coordinator stops. Not on every task: watchers report progress at
  // their own interval.
  void JobsChanged() {
    absl::MutexLock lock(&watch_mu_);
    ++job_events_;
    watch_cv_.SignalAll();
  }

  const CoordinatorSpec spec_;
  CoordinatorFolders folders_;
  std::unique_ptr<JobStore> store_;
  std::unique_ptr<UploadStore> uploads_;
  GrpcServers servers_;  // the two APIs; the plaintext health port if asked for
  TokenTable tokens_;
  std::unique_ptr<grpc::Service> job_service_;
  std::unique_ptr<grpc::Service> carve_service_;
  CoordinatorMetrics metrics_;
  MetricsEndpoint metrics_endpoint_;  // spec_.metrics_listen_address
  std::atomic<bool> stopping_{false};
  absl::Notification stop_sweeper_;  // wakes the sweeper's wait between sweeps
  absl::Notification shutdown_done_;
  std::thread sweeper_;

  // The lease table, the workers and the running jobs' runtimes (coordinator/
  // coordinator_core.h); made by Start.
  std::unique_ptr<CoordinatorCore> core_;
  absl::Mutex watch_mu_;  // JobsChanged
  absl::CondVar watch_cv_;
  uint64_t job_events_ ABSL_GUARDED_BY(watch_mu_) = 0;
  absl::Mutex threads_mu_;
  std::map<uint64_t, std::thread> job_threads_ ABSL_GUARDED_BY(threads_mu_);
  std::vector<uint64_t> ended_job_threads_ ABSL_GUARDED_BY(threads_mu_);  // to join
  uint64_t job_thread_seq_ ABSL_GUARDED_BY(threads_mu_) = 0;
  absl::Mutex shutdown_mu_;
  // HDF5 (scan reading when planning, the in-process merge) is not thread-safe in the Debian
  // build: one job at a time uses it in this process (and each call takes Hdf5Lock()).
  absl::Mutex hdf5_mu_;
};

// ---- gRPC adapters: one conversion each way, nothing else (and the RPC's time).

namespace {

// Runs one handler and records its duration and status code (carvemap_rpc_duration_seconds).
template <typename Handler>
grpc::Status Timed(CoordinatorMetrics& metrics, const char* method, Handler&& handler) {
  const auto start = std::chrono::steady_clock::now();
  grpc::Status status = handler();
  metrics.ObserveRpc(
      method, absl::StatusCodeToString(static_cast<absl::StatusCode>(status.error_code())),
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  return status;
}

class JobServiceAdapter final : public pb::JobService::Service {
 public:
  explicit JobServiceAdapter(CoordinatorServer::Impl& impl) : impl_(impl) {}
  grpc::Status SubmitJob(grpc::ServerContext* ctx, const pb::SubmitJobRequest* req,
                         pb::SubmitJobResponse* resp) override {
    return Timed(impl_.metrics(), "SubmitJob", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.SubmitJob(*caller, *req, *resp));
    });
  }
  grpc::Status GetJob(grpc::ServerContext* ctx, const pb::GetJobRequest* req,
                      pb::Job* resp) override {
    return Timed(impl_.metrics(), "GetJob", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.GetJob(*caller, *req, *resp));
    });
  }
  grpc::Status WatchJob(grpc::ServerContext* ctx, const pb::WatchJobRequest* req,
                        grpc::ServerWriter<pb::JobEvent>* writer) override {
    return Timed(impl_.metrics(), "WatchJob", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.WatchJob(*caller, *ctx, *req, *writer));
    });
  }
  grpc::Status CancelJob(grpc::ServerContext* ctx, const pb::CancelJobRequest* req,
                         pb::CancelJobResponse* resp) override {
    return Timed(impl_.metrics(), "CancelJob", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.CancelJob(*caller, *req, *resp));
    });
  }
  grpc::Status ListJobs(grpc::ServerContext* ctx, const pb::ListJobsRequest* req,
                        pb::ListJobsResponse* resp) override {
    return Timed(impl_.metrics(), "ListJobs", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.ListJobs(*caller, *req, *resp));
    });
  }
  grpc::Status FetchArtifact(grpc::ServerContext* ctx, const pb::FetchArtifactRequest* req,
                             grpc::ServerWriter<pb::ArtifactChunk>* writer) override {
    return Timed(impl_.metrics(), "FetchArtifact", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.FetchArtifact(*caller, *ctx, *req, *writer));
    });
  }
  grpc::Status StartUpload(grpc::ServerContext* ctx, const pb::StartUploadRequest* req,
                           pb::Upload* resp) override {
    return Timed(impl_.metrics(), "StartUpload", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.StartUpload(*caller, *req, *resp));
    });
  }
  grpc::Status UploadScan(grpc::ServerContext* ctx,
                          grpc::ServerReader<pb::UploadScanRequest>* reader,
                          pb::Upload* resp) override {
    return Timed(impl_.metrics(), "UploadScan", [&] {
      auto caller = impl_.AuthenticateTenant(*ctx);
      if (!caller.ok()) return ToGrpcStatus(caller.status());
      return ToGrpcStatus(impl_.UploadScan(*caller, *reader, *resp));
    });
  }

 private:
  CoordinatorServer::Impl& impl_;
};

class CarveServiceAdapter final : public pb::CarveTaskService::Service {
 public:
  explicit CarveServiceAdapter(CoordinatorServer::Impl& impl) : impl_(impl) {}
  grpc::Status RegisterWorker(grpc::ServerContext* ctx, const pb::RegisterWorkerRequest* req,
                              pb::RegisterWorkerResponse* resp) override {
    return Timed(impl_.metrics(), "RegisterWorker", [&] {
      if (absl::Status s = impl_.AuthenticatePeer(*ctx); !s.ok()) return ToGrpcStatus(s);
      return ToGrpcStatus(impl_.RegisterWorker(*ctx, *req, *resp));
    });
  }
  grpc::Status Heartbeat(grpc::ServerContext* ctx, const pb::HeartbeatRequest* req,
                         pb::HeartbeatResponse* resp) override {
    return Timed(impl_.metrics(), "Heartbeat", [&] {
      if (absl::Status s = impl_.AuthenticatePeer(*ctx); !s.ok()) return ToGrpcStatus(s);
      return ToGrpcStatus(impl_.Heartbeat(*req, *resp));
    });
  }
  grpc::Status LeaseChunk(grpc::ServerContext* ctx, const pb::LeaseChunkRequest* req,
                          pb::LeaseChunkResponse* resp) override {
    return Timed(impl_.metrics(), "LeaseChunk", [&] {
      if (absl::Status s = impl_.AuthenticatePeer(*ctx); !s.ok()) return ToGrpcStatus(s);
      return ToGrpcStatus(impl_.LeaseChunk(*ctx, *req, *resp));
    });
  }
  grpc::Status CompleteChunk(grpc::ServerContext* ctx, const pb::CompleteChunkRequest* req,
                             pb::CompleteChunkResponse* resp) override {
    return Timed(impl_.metrics(), "CompleteChunk", [&] {
      if (absl::Status s = impl_.AuthenticatePeer(*ctx); !s.ok()) return ToGrpcStatus(s);
      return ToGrpcStatus(impl_.CompleteChunk(*req, *resp));
    });
  }
  grpc::Status FailChunk(grpc::ServerContext* ctx, const pb::FailChunkRequest* req,
                         pb::FailChunkResponse* resp) override {
    return Timed(impl_.metrics(), "FailChunk", [&] {
      if (absl::Status s = impl_.AuthenticatePeer(*ctx); !s.ok()) return ToGrpcStatus(s);
      return ToGrpcStatus(impl_.FailChunk(*req, *resp));
    });
  }

 private:
  CoordinatorServer::Impl& impl_;
};

}  // namespace

// ---- lifecycle

absl::Status CoordinatorServer::Impl::Start() {
  if (absl::Status s = spec_.Validate(); !s.ok()) return s;
  absl::StatusOr<TokenTable> tokens = TokenTable::Build(spec_.tokens);
  if (!tokens.ok()) return tokens.status();
  tokens_ = *std::move(tokens);
  absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
      ServerCredentialsFor(spec_.tls_cert_file, spec_.tls_key_file, spec_.tls_client_ca_file);
  if (!credentials.ok()) return credentials.status();
  folders_ = CoordinatorFolders::Of(spec_.data_root, spec_.output_root, spec_.storage_root,
                                    spec_.work_dir);
  if (absl::Status s = CheckWritableDir(folders_.work_dir, "work dir"); !s.ok()) return s;
  absl::StatusOr<std::unique_ptr<JobStore>> store =
      JobStore::Open((fs::path(folders_.work_dir) / "jobs.db").string());
  if (!store.ok()) return store.status();
  store_ = *std::move(store);
  uploads_ =
      std::make_unique<UploadStore>(UploadStore::Options{.quota_bytes = spec_.upload_quota_bytes});
  CoordinatorCoreOptions core;
  core.leases.lease_timeout_ms = static_cast<int64_t>(spec_.lease_timeout_s * 1000);
  core.leases.max_attempts = spec_.max_attempts;
  core.worker_timeout_ms = static_cast<int64_t>(spec_.worker_timeout_s * 1000);
  core.folders = folders_;
  // Random: tells this coordinator's worker ids from a previous one's.
  core.instance = RandomHex(4);
  core_ = std::make_unique<CoordinatorCore>(*store_, LeaseTable::Clock::System(), std::move(core));

  job_service_ = std::make_unique<JobServiceAdapter>(*this);
  carve_service_ = std::make_unique<CarveServiceAdapter>(*this);
  GrpcServerSpec server;
  server.component = "coordinator";
  server.listen_address = spec_.listen_address;
  server.credentials = *std::move(credentials);
  // Oversize requests are refused by gRPC itself (RESOURCE_EXHAUSTED) before any handler.
  server.max_receive_message_bytes = spec_.max_request_bytes;
  server.services = {job_service_.get(), carve_service_.get()};
  server.health_listen_address = spec_.health_listen_address;
  absl::StatusOr<GrpcServers> servers = StartGrpcServer(server);
  if (!servers.ok()) return servers.status();
  servers_ = *std::move(servers);
  if (!spec_.metrics_listen_address.empty()) {
    absl::StatusOr<MetricsEndpoint> endpoint =
        ServeMetrics(spec_.metrics_listen_address, {metrics_.registry()}, "coordinator");
    if (!endpoint.ok()) return endpoint.status();
    metrics_endpoint_ = *std::move(endpoint);
  }
  servers_.MarkServing({"carvemap.v1.JobService", "carvemap.v1.CarveTaskService"});
  const bool loopback = IsLoopbackAddress(spec_.listen_address);
  if (tokens_.empty()) {
    spdlog::warn("coordinator: no bearer tokens: the job API is open, every caller is tenant "
                 "'{}'{}", kDefaultTenant,
                 loopback ? " (loopback only)" : " (--insecure, NOT loopback)");
  } else {
    spdlog::info("coordinator: {} bearer token(s) for {} tenant(s), {}", tokens_.size(),
                 tokens_.tenants().size(),
                 spec_.shared_dirs ? "sharing the data and output roots"
                                   : "each in its own folder under the data and output roots");
  }
  if (!spec_.cluster_secret.empty() || !spec_.tls_client_ca_file.empty()) {
    spdlog::info("coordinator: carve-task API needs {}",
                 spec_.cluster_secret.empty()       ? "a client certificate"
                 : spec_.tls_client_ca_file.empty() ? "the cluster secret"
                                                    : "the cluster secret or a client certificate");
  } else {
    spdlog::warn("coordinator: carve-task API open to any caller{}",
                 loopback ? " (loopback only)" : " (--insecure, NOT loopback)");
  }
  if (spec_.tls_cert_file.empty() && !loopback) {
    spdlog::warn("coordinator: plaintext on {}: tokens and data cross the network unencrypted "
                 "(give --tls-cert/--tls-key)", spec_.listen_address);
  }
  sweeper_ = std::thread([this] { SweepLoop(); });

  // Resume what a previous coordinator left unfinished: the store is the truth.
  for (JobState state : {JobState::kQueued, JobState::kIngesting, JobState::kCarving,
                         JobState::kMerging}) {
    ListJobsQuery q;
    q.state = state;
    q.limit = 1000;
    absl::StatusOr<std::vector<JobRecord>> jobs = store_->ListJobs(q);
    if (!jobs.ok()) return jobs.status();
    for (const JobRecord& job : *jobs) {
      spdlog::info("coordinator: resuming job {} ({})", job.id, std::string(JobStateName(job.state)));
      StartJobThread(job.id);
    }
  }
  spdlog::info("coordinator: listening on {}:{} (outputs {}, work dir {})",
               spec_.listen_address.substr(0, spec_.listen_address.rfind(':')), servers_.port,
               spec_.output_root, folders_.work_dir);
  return absl::OkStatus();
}

void CoordinatorServer::Impl::Shutdown() {
  absl::MutexLock shutdown_lock(&shutdown_mu_);
  if (shutdown_done_.HasBeenNotified()) return;
  stopping_ = true;
  if (core_) core_->Stop();
  JobsChanged();
  stop_sweeper_.Notify();
  // Streams and long polls see stopping_ within a poll interval; the deadline bounds the wait.
  servers_.Shutdown(std::chrono::milliseconds(500));
  if (sweeper_.joinable()) sweeper_.join();
  std::map<uint64_t, std::thread> threads;
  {
    absl::MutexLock lock(&threads_mu_);
    threads.swap(job_threads_);
    ended_job_threads_.clear();
  }
  for (auto& [key, t] : threads) t.join();
  metrics_endpoint_ = {};
  spdlog::info("coordinator: stopped");
  shutdown_done_.Notify();
}

void CoordinatorServer::Impl::SweepLoop() {
  const absl::Duration interval = absl::Seconds(spec_.sweep_interval_s);
  while (!stopping_) {
    const int64_t due = NowMs() + absl::ToInt64Milliseconds(interval);
    if (stop_sweeper_.WaitForNotificationWithTimeout(interval)) break;
    ReapJobThreads();
    const CoordinatorCore::SweepReport sweep = core_->Sweep(due);
    if (!sweep.expired.ok()) {
      spdlog::error("coordinator: expiring leases: {}", sweep.expired.status().ToString());
    } else if (*sweep.expired > 0) {
      spdlog::warn("coordinator: {} lease(s) expired and were requeued", *sweep.expired);
      metrics_.LeasesExpired(*sweep.expired);
      JobsChanged();  // a task out of attempts fails its job
    }
    for (const CoordinatorCore::SweepReport::LostWorker& lost : sweep.lost) {
      LogScope log_scope({{"worker", lost.worker_id}});
      spdlog::warn("coordinator: worker {} lost (no heartbeat for {:.1f} s); {} lease(s) requeued",
                   lost.worker_id, lost.silent_ms / 1000.0, lost.leases.ok() ? *lost.leases : -1);
      metrics_.WorkerLost(lost.leases.ok() ? *lost.leases : 0);
    }
    metrics_.SetChunks(sweep.tasks_queued, sweep.tasks_leased, sweep.tasks_done);
    metrics_.SetWorkers(sweep.workers);
    metrics_.SetActiveJobs(sweep.active_jobs);
    metrics_.UpdateRate(std::chrono::steady_clock::now());
  }
}

// ---- authentication

absl::StatusOr<CoordinatorServer::Impl::Caller> CoordinatorServer::Impl::AuthenticateTenant(
    const grpc::ServerContext& ctx) {
  if (tokens_.empty()) return Caller{kDefaultTenant, ""};
  const CallerBearer bearer = BearerOf(ctx);
  std::optional<std::string> tenant;
  if (bearer.token) tenant = tokens_.Lookup(*bearer.token);
  if (!tenant) {
    // The reason goes to the log (with the peer, never the token); the caller learns only
    // what to send.
    metrics_.CallRefused("job");
    spdlog::warn("coordinator: job API call from {} refused: {}", ctx.peer(),
                 !bearer.present ? "no authorization metadata"
                 : !bearer.token ? "authorization is not a bearer token"
                                 : "unknown bearer token");
    return absl::UnauthenticatedError(
        !bearer.present
            ? "missing bearer token: send metadata 'authorization: Bearer <token>' (carvemap: "
              "--token-file FILE or CARVEMAP_TOKEN)"
            : "invalid bearer token");
  }
  return Caller{*tenant, spec_.shared_dirs ? "" : *tenant};
}

absl::Status CoordinatorServer::Impl::AuthenticatePeer(const grpc::ServerContext& ctx) {
  if (IsClusterPeer(ctx, spec_.cluster_secret, spec_.tls_client_ca_file)) {
    return absl::OkStatus();
  }
  metrics_.CallRefused("carve");
  spdlog::warn("coordinator: carve-task call from {} refused: no cluster secret or client "
               "certificate", ctx.peer());
  return absl::UnauthenticatedError(
      "internal carve-task API: present the cluster secret ('authorization: Bearer <secret>', "
      "carvemap worker --cluster-secret-file) or a client certificate");
}

absl::StatusOr<JobRecord> CoordinatorServer::Impl::OwnJob(const Caller& caller,
                                                          const std::string& job_id) {
  // One message for "no such job" and "another tenant's job", built here (not the store's).
  auto not_found = [&] {
    return absl::NotFoundError(absl::StrCat("job ", job_id, " not found"));
  };
  if (job_id.empty()) return absl::InvalidArgumentError("job_id is empty");
  if (job_id.size() > 128) return absl::InvalidArgumentError("job_id longer than 128 bytes");
  absl::StatusOr<JobRecord> job = store_->GetJob(job_id);
  if (absl::IsNotFound(job.status())) return not_found();
  if (!job.ok()) return job.status();
  if (job->tenant != caller.tenant) return not_found();
  return job;
}

// ---- the job pipeline

void CoordinatorServer::Impl::EnterStage(const std::string& job_id, const std::string& stage) {
  core_->EnterStage(job_id, stage);
}

void CoordinatorServer::Impl::Moved(const std::string& job_id, JobState from, JobState to,
                                    const std::string& reason) {
  JobsChanged();
  if (to == JobState::kFailed) {
    spdlog::error("coordinator: job {} FAILED: {}", job_id, reason);
  } else {
    spdlog::info("coordinator: job {} {} -> {}", job_id, std::string(JobStateName(from)),
                 std::string(JobStateName(to)));
  }
}

void CoordinatorServer::Impl::NotMoved(const std::string& job_id, JobState to,
                                       const absl::Status& why) {
  JobsChanged();
  if (to == JobState::kFailed) {
    spdlog::warn("coordinator: job {}: could not mark FAILED: {}", job_id, why.ToString());
  }
}

void CoordinatorServer::Impl::CleanUp(const std::string& job_id, bool succeeded) {
  // Called once when a job's thread ends it (not when the coordinator stops: then it resumes).
  if (absl::StatusOr<JobRecord> job = store_->GetJob(job_id); job.ok() && IsTerminal(job->state)) {
    metrics_.JobFinished(JobStateName(job->state));
  }
  core_->DropTasks(job_id);
  const auto [tiles, partials] = core_->WithRuntime(
      job_id, [](const JobRuntime& rt) { return std::pair(rt.tiles_dir, rt.partials_dir); });
  std::error_code ec;
  if (!spec_.keep_partials && !partials.empty()) {
    fs::remove_all(fs::path(partials).parent_path(), ec);
  }
  // A failed or cancelled job leaves no tiles that could pass for a complete set.
  if (!succeeded && !tiles.empty()) {
    fs::remove_all(tiles, ec);
    fs::remove_all(ObjectTilesDir(tiles), ec);
  }
  // The job's plan, stage times and counts are in its job.json now (and it no longer counts as
  // active): a coordinator that runs for months must not keep them for every job it ran.
  core_->EraseRuntime(job_id);
}

absl::Status CoordinatorServer::Impl::EnsurePlan(const JobRecord& job) {
  if (core_->WithRuntime(job.id, [](const JobRuntime& rt) { return !rt.slices.empty(); })) {
    return absl::OkStatus();
  }
  // Checked again (the submit's check was then), through the descriptor opened here, so a
  // symlink swapped meanwhile cannot point the plan elsewhere, and errors name the path as the
  // tenant gave it. Workers open it the same way (SliceTask.scan_root, scan_path).
  absl::StatusOr<ConfinedFile> scan =
      ConfinedFile::Open(folders_.DataDir(job.tenant_dir), job.input_path, "input_path");
  if (!scan.ok()) return scan.status();
  absl::StatusOr<JobPlan> plan;
  {
    absl::MutexLock hdf5_lock(&hdf5_mu_);
    std::lock_guard<std::mutex> lock(Hdf5Lock());
    plan = PlanJob(scan->path(), JobParams::FromJson(job.params_json));
  }
  if (!plan.ok()) return scan->Rename(plan.status());
  const ScanNorth& north = plan->north;
  if (north.decision.warn) {
    spdlog::warn("coordinator: job {}: north: {}", job.id, north.decision.note);
  } else if (north.decision.turned) {
    spdlog::info("coordinator: job {}: turned {:.2f}° to {} north (§2.3)", job.id,
                 north.decision.yaw_rad * 180 / std::numbers::pi,
                 north.place ? "true" : "magnetic");
  }
  core_->WithRuntime(job.id, [&](JobRuntime& rt) {
    rt.world_yaw_rad = north.decision.yaw_rad;
    rt.north = NorthJson(north);
    rt.slices = std::move(plan->slices.slices);
    rt.slice_s = plan->slices.slice_s;
    rt.rays_to_carve = int64_t(plan->slices.rays);  // the slices' own rows partition every frame
  });
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::PlanStage(const JobRecord& job) {
  const auto [partials, tiles] = core_->WithRuntime(
      job.id, [](const JobRuntime& rt) { return std::pair(rt.partials_dir, rt.tiles_dir); });
  // Planning starts from scratch (also after a restart): an earlier attempt's partial sums and
  // tiles must not mix with this run's.
  std::error_code ec;
  fs::remove_all(partials, ec);
  fs::remove_all(tiles, ec);
  fs::create_directories(tiles, ec);
  if (!ec) fs::create_directories(partials, ec);
  if (ec) {
    return absl::FailedPreconditionError(absl::StrCat("tiles dir ", tiles, ": ", ec.message()));
  }
  if (absl::Status s = EnsurePlan(job); !s.ok()) return s;
  if (stopping_) return absl::CancelledError("coordinator stopping");
  absl::StatusOr<JobRecord> now = store_->GetJob(job.id);
  if (!now.ok()) return now.status();
  if (IsTerminal(now->state)) return absl::CancelledError("job ended while planned");
  const std::vector<ChunkRecord> records = core_->WithRuntime(job.id, [&](const JobRuntime& rt) {
    spdlog::info("coordinator: job {}: {} rays in {} slices of {:.1f} s", job.id, rt.rays_to_carve,
                 rt.slices.size(), rt.slice_s);
    return SliceTasks(job.id, rt.slices, 0);
  });
  return store_->AddChunks(job.id, records);
}

absl::StatusOr<std::vector<ChunkCoord>> CoordinatorServer::Impl::ChunksOfPass(
    const std::string& job_id) {
  const std::vector<std::string> paths = core_->WithRuntime(job_id, [](const JobRuntime& rt) {
    std::vector<std::string> out;
    for (const ScanSlice& s : rt.slices) out.push_back(SlicePartialPath(rt.pass_dir, s.index));
    return out;
  });
  return ChunksOfPartials(paths);
}

absl::Status CoordinatorServer::Impl::CarveStage(const std::string& job_id) {
  absl::StatusOr<JobRecord> job = store_->GetJob(job_id);
  if (!job.ok()) return job.status();
  if (absl::Status s = EnsurePlan(*job); !s.ok()) return s;
  const auto [tiles_dir, partials_dir] = core_->WithRuntime(job_id, [](JobRuntime& rt) {
    rt.pass = 0;
    rt.pass_dir = rt.partials_dir;
    rt.regions_path.clear();
    return std::pair(rt.tiles_dir, rt.partials_dir);
  });
  // A restarted coordinator may find the chunks to combine stored already.
  bool combines = false;
  if (absl::StatusOr<std::vector<ChunkRecord>> chunks = store_->ListChunks(job_id); chunks.ok()) {
    for (const ChunkRecord& c : *chunks) combines |= !IsSliceTask(c.key);
  }
  // What a restart finds done is trusted only if its file is there whole (docs/JOB_STORE.md,
  // "Durability"): a missing or short tile is combined again. A slice's partial sums are
  // checked only while no chunk is combined from them yet (a slice carved again then would
  // race the combines queued beside it); later a bad one fails its combine by its CRCs.
  const auto check = [&](const ChunkRecord& c) -> std::string {
    const bool slice = IsSliceTask(c.key);
    if (slice && combines) return "";
    const fs::path path = fs::path(slice ? partials_dir : tiles_dir) / c.tile_path;
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    std::string why;
    if (ec) {
      why = absl::StrCat(path.string(), ": ", ec.message());
    } else if (int64_t(size) != c.tile_size_bytes) {
      why = absl::StrCat(path.string(), ": ", size, " bytes, ", c.tile_size_bytes,
                         " when it was done");
    }
    if (!why.empty()) {
      spdlog::warn("coordinator: job {}: {}; its {} is carved again", job_id, why,
                   slice ? "slice" : "chunk");
    }
    return why;
  };
  if (absl::Status s = core_->LoadTasks(job_id, check); !s.ok()) return s;
  // The slices (and any chunks stored already).
  if (absl::Status s = core_->WaitForTasks(job_id); !s.ok()) return s;
  if (!combines) {
    absl::StatusOr<std::vector<ChunkCoord>> chunks = ChunksOfPass(job_id);
    if (!chunks.ok()) return chunks.status();
    std::vector<ChunkRecord> records;
    for (const ChunkCoord& c : *chunks) {
      ChunkRecord r;
      r.job_id = job_id;
      r.key = c;
      records.push_back(std::move(r));
    }
    if (absl::Status s = core_->AddTasks(job_id, records); !s.ok()) return s;
    spdlog::info("coordinator: job {}: slices carved; combining {} chunks", job_id,
                 records.size());
    if (absl::Status s = core_->WaitForTasks(job_id); !s.ok()) return s;
  }
  core_->DropTasks(job_id);
  // Every chunk is combined: nothing reads these sums again (a re-carve pass writes its own,
  // a restart in MERGING does not carve), so the scratch space goes now, not at the job's end.
  RemovePartials(job_id, partials_dir, /*files_only=*/true);
  return absl::OkStatus();
}

void CoordinatorServer::Impl::RemovePartials(const std::string& job_id, const std::string& dir,
                                             bool files_only) {
  if (spec_.keep_partials || dir.empty()) return;
  uint64_t bytes = 0, files = 0;
  std::error_code ec;
  // Listed first, removed after: the error_code forms never throw, an iterator's ++ may.
  std::vector<fs::path> entries;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    entries.push_back(it->path());
  }
  for (const fs::path& e : entries) {
    if (!fs::is_regular_file(e, ec)) {
      if (!files_only) fs::remove_all(e, ec);
      continue;
    }
    const uintmax_t size = fs::file_size(e, ec);
    if (fs::remove(e, ec)) {
      ++files;
      bytes += ec ? 0 : size;
    }
  }
  if (!files_only) fs::remove(dir, ec);
  spdlog::info("coordinator: job {}: {} partial-sums files removed ({:.1f} MB)", job_id, files,
               double(bytes) * 1e-6);
}

absl::StatusOr<std::string> CoordinatorServer::Impl::RecarveStage(
    const std::string& job_id, const std::vector<RecarveChunk>& chunks, double resolution_m) {
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
  if (!grid.ok()) return grid.status();
  absl::StatusOr<JobRecord> job = store_->GetJob(job_id);
  if (!job.ok()) return job.status();
  if (absl::Status s = EnsurePlan(*job); !s.ok()) return s;
  int pass = 0;
  const JobRuntime saved = core_->WithRuntime(job_id, [&](JobRuntime& rt) {
    JobRuntime before = rt;
    pass = ++rt.passes;
    return before;
  });
  const std::string dir = ObjectTilesDir(saved.tiles_dir);
  // A pass's partial sums go to a folder of their own (a merge asking again, after a restart
  // too, gets fresh files: a worker caches the indexes of the files it combines).
  const std::string pass_dir =
      (fs::path(saved.partials_dir) / absl::StrCat("p", pass, "-", RandomHex(4))).string();
  std::error_code ec;
  fs::remove_all(dir, ec);  // an earlier (interrupted) merge's: not this pass's
  fs::create_directories(dir, ec);
  if (!ec) fs::create_directories(pass_dir, ec);
  if (ec) {
    return absl::FailedPreconditionError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  CoordinatorCore::RecarvePass recarve{
      .pass = pass,
      .resolution_m = resolution_m,
      .grid_resolution_m = grid->resolution_m(),
      .tiles_dir = dir,
      .pass_dir = pass_dir,
      .regions_path = (fs::path(pass_dir) / "regions.bin").string(),
      .chunks = {}};
  for (const RecarveChunk& c : chunks) {
    recarve.chunks.push_back({c.chunk.x(), c.chunk.y(), c.chunk.z()});
  }
  if (absl::Status s = WriteRegionsFile(recarve.regions_path, chunks); !s.ok()) return s;
  if (absl::Status s = core_->StartRecarve(job_id, recarve); !s.ok()) return s;
  spdlog::info("coordinator: job {}: carving {} object chunks again at {} m (pass {})", job_id,
               chunks.size(), resolution_m, pass);
  absl::Status s = core_->WaitForTasks(job_id, /*except_held=*/true);
  if (s.ok()) s = core_->ReleaseTasks(job_id, recarve.chunks);
  if (s.ok()) s = core_->WaitForTasks(job_id);
  core_->EndRecarve(job_id, saved);
  if (!s.ok()) return s;
  RemovePartials(job_id, pass_dir, /*files_only=*/false);  // the pass's chunks are combined
  return dir;
}

void CoordinatorServer::Impl::RunJob(const std::string& job_id) {
  LogScope log_scope({{"job", job_id}});  // JSON logs: every line of this job's thread
  absl::StatusOr<JobRecord> job = store_->GetJob(job_id);
  if (!job.ok()) {
    spdlog::error("coordinator: job {}: {}", job_id, job.status().ToString());
    return;
  }
  core_->WithRuntime(job_id, [&](JobRuntime& rt) {
    rt.tiles_dir = fs::absolute(folders_.TilesDir(*job)).lexically_normal().string();
    rt.partials_dir = fs::absolute(folders_.PartialsDir(*job)).lexically_normal().string();
    rt.pass_dir = rt.partials_dir;
    rt.tenant_dir = job->tenant_dir;
    rt.input_path = job->input_path;
    rt.output_dir = fs::absolute(folders_.OutputDir(*job)).lexically_normal().string();
    rt.params = JobParams::FromJson(job->params_json);
  });
  absl::StatusOr<JobState> ended =
      carvemap::RunJob(job_id, *store_, *this, LeaseTable::Clock::System());
  if (!ended.ok()) spdlog::error("coordinator: job {}: {}", job_id, ended.status().ToString());
}

absl::Status CoordinatorServer::Impl::MergeStage(const JobRecord& job) {
  const std::string& job_id = job.id;
  // After a restart in MERGING the plan and the turn to north are made again from the scan.
  if (absl::Status s = EnsurePlan(job); !s.ok()) return s;
  MergeJobRequest req;
  const absl::StatusOr<JobRecord> stored = store_->GetJob(job_id);  // its counters now
  core_->WithRuntime(job_id, [&](const JobRuntime& rt) {
    req.job_id = job_id;
    req.tiles_dir = rt.tiles_dir;
    req.output_dir = rt.output_dir;
    // Filled in below, through a confined descriptor as in the ingest.
    req.params = rt.params.merge_params(rt.world_yaw_rad);
    req.job_json =
        MergeJobDocument(job, stored.ok() ? std::optional(stored->counters) : std::nullopt, rt)
            .dump();
  });
  // Merge stages show as "merge/<stage>" in the job's stage timings (WatchJob); a cancelled
  // job or a stopping coordinator stops the merge at its next progress call.
  std::string merge_stage;
  std::chrono::steady_clock::time_point last_check{};
  bool keep_going = true;
  req.progress = [&](const std::string& stage, uint64_t done, uint64_t total) {
    if (stage != merge_stage) {
      merge_stage = stage;
      EnterStage(job_id, "merge/" + stage);
    }
    core_->WithRuntime(job_id, [&](JobRuntime& rt) {
      rt.merge_done = done;
      rt.merge_total = total;
    });
    if (stopping_) return false;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_check > std::chrono::milliseconds(500)) {
      last_check = now;
      absl::StatusOr<JobRecord> j = store_->GetJob(job_id);
      keep_going = !(j.ok() && IsTerminal(j->state));
    }
    return keep_going;
  };
  req.recarve = [this, &job_id](const std::vector<RecarveChunk>& chunks, double resolution_m) {
    LogScope log_scope({{"job", job_id}});  // the merge may call it from a thread of its own
    return RecarveStage(job_id, chunks, resolution_m);
  };
  if (spec_.merge) {
    // The merge opens the scan itself, confined to the tenant's folder as at submit and
    // ingest (LocalMerge here, or a merge service on the same shared storage).
    req.scan_root = fs::absolute(folders_.DataDir(job.tenant_dir)).lexically_normal().string();
    req.scan_input = job.input_path;
    absl::Status merged;
    if (spec_.merge_in_process) {
      absl::MutexLock lock(&hdf5_mu_);
      merged = spec_.merge(req);
    } else {
      merged = spec_.merge(req);
    }
    if (!merged.ok()) return merged;
  } else {
    spdlog::warn("coordinator: job {}: no merge step configured; tiles only", job_id);
  }
  return absl::OkStatus();
}

// ---- JobService

absl::Status CoordinatorServer::Impl::SubmitJob(const Caller& caller,
                                                const pb::SubmitJobRequest& req,
                                                pb::SubmitJobResponse& resp) {
  if (stopping_) return absl::UnavailableError("coordinator shutting down");
  SubmitRequest submit{.tenant = caller.tenant,
                       .tenant_dir = caller.tenant_dir,
                       .input_path = req.input_path(),
                       .output_name = req.output_name(),
                       .params = FromProto(req.params()),
                       .idempotency_key = req.idempotency_key()};
  if (req.input_case() == pb::SubmitJobRequest::kUploadId) {
    absl::StatusOr<UploadState> upload =
        uploads_->Find(folders_.DataDir(caller.tenant_dir), req.upload_id());
    if (!upload.ok()) return upload.status();
    if (!upload->complete) {
      return absl::FailedPreconditionError(
          absl::StrCat("upload ", upload->id, " holds ", upload->received_bytes, " of ",
                       upload->size_bytes, " bytes: finish it first"));
    }
    submit.input_path = upload->input_path;
  }
  absl::StatusOr<SubmitOutcome> outcome = carvemap::SubmitJob(
      submit,
      {.store = store_.get(),
       .folders = folders_,
       .max_jobs_per_tenant = spec_.max_jobs_per_tenant,
       .now_unix_ms = NowMs(),
       .new_job_id = NewJobId,
       .server_note = [](const std::string& note) { spdlog::error("coordinator: {}", note); }});
  if (!outcome.ok()) return outcome.status();
  const JobRecord& job = outcome->job;
  ToProto(job, *resp.mutable_job());
  if (outcome->deduplicated) {
    resp.set_deduplicated(true);
    return absl::OkStatus();
  }
  LogScope log_scope({{"job", job.id}, {"tenant", job.tenant}});
  spdlog::info("coordinator: job {} of tenant {} submitted: {} -> {} (resolution {} m)", job.id,
               job.tenant, (fs::path(folders_.DataDir(job.tenant_dir)) / job.input_path).string(),
               folders_.OutputDir(job), JobParams::FromJson(job.params_json).resolution_m);
  metrics_.JobSubmitted();
  StartJobThread(job.id);
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::GetJob(const Caller& caller, const pb::GetJobRequest& req,
                                             pb::Job& resp) {
  absl::StatusOr<JobRecord> job = OwnJob(caller, req.job_id());
  if (!job.ok()) return job.status();
  ToProto(*job, resp);
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::CancelJob(const Caller& caller,
                                                const pb::CancelJobRequest& req,
                                                pb::CancelJobResponse& resp) {
  absl::StatusOr<JobRecord> job = OwnJob(caller, req.job_id());
  if (!job.ok()) return job.status();
  if (req.reason().size() > 1024) {
    return absl::InvalidArgumentError("reason longer than 1024 bytes");
  }
  if (job->state == JobState::kSucceeded || job->state == JobState::kFailed) {
    return absl::FailedPreconditionError(
        absl::StrCat("job ", job->id, " is ", JobStateName(job->state), ": cannot cancel"));
  }
  if (job->state != JobState::kCancelled) {
    std::string why = "cancelled by client";
    if (!req.reason().empty()) absl::StrAppend(&why, ": ", req.reason());
    absl::Status s = store_->TransitionJob(job->id, {JobState::kCancelled, why, NowMs()});
    // A race with the job reaching a terminal state on its own: report what it is now.
    if (!s.ok() && !absl::IsFailedPrecondition(s)) return s;
    if (s.ok()) spdlog::info("coordinator: job {} cancelled", job->id);
    core_->DropTasks(job->id);
    JobsChanged();
  }
  absl::StatusOr<JobRecord> now = store_->GetJob(req.job_id());
  if (!now.ok()) return now.status();
  ToProto(*now, *resp.mutable_job());
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::ListJobs(const Caller& caller,
                                               const pb::ListJobsRequest& req,
                                               pb::ListJobsResponse& resp) {
  ListJobsQuery q;
  q.tenant = caller.tenant;
  const int page = req.page_size() <= 0 ? 50 : std::min(req.page_size(), 500);
  q.limit = page + 1;  // one more tells whether there is a next page
  if (req.state_filter() != pb::JOB_STATE_UNSPECIFIED) {
    q.state = static_cast<JobState>(static_cast<int>(req.state_filter()));
  }
  if (!req.page_token().empty()) {
    // Token: "<created_unix_ms>:<job id>" of the last job of the previous page.
    const size_t colon = req.page_token().find(':');
    int64_t ms = 0;
    if (colon == std::string::npos ||
        !absl::SimpleAtoi(req.page_token().substr(0, colon), &ms)) {
      return absl::InvalidArgumentError("page_token does not parse");
    }
    q.before = std::make_pair(ms, req.page_token().substr(colon + 1));
  }
  absl::StatusOr<std::vector<JobRecord>> jobs = store_->ListJobs(q);
  if (!jobs.ok()) return jobs.status();
  for (int i = 0; i < static_cast<int>(jobs->size()) && i < page; ++i) {
    ToProto((*jobs)[i], *resp.add_jobs());
  }
  if (static_cast<int>(jobs->size()) > page) {
    const JobRecord& last = (*jobs)[page - 1];
    resp.set_next_page_token(absl::StrCat(last.created_unix_ms, ":", last.id));
  }
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::WatchJob(const Caller& caller, grpc::ServerContext& ctx,
                                               const pb::WatchJobRequest& req,
                                               grpc::ServerWriter<pb::JobEvent>& writer) {
  absl::StatusOr<JobRecord> job = OwnJob(caller, req.job_id());
  if (!job.ok()) return job.status();
  int64_t sequence = 0;
  auto event = [&]() {
    pb::JobEvent e;
    e.set_time_unix_ms(NowMs());
    e.set_sequence(++sequence);
    return e;
  };
  {
    pb::JobEvent e = event();
    ToProto(*job, *e.mutable_snapshot());
    if (!writer.Write(e)) return absl::OkStatus();
  }
  const double min_interval_s = req.min_interval_s() > 0 ? req.min_interval_s() : 1.0;
  JobState state = job->state;
  auto last_progress = std::chrono::steady_clock::now();
  uint64_t seen;
  {
    absl::MutexLock lock(&watch_mu_);
    seen = job_events_;
  }
  while (!IsTerminal(state)) {
    {
      // Until a job changes state (JobsChanged) or the next progress event is due: at least
      // 0.2 s (a client asking for a tiny interval must not turn the stream into a busy poll
      // of the store), at most a second (a client that went away is noticed).
      const double due_s =
          min_interval_s -
          std::chrono::duration<double>(std::chrono::steady_clock::now() - last_progress).count();
      const absl::Time deadline = absl::Now() + absl::Seconds(std::clamp(due_s, 0.2, 1.0));
      absl::MutexLock lock(&watch_mu_);
      while (job_events_ == seen && !stopping_) {
        if (watch_cv_.WaitWithDeadline(&watch_mu_, deadline)) break;
      }
      seen = job_events_;
    }
    if (ctx.IsCancelled()) return absl::CancelledError("watch cancelled by the client");
    if (stopping_) return absl::UnavailableError("coordinator shutting down");
    job = store_->GetJob(req.job_id());
    if (!job.ok()) return job.status();
    const JobState from = state;
    const bool changed = job->state != state;
    state = job->state;
    const auto now = std::chrono::steady_clock::now();
    // A state change is preceded by fresh counters, so a client never shows the new state with
    // old counts, and the terminal state change stays the last event.
    if (changed || std::chrono::duration<double>(now - last_progress).count() >= min_interval_s) {
      if (!WriteProgress(writer, event(), *job, state)) {
        return absl::OkStatus();
      }
      last_progress = now;
    }
    if (changed) {
      pb::JobEvent e = event();
      auto* sc = e.mutable_state_change();
      sc->set_from_state(static_cast<pb::JobState>(static_cast<int>(from)));
      sc->set_to_state(static_cast<pb::JobState>(static_cast<int>(state)));
      sc->set_error(job->error);
      if (!writer.Write(e)) return absl::OkStatus();
    }
  }
  return absl::OkStatus();
}

bool CoordinatorServer::Impl::WriteProgress(grpc::ServerWriter<pb::JobEvent>& writer,
                                            pb::JobEvent e, const JobRecord& job, JobState state) {
  auto* p = e.mutable_progress();
  auto* c = p->mutable_chunks();
  c->set_chunks_total(job.counters.chunks_total);
  c->set_chunks_done(job.counters.chunks_done);
  c->set_chunks_leased(job.counters.chunks_leased);
  c->set_chunk_retries(job.counters.chunk_retries);
  const CoordinatorCore::WatchSnapshot snapshot = core_->Watch(job.id, job.counters, state);
  if (const std::optional<JobProgress>& progress = snapshot.progress) {
    p->set_rays_done(progress->rays_done);
    p->set_rays_total(progress->rays_total);
    p->set_rays_per_s(progress->rays_per_s);
    p->set_eta_s(progress->eta_s);
    p->set_stage_done(progress->stage_done);
    p->set_stage_total(progress->stage_total);
    for (const StageTimes::Stage& stage : progress->stages) {
      auto* st = p->add_stages();
      st->set_stage(stage.name);
      st->set_elapsed_s(stage.elapsed_s);
      st->set_finished(stage.finished);
    }
  }
  p->set_active_workers(snapshot.active_workers);
  return writer.Write(e);
}

absl::Status CoordinatorServer::Impl::FetchArtifact(const Caller& caller,
                                                    grpc::ServerContext& ctx,
                                                    const pb::FetchArtifactRequest& req,
                                                    grpc::ServerWriter<pb::ArtifactChunk>& writer) {
  absl::StatusOr<JobRecord> job = OwnJob(caller, req.job_id());
  if (!job.ok()) return job.status();
  if (absl::Status s = CheckConfinedPathText(req.name(), "artifact"); !s.ok()) return s;
  // Outputs never start with '.'; hidden names are the servers' own (a `carvemap run`
  // output folder holds .carvemap/ with the job store and its secrets).
  for (absl::string_view part : absl::StrSplit(req.name(), '/', absl::SkipEmpty())) {
    if (absl::StartsWith(part, ".")) {
      return absl::InvalidArgumentError(
          absl::StrCat("artifact '", req.name(), "': no part of an output name starts with '.'"));
    }
  }
  // Resolved under the job's output folder like an input under the data root.
  absl::StatusOr<ConfinedFile> file =
      ConfinedFile::Open(folders_.OutputDir(*job), req.name(), "artifact");
  if (absl::IsNotFound(file.status())) {
    if (job->state != JobState::kSucceeded) {
      return absl::FailedPreconditionError(absl::StrCat("job ", job->id, " is ",
                                                        JobStateName(job->state), ": artifact '",
                                                        req.name(), "' not written yet"));
    }
    return absl::NotFoundError(absl::StrCat("job ", job->id, ": no artifact '", req.name(), "'"));
  }
  if (!file.ok()) return file.status();
  const int64_t size = file->size_bytes();
  if (req.offset() < 0 || req.offset() > size) {
    return absl::OutOfRangeError(absl::StrCat("offset ", req.offset(), " past the end (", size,
                                              " bytes)"));
  }
  // 4 MiB of data plus the message's own fields must fit a client's default 4 MiB limit.
  const int64_t chunk = req.chunk_size_bytes() <= 0
                            ? (1 << 20)
                            : std::clamp<int64_t>(req.chunk_size_bytes(), 4096, (4 << 20) - 1024);
  // The hash covers the whole artifact, also the bytes before `offset`.
  absl::StatusOr<std::string> sha = Sha256HexOfFile(file->path());
  if (!sha.ok()) return file->Rename(sha.status());
  std::string buf(static_cast<size_t>(chunk), '\0');
  int64_t offset = req.offset();
  do {
    if (ctx.IsCancelled()) break;
    const ssize_t got = ::pread(file->fd(), buf.data(), buf.size(), static_cast<off_t>(offset));
    if (got < 0) {
      return absl::InternalError(absl::StrCat("job ", job->id, ": artifact '", req.name(),
                                              "': read error: ", std::strerror(errno)));
    }
    const size_t n = static_cast<size_t>(got);
    pb::ArtifactChunk out;
    out.set_offset(offset);
    out.set_data(buf.data(), n);
    out.set_total_size_bytes(size);
    offset += static_cast<int64_t>(n);
    if (offset >= size) {
      out.set_last(true);
      out.set_sha256_hex(*sha);
    }
    if (!writer.Write(out)) break;
    if (n == 0) break;
  } while (offset < size);
  return absl::OkStatus();
}

// ---- Uploads

absl::Status CoordinatorServer::Impl::StartUpload(const Caller& caller,
                                                  const pb::StartUploadRequest& req,
                                                  pb::Upload& resp) {
  if (stopping_) return absl::UnavailableError("coordinator shutting down");
  const std::string dir = folders_.DataDir(caller.tenant_dir);
  if (absl::Status s = CheckWritableDir(dir, "data folder"); !s.ok()) {
    spdlog::error("coordinator: uploads of tenant {}: {}", caller.tenant, s.ToString());
    return absl::FailedPreconditionError(
        "the tenant's data folder cannot be written: this server takes no uploads");
  }
  absl::StatusOr<UploadState> upload =
      uploads_->Start(dir, {req.name(), req.size_bytes(), req.sha256_hex()}, NowMs());
  if (!upload.ok()) return upload.status();
  ToProto(*upload, resp);
  if (!upload->complete) {
    spdlog::info("coordinator: upload {} of tenant {}: {} ({} bytes), {} bytes held", upload->id,
                 caller.tenant, upload->input_path, upload->size_bytes, upload->received_bytes);
  }
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::UploadScan(const Caller& caller,
                                                 grpc::ServerReader<pb::UploadScanRequest>& reader,
                                                 pb::Upload& resp) {
  if (stopping_) return absl::UnavailableError("coordinator shutting down");
  pb::UploadScanRequest msg;
  if (!reader.Read(&msg)) return absl::InvalidArgumentError("UploadScan: no message in the stream");
  const std::string id = msg.upload_id();
  absl::StatusOr<std::unique_ptr<UploadWriter>> writer =
      uploads_->OpenWriter(folders_.DataDir(caller.tenant_dir), id);
  if (!writer.ok()) return writer.status();
  do {
    if (stopping_) {
      return absl::UnavailableError(
          absl::StrCat("coordinator shutting down: resume upload ", id, " later"));
    }
    if (msg.upload_id() != id) {
      return absl::InvalidArgumentError(
          absl::StrCat("every message of an UploadScan stream must name upload ", id));
    }
    if (absl::Status s = (*writer)->Append(msg.offset(), msg.data()).status(); !s.ok()) return s;
  } while (reader.Read(&msg));
  // The stream ended (the client finished, or went away: then no one reads the answer).
  const UploadState& state = (*writer)->state();
  if (state.received_bytes == state.size_bytes && !state.complete) {
    absl::StatusOr<UploadState> done = (*writer)->Finish();
    if (!done.ok()) {
      spdlog::warn("coordinator: upload {} of tenant {}: {}", id, caller.tenant,
                   done.status().ToString());
      return done.status();
    }
    spdlog::info("coordinator: upload {} of tenant {} complete: {} ({} bytes)", id, caller.tenant,
                 done->input_path, done->size_bytes);
  }
  ToProto((*writer)->state(), resp);
  return absl::OkStatus();
}

// ---- CarveTaskService

absl::Status CoordinatorServer::Impl::RegisterWorker(grpc::ServerContext& ctx,
                                                     const pb::RegisterWorkerRequest& req,
                                                     pb::RegisterWorkerResponse& resp) {
  if (stopping_) return absl::UnavailableError("coordinator shutting down");
  const std::string id = core_->RegisterWorker();
  LogScope log_scope({{"worker", id}});
  spdlog::info("coordinator: worker {} registered (host {}, {} thread(s), peer {})", id,
               req.hostname(), req.threads(), ctx.peer());
  resp.set_worker_id(id);
  resp.set_heartbeat_interval_s(spec_.heartbeat_interval_s);
  resp.set_worker_timeout_s(spec_.worker_timeout_s);
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::Heartbeat(const pb::HeartbeatRequest& req,
                                                pb::HeartbeatResponse& resp) {
  absl::StatusOr<CoordinatorCore::HeartbeatReply> reply = core_->Heartbeat(
      {.worker_id = req.worker_id(),
       .rays_carved = req.rays_carved(),
       .report_leases = req.report_leases(),
       .active_lease_ids = {req.active_lease_ids().begin(), req.active_lease_ids().end()}});
  if (!reply.ok()) return reply.status();
  if (req.rays_carved() > 0) metrics_.RaysCarvedLive(req.rays_carved());
  for (const std::string& lease : reply->revoked_lease_ids) resp.add_revoked_lease_ids(lease);
  if (reply->lease_deadline_unix_ms) {
    resp.set_lease_deadline_unix_ms(*reply->lease_deadline_unix_ms);
  }
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::LeaseChunk(grpc::ServerContext& ctx,
                                                 const pb::LeaseChunkRequest& req,
                                                 pb::LeaseChunkResponse& resp) {
  if (req.worker_id().empty()) return absl::InvalidArgumentError("empty worker id");
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration<double>(std::clamp(req.wait_s(), 0.0, 30.0));
  while (true) {
    if (stopping_) return absl::UnavailableError("coordinator shutting down");
    // Parked in the core until work may have been queued or the call's time is up; at most a
    // second at a time: a worker that gives up is noticed within it.
    const double left_s =
        std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
    absl::StatusOr<std::optional<CarveTask>> task =
        core_->Lease(req.worker_id(), absl::Seconds(std::clamp(left_s, 0.0, 1.0)),
                     [&ctx] { return ctx.IsCancelled(); });
    if (!task.ok()) return task.status();
    if (*task) {
      const LeaseTable::Grant& grant = (*task)->grant;
      LogScope log_scope(LeaseLogFields(grant.lease_id, req.worker_id()));
      ToProto(**task, *resp.mutable_lease());
      spdlog::debug("coordinator: lease {} -> {} (attempt {})", grant.lease_id, req.worker_id(),
                    grant.attempt);
      return absl::OkStatus();
    }
    if (std::chrono::steady_clock::now() >= deadline || ctx.IsCancelled()) break;
  }
  resp.set_retry_after_s(0.25);
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::CheckLeaseJob(absl::string_view lease_id, JobRecord* out) {
  absl::StatusOr<std::string> job_id = JobOfLease(lease_id);
  if (!job_id.ok()) return job_id.status();
  absl::StatusOr<JobRecord> job = store_->GetJob(*job_id);
  if (!job.ok()) return job.status();
  if (out != nullptr) *out = *job;
  if (IsTerminal(job->state)) {
    return absl::FailedPreconditionError(absl::StrCat("lease ", lease_id, ": job ", job->id,
                                                      " is ", JobStateName(job->state)));
  }
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::CompleteChunk(const pb::CompleteChunkRequest& req,
                                                    pb::CompleteChunkResponse& resp) {
  LogScope log_scope(LeaseLogFields(req.lease_id(), req.worker_id()));
  JobRecord job;
  if (absl::Status s = CheckLeaseJob(req.lease_id(), &job); !s.ok()) {
    // A tile finished after its job failed or was cancelled: the job's cleanup has already
    // run, so remove the late tile here, or it would sit in a tiles dir that looks partial.
    if ((job.state == JobState::kFailed || job.state == JobState::kCancelled) &&
        ValidRelativePath(req.tile().path())) {
      std::error_code ec;
      fs::remove(fs::path(folders_.TilesDir(job)) / req.tile().path(), ec);
    }
    return s;
  }
  const pb::CarveStats& st = req.stats();
  absl::StatusOr<LeaseTable::Progress> p = core_->Complete(
      {.worker_id = req.worker_id(),
       .lease_id = req.lease_id(),
       .generation = req.generation(),
       .tile = {req.tile().path(), req.tile().size_bytes(), req.tile().sha256_hex()},
       .counts = {.frames = st.frames(),
                  .rays = st.rays(),
                  .returns = st.returns(),
                  .wedges = st.wedges(),
                  .wedge_chunk_pairs = st.wedge_chunk_pairs(),
                  .leaf_updates = st.leaf_updates(),
                  .partial_bytes = st.partial_bytes()}});
  if (!p.ok()) {
    spdlog::info("coordinator: completion of {} by {} rejected: {}", req.lease_id(),
                 req.worker_id(), p.status().ToString());
    return p.status();
  }
  metrics_.ChunkCompleted(st.rays());
  resp.mutable_progress()->set_chunks_total(p->chunks_total);
  resp.mutable_progress()->set_chunks_done(p->chunks_done);
  resp.mutable_progress()->set_chunks_leased(p->chunks_leased);
  resp.mutable_progress()->set_chunk_retries(p->chunk_retries);
  return absl::OkStatus();
}

absl::Status CoordinatorServer::Impl::FailChunk(const pb::FailChunkRequest& req,
                                                pb::FailChunkResponse& resp) {
  LogScope log_scope(LeaseLogFields(req.lease_id(), req.worker_id()));
  if (absl::Status s = CheckLeaseJob(req.lease_id()); !s.ok()) return s;
  absl::StatusOr<bool> requeued =
      core_->Fail(req.worker_id(), req.lease_id(), req.generation(), req.reason(), req.retryable());
  if (!requeued.ok()) return requeued.status();
  if (!*requeued) JobsChanged();
  metrics_.ChunkFailed();
  spdlog::warn("coordinator: worker {} failed {}: {} ({})", req.worker_id(), req.lease_id(),
               req.reason(), *requeued ? "requeued" : "job failed");
  resp.set_requeued(*requeued);
  return absl::OkStatus();
}

// ---- public shell

CoordinatorServer::CoordinatorServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
CoordinatorServer::~CoordinatorServer() = default;

absl::StatusOr<std::unique_ptr<CoordinatorServer>> CoordinatorServer::Start(CoordinatorSpec spec) {
  auto impl = std::make_unique<Impl>(std::move(spec));
  if (absl::Status s = impl->Start(); !s.ok()) return s;
  return std::unique_ptr<CoordinatorServer>(new CoordinatorServer(std::move(impl)));
}

int CoordinatorServer::port() const { return impl_->port(); }
int CoordinatorServer::health_port() const { return impl_->health_port(); }
int CoordinatorServer::metrics_port() const { return impl_->metrics_port(); }
std::string CoordinatorServer::MetricsText() const { return impl_->metrics().Text(); }
void CoordinatorServer::Shutdown() { impl_->Shutdown(); }
void CoordinatorServer::Wait() { impl_->Wait(); }

}  // namespace carvemap
