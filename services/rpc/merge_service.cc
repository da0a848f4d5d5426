#include "services/rpc/merge_service.h"

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <utility>

#include <spdlog/spdlog.h>

#include "absl/base/thread_annotations.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "proto/carvemap/v1/merge.grpc.pb.h"
#include "services/rpc/bearer_tokens.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/grpc_server_common.h"
#include "services/rpc/grpc_status.h"
#include "services/rpc/merge_metrics.h"
#include "services/rpc/merge_params_proto.h"
#include "services/rpc/process_metrics.h"
#include "services/rpc/server_log.h"

namespace carvemap {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;

namespace {

using Stream = grpc::ServerReaderWriter<pb::MergeServerMessage, pb::MergeClientMessage>;
using Clock = std::chrono::steady_clock;

// Progress goes out when the stage changes or at most this often (a stage reports per tile).
constexpr auto kProgressInterval = std::chrono::milliseconds(200);
// A RecarveRequest part holds about this many bytes of regions (gRPC's default limit on what
// the coordinator accepts is 4 MiB; RemoteMerge raises it, and parts stay well below).
constexpr size_t kRecarvePartBytes = size_t{1} << 20;

// The process's resident and peak resident memory, MiB. Logged as each merge stage starts:
// the stage during which the peak rose is the one that sizes the merge service
// (deploy/k8s/base/merger.yaml).
std::pair<double, double> ResidentMiB() {
  const ProcessStats s = ReadProcessStats();
  return {double(s.resident_bytes) / (1 << 20), double(s.peak_resident_bytes) / (1 << 20)};
}

absl::Status ValidateJob(const pb::MergeJob& job) {
  if (job.job_id().empty() || job.job_id().size() > 128) {
    return absl::InvalidArgumentError("MergeJob.job_id: empty or longer than 128 bytes");
  }
  for (const auto& [name, path] : {std::pair{"tiles_dir", &job.tiles_dir()},
                                   std::pair{"output_dir", &job.output_dir()}}) {
    if (path->empty() || !fs::path(*path).is_absolute()) {
      return absl::InvalidArgumentError(
          absl::StrCat("MergeJob.", name, " '", *path, "': must be an absolute path"));
    }
  }
  if (job.scan_path().empty() != job.scan_root().empty()) {
    return absl::InvalidArgumentError("MergeJob: scan_root and scan_path go together");
  }
  if (!job.scan_root().empty() && !fs::path(job.scan_root()).is_absolute()) {
    return absl::InvalidArgumentError(
        absl::StrCat("MergeJob.scan_root '", job.scan_root(), "': must be an absolute path"));
  }
  if (job.resolution_m() < 0 || job.object_resolution_m() < 0) {
    return absl::InvalidArgumentError("MergeJob: negative resolution");
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status MergeServerSpec::Validate() const {
  if (listen_address.empty()) return absl::InvalidArgumentError("merger: listen address is empty");
  if (tls_cert_file.empty() != tls_key_file.empty()) {
    return absl::InvalidArgumentError("TLS needs both --tls-cert and --tls-key");
  }
  if (!tls_client_ca_file.empty() && tls_cert_file.empty()) {
    return absl::InvalidArgumentError(
        "--tls-client-ca (mutual TLS) needs the server's own --tls-cert and --tls-key");
  }
  if (!cluster_secret.empty()) {
    if (absl::Status s = ValidateSecret(cluster_secret, "cluster secret"); !s.ok()) return s;
  }
  if (max_request_bytes < 4096) {
    return absl::InvalidArgumentError("max_request_bytes must be >= 4096");
  }
  if (!IsLoopbackAddress(listen_address) && !insecure && cluster_secret.empty() &&
      tls_client_ca_file.empty()) {
    return absl::FailedPreconditionError(absl::StrCat(
        "listening on ", listen_address, " (not loopback) with an open merge API: anyone who "
        "reaches it could have the merge read and write any path the service can. Give "
        "--cluster-secret-file FILE (or CARVEMAP_CLUSTER_SECRET), or --tls-client-ca for mutual "
        "TLS, or --insecure"));
  }
  return absl::OkStatus();
}

class MergeServer::Impl {
 public:
  explicit Impl(MergeServerSpec spec) : spec_(std::move(spec)) {
    if (!spec_.merge) spec_.merge = LocalMerge(spec_.memory_budget_bytes);
  }
  ~Impl() { Shutdown(); }

  absl::Status Start();
  void Shutdown();
  void Wait() { shutdown_done_.WaitForNotification(); }
  int port() const { return servers_.port; }
  int health_port() const { return servers_.health_port; }
  int metrics_port() const { return metrics_endpoint_.port; }

  absl::Status Authenticate(const grpc::ServerContext& ctx);
  // One call: the job, the merge, the verdict. Errors are the call's own (the merge's
  // failure is a MergeResult and the call ends OK).
  absl::Status Serve(grpc::ServerContext& ctx, Stream& stream);

 private:
  // Waits until no other merge runs in this process; then this call holds the slot.
  absl::Status TakeSlot(grpc::ServerContext& ctx, Stream& stream);
  void ReleaseSlot() {
    absl::MutexLock lock(&mu_);
    busy_ = false;
  }
  // §5.6.1 through the coordinator: sends the request in parts, waits for its answer.
  absl::StatusOr<std::string> Recarve(Stream& stream, uint64_t id,
                                      const std::vector<RecarveChunk>& chunks,
                                      double resolution_m);

  MergeServerSpec spec_;
  std::unique_ptr<grpc::Service> service_;
  GrpcServers servers_;  // the merge API; the plaintext health port if asked for
  MergeMetrics metrics_;
  MetricsEndpoint metrics_endpoint_;  // spec_.metrics_listen_address
  std::atomic<bool> stopping_{false};
  absl::Mutex shutdown_mu_;
  absl::Notification shutdown_done_;
  absl::Mutex mu_;
  bool busy_ ABSL_GUARDED_BY(mu_) = false;
};

namespace {

class MergeServiceAdapter final : public pb::MergeService::Service {
 public:
  explicit MergeServiceAdapter(MergeServer::Impl& impl) : impl_(impl) {}
  grpc::Status Merge(grpc::ServerContext* ctx, Stream* stream) override {
    if (absl::Status s = impl_.Authenticate(*ctx); !s.ok()) return ToGrpcStatus(s);
    return ToGrpcStatus(impl_.Serve(*ctx, *stream));
  }

 private:
  MergeServer::Impl& impl_;
};

}  // namespace

absl::Status MergeServer::Impl::Start() {
  if (absl::Status s = spec_.Validate(); !s.ok()) return s;
  absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
      ServerCredentialsFor(spec_.tls_cert_file, spec_.tls_key_file, spec_.tls_client_ca_file);
  if (!credentials.ok()) return credentials.status();
  service_ = std::make_unique<MergeServiceAdapter>(*this);
  GrpcServerSpec server;
  server.component = "merger";
  server.listen_address = spec_.listen_address;
  server.credentials = *std::move(credentials);
  server.max_receive_message_bytes = spec_.max_request_bytes;
  server.services = {service_.get()};
  // A merge stage can run for minutes without a message either way; keepalive pings find a
  // coordinator that is gone (host lost, network cut) so the merge stops, and the server
  // accepts the coordinator's own pings (RemoteMerge sends one every 10 s).
  server.channel_args = {{GRPC_ARG_KEEPALIVE_TIME_MS, 10000},
                         {GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 10000},
                         {GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0},
                         {GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 5000}};
  server.health_listen_address = spec_.health_listen_address;
  absl::StatusOr<GrpcServers> servers = StartGrpcServer(server);
  if (!servers.ok()) return servers.status();
  servers_ = *std::move(servers);
  servers_.MarkServing({"carvemap.v1.MergeService"});
  const bool loopback = IsLoopbackAddress(spec_.listen_address);
  if (!spec_.cluster_secret.empty() || !spec_.tls_client_ca_file.empty()) {
    spdlog::info("merger: merge API needs {}",
                 spec_.cluster_secret.empty()       ? "a client certificate"
                 : spec_.tls_client_ca_file.empty() ? "the cluster secret"
                                                    : "the cluster secret or a client certificate");
  } else {
    spdlog::warn("merger: merge API open to any caller{}",
                 loopback ? " (loopback only)" : " (--insecure, NOT loopback)");
  }
  spdlog::info("merger: listening on {}:{}",
               spec_.listen_address.substr(0, spec_.listen_address.rfind(':')), servers_.port);
  if (!spec_.metrics_listen_address.empty()) {
    absl::StatusOr<MetricsEndpoint> endpoint =
        ServeMetrics(spec_.metrics_listen_address, {metrics_.registry()}, "merger");
    if (!endpoint.ok()) return endpoint.status();
    metrics_endpoint_ = *std::move(endpoint);
  }
  return absl::OkStatus();
}

void MergeServer::Impl::Shutdown() {
  absl::MutexLock shutdown_lock(&shutdown_mu_);
  if (shutdown_done_.HasBeenNotified()) return;
  stopping_ = true;
  // A running merge sees stopping_ at its next progress step and its call ends UNAVAILABLE
  // (the coordinator runs it again); the deadline cancels calls still waiting.
  servers_.Shutdown(std::chrono::seconds(2));
  spdlog::info("merger: stopped");
  shutdown_done_.Notify();
}

absl::Status MergeServer::Impl::Authenticate(const grpc::ServerContext& ctx) {
  if (IsClusterPeer(ctx, spec_.cluster_secret, spec_.tls_client_ca_file)) {
    return absl::OkStatus();
  }
  // The reason goes to the log with the peer, never the token.
  spdlog::warn("merger: merge call from {} refused: no cluster secret or client certificate",
               ctx.peer());
  return absl::UnauthenticatedError(
      "internal merge API: present the cluster secret ('authorization: Bearer <secret>', "
      "carvemap coordinator --cluster-secret-file) or a client certificate");
}

absl::Status MergeServer::Impl::TakeSlot(grpc::ServerContext& ctx, Stream& stream) {
  bool queued = false;
  auto leave = [&](absl::Status s) {
    if (queued) metrics_.Dequeued();
    return s;
  };
  while (true) {
    {
      absl::MutexLock lock(&mu_);
      if (!busy_) {
        busy_ = true;
        return leave(absl::OkStatus());
      }
    }
    if (stopping_) return leave(absl::UnavailableError("merge service shutting down"));
    if (ctx.IsCancelled()) return leave(absl::CancelledError("merge cancelled by the caller"));
    if (!queued) {
      spdlog::info("merger: another job's merge runs; this one waits");
      metrics_.Queued();
      queued = true;
      pb::MergeServerMessage msg;
      msg.mutable_progress()->set_stage("queued");
      msg.mutable_progress()->set_total(1);
      if (!stream.Write(msg)) return leave(absl::CancelledError("the caller went away"));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

absl::StatusOr<std::string> MergeServer::Impl::Recarve(Stream& stream, uint64_t id,
                                                       const std::vector<RecarveChunk>& chunks,
                                                       double resolution_m) {
  spdlog::info("merger: asking the coordinator to carve {} object chunks again at {} m",
               chunks.size(), resolution_m);
  pb::MergeServerMessage msg;
  pb::RecarveRequest* r = msg.mutable_recarve();
  size_t bytes = 0;
  auto send = [&](bool last) {
    r->set_request_id(id);
    r->set_resolution_m(resolution_m);
    r->set_last(last);
    const bool ok = stream.Write(msg);
    r->clear_chunks();
    bytes = 0;
    return ok;
  };
  for (const RecarveChunk& c : chunks) {
    pb::RecarveChunk* out = r->add_chunks();
    out->mutable_chunk()->set_x(c.chunk.x());
    out->mutable_chunk()->set_y(c.chunk.y());
    out->mutable_chunk()->set_z(c.chunk.z());
    out->set_region_depth(c.depth);
    out->set_region(c.cells);
    bytes += out->region().size() + 32;
    if (bytes >= kRecarvePartBytes && !send(false)) {
      return absl::CancelledError("the coordinator went away");
    }
  }
  if (!send(true)) return absl::CancelledError("the coordinator went away");
  pb::MergeClientMessage in;
  if (!stream.Read(&in)) {
    return absl::CancelledError(
        "the coordinator went away while the object chunks were carved again");
  }
  if (!in.has_recarve_result() || in.recarve_result().request_id() != id) {
    return absl::InvalidArgumentError(absl::StrCat(
        "MergeService protocol: expected the RecarveResult of request ", id));
  }
  const pb::RecarveResult& result = in.recarve_result();
  if (result.code() != 0) {
    return absl::Status(static_cast<absl::StatusCode>(result.code()), result.message());
  }
  if (result.tiles_dir().empty() || !fs::path(result.tiles_dir()).is_absolute()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "RecarveResult.tiles_dir '", result.tiles_dir(), "': must be an absolute path"));
  }
  return result.tiles_dir();
}

absl::Status MergeServer::Impl::Serve(grpc::ServerContext& ctx, Stream& stream) {
  if (stopping_) return absl::UnavailableError("merge service shutting down");
  pb::MergeClientMessage first;
  if (!stream.Read(&first)) return absl::CancelledError("the caller sent no MergeJob");
  if (!first.has_start()) {
    return absl::InvalidArgumentError("MergeService: the first message must be a MergeJob");
  }
  const pb::MergeJob& job = first.start();
  if (absl::Status s = ValidateJob(job); !s.ok()) return s;
  LogScope log_scope({{"job", job.job_id()}});
  if (absl::Status s = TakeSlot(ctx, stream); !s.ok()) return s;
  const Clock::time_point t0 = Clock::now();
  metrics_.MergeStarted(t0);
  spdlog::info("merger: job {}: merge started (attempt {}) -> {}", job.job_id(),
               std::max(1, job.attempt()), job.output_dir());

  MergeJobRequest req;
  req.job_id = job.job_id();
  req.tiles_dir = job.tiles_dir();
  req.output_dir = job.output_dir();
  req.scan_root = job.scan_root();
  req.scan_input = job.scan_path();
  req.params = MergeParamsFromProto(job);
  req.job_json = job.job_json();
  req.attempt = std::max(1, job.attempt());
  std::string last_stage;
  Clock::time_point last_sent{};
  bool caller_gone = false;
  req.progress = [&](const std::string& stage, uint64_t done, uint64_t total) {
    if (caller_gone || stopping_ || ctx.IsCancelled()) return false;
    const Clock::time_point now = Clock::now();
    if (stage != last_stage || done == total || now - last_sent >= kProgressInterval) {
      pb::MergeServerMessage msg;
      msg.mutable_progress()->set_stage(stage);
      msg.mutable_progress()->set_done(done);
      msg.mutable_progress()->set_total(total);
      if (!stream.Write(msg)) {
        caller_gone = true;
        return false;
      }
      if (stage != last_stage) {
        metrics_.Stage(stage, Clock::now());
        const auto [rss, peak] = ResidentMiB();
        spdlog::info("merger: job {}: {} (resident {:.0f} MiB, peak so far {:.0f} MiB)",
                     job.job_id(), stage, rss, peak);
      }
      last_stage = stage;
      last_sent = now;
    }
    return true;
  };
  uint64_t next_request = 0;
  if (job.recarve_available()) {
    req.recarve = [&](const std::vector<RecarveChunk>& chunks, double resolution_m) {
      LogScope log_scope({{"job", job.job_id()}});  // the merge calls it from a thread of its own
      return Recarve(stream, ++next_request, chunks, resolution_m);
    };
  }
  const absl::Status merged = spec_.merge(req);
  ReleaseSlot();
  metrics_.MergeFinished(merged.ok()                                       ? "succeeded"
                         : absl::IsCancelled(merged) || ctx.IsCancelled() ? "cancelled"
                                                                          : "failed",
                         Clock::now());
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  if (ctx.IsCancelled() || caller_gone) {
    spdlog::warn("merger: job {}: the caller cancelled or went away after {:.1f} s; merge stopped",
                 job.job_id(), seconds);
    return absl::CancelledError("merge cancelled by the caller");
  }
  if (stopping_ && absl::IsCancelled(merged)) {
    spdlog::warn("merger: job {}: stopped after {:.1f} s by the shutdown", job.job_id(), seconds);
    return absl::UnavailableError("merge service shutting down; the merge was stopped");
  }
  if (merged.ok()) {
    const auto [rss, peak] = ResidentMiB();
    spdlog::info("merger: job {}: merge done in {:.1f} s (resident {:.0f} MiB, peak {:.0f} MiB)",
                 job.job_id(), seconds, rss, peak);
  } else {
    spdlog::error("merger: job {}: merge failed after {:.1f} s: {}", job.job_id(), seconds,
                  merged.ToString());
  }
  pb::MergeServerMessage msg;
  msg.mutable_result()->set_code(static_cast<int>(merged.code()));
  msg.mutable_result()->set_message(std::string(merged.message()));
  if (!stream.Write(msg)) return absl::CancelledError("the caller went away");
  return absl::OkStatus();
}

// ---- MergeServer

absl::StatusOr<std::unique_ptr<MergeServer>> MergeServer::Start(MergeServerSpec spec) {
  auto impl = std::make_unique<Impl>(std::move(spec));
  if (absl::Status s = impl->Start(); !s.ok()) {
    impl->Shutdown();
    return s;
  }
  return std::unique_ptr<MergeServer>(new MergeServer(std::move(impl)));
}

MergeServer::MergeServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MergeServer::~MergeServer() = default;
int MergeServer::port() const { return impl_->port(); }
int MergeServer::health_port() const { return impl_->health_port(); }
void MergeServer::Shutdown() { impl_->Shutdown(); }
void MergeServer::Wait() { impl_->Wait(); }
int MergeServer::metrics_port() const { return impl_->metrics_port(); }

}  // namespace carvemap
