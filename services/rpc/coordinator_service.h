// The coordinator server (docs/DESIGN.md §5, §8): JobService (public) and CarveTaskService
// (internal) on one gRPC port, over the SQLite job store and the lease table. A job runs in a
// background thread: INGESTING (validate the scan, plan its time slices) ➜ CARVING (slices, then
// the chunks they touch, leased to workers) ➜ MERGING ➜ SUCCEEDED, or FAILED with the reason.
//
// Shape of a tensorstore service: Spec (config, Validate) ➜ Start ➜ port() ➜ Wait/Shutdown.
// gRPC stays behind the pimpl so this header is cheap to include.
#ifndef CARVEMAP_SERVICES_RPC_COORDINATOR_SERVICE_H_
#define CARVEMAP_SERVICES_RPC_COORDINATOR_SERVICE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/chunk_region.h"
#include "services/rpc/bearer_tokens.h"
#include "services/rpc/merge_request.h"

namespace carvemap {

struct CoordinatorSpec {
  // "host:port"; port 0 picks a free port (see CoordinatorServer::port()).
  std::string listen_address = "127.0.0.1:0";
  // Input paths of SubmitJob are relative to this directory (with tenant folders: to
  // <data_root>/<tenant>/), and cannot leave it (storage/confined_path.h).
  std::string data_root = ".";
  // A job's outputs go to <output_root>/<output_name>/ (with tenant folders:
  // <output_root>/<tenant>/<output_name>/).
  std::string output_root = "out";
  // Empty: tiles go to <output_root>/<output_name>/tiles. Set: <storage_root>/<job_id>/tiles
  // (a shared volume for a cluster).
  std::string storage_root;
  // The job store (jobs.db) and the partial sums (<work_dir>/<job_id>/partials). Empty:
  // <storage_root or output_root>/.carvemap.
  std::string work_dir;
  double heartbeat_interval_s = 5.0;
  double worker_timeout_s = 15.0;  // no heartbeat for this long: the worker is lost
  double lease_timeout_s = 30.0;
  int max_attempts = 3;
  // Sweeps expired leases and lost workers this often.
  double sweep_interval_s = 0.5;
  // Keep the slices' partial sums after a job ends (debugging). Default: removed when the job
  // ends.
  bool keep_partials = false;
  // The merge step; empty: MERGING is skipped with a warning (tiles only). `carvemap
  // coordinator` gives RemoteMerge (a merge service, services/rpc/merge_client.h); tests may
  // give LocalMerge() or their own.
  MergeFunction merge;
  // The merge runs in this process (LocalMerge): it then holds the process's HDF5 lock, as
  // the ingest does. False for a remote merge, which does no HDF5 here.
  bool merge_in_process = true;

  // ---- security (docs/RPC.md "Authentication", docs/CLUSTER.md)
  // Bearer tokens of the job API, each mapped to a tenant; a call sees only its tenant's jobs
  // and paths. Empty: no authentication, every caller is tenant "default" (refused on a
  // non-loopback address unless `insecure`).
  std::vector<TenantToken> tokens;
  // The shared secret that internal peers (workers) present on the carve-task API as
  // "authorization: Bearer <secret>". Empty and no tls_client_ca_file: that API is open
  // (refused on a non-loopback address unless `insecure`).
  std::string cluster_secret;
  // TLS from PEM files (certificate chain and key: both or neither). tls_client_ca_file: a
  // client certificate verified against it authenticates an internal peer (mutual TLS) as
  // the cluster secret does; requires TLS.
  std::string tls_cert_file;
  std::string tls_key_file;
  std::string tls_client_ca_file;
  // Serve without tokens, or with an open carve-task API, on a non-loopback address.
  bool insecure = false;
  // With tokens: false = each tenant's inputs are under <data_root>/<tenant>/ and its outputs
  // under <output_root>/<tenant>/; true = all tenants share the roots, which is allowed only
  // when the tokens belong to one tenant (two would overwrite each other's outputs).
  // Without tokens the roots are always shared.
  bool shared_dirs = false;
  // Jobs of one tenant not yet SUCCEEDED/FAILED/CANCELLED; one more is RESOURCE_EXHAUSTED.
  // 0 = no limit.
  int max_jobs_per_tenant = 0;
  // Bytes a tenant may hold in streamed uploads (its uploads/ folder and what unfinished
  // uploads announced; docs/RPC.md "Uploads"); more is RESOURCE_EXHAUSTED. 0 = no limit.
  int64_t upload_quota_bytes = 0;
  // Largest request message the server accepts (gRPC's max receive message size); larger is
  // RESOURCE_EXHAUSTED before any handler runs.
  int max_request_bytes = 1 << 20;
  // A second, plaintext listener serving only grpc.health.v1 (Kubernetes' gRPC probes cannot
  // speak TLS). "" = none.
  std::string health_listen_address;
  // HTTP "host:port" serving Prometheus metrics at /metrics (services/rpc/
  // coordinator_metrics.h; aggregates only, no job ids or tenants). "" = none.
  std::string metrics_listen_address;

  absl::Status Validate() const;
};

// Thread-safe. Destroying it shuts it down.
class CoordinatorServer {
 public:
  // Opens the job store, resumes unfinished jobs, and starts serving.
  static absl::StatusOr<std::unique_ptr<CoordinatorServer>> Start(CoordinatorSpec spec);
  ~CoordinatorServer();
  CoordinatorServer(const CoordinatorServer&) = delete;
  CoordinatorServer& operator=(const CoordinatorServer&) = delete;

  // The bound port (useful with port 0).
  [[nodiscard]] int port() const;
  // The bound port of health_listen_address; 0 without one.
  [[nodiscard]] int health_port() const;
  // The bound port of metrics_listen_address; 0 without one.
  [[nodiscard]] int metrics_port() const;
  // What /metrics serves (Prometheus text format), also without a metrics listener.
  [[nodiscard]] std::string MetricsText() const;
  // Stops accepting calls, ends streams, joins the job threads. Idempotent.
  void Shutdown();
  // Blocks until Shutdown() has been called (from another thread or a signal handler thread).
  void Wait();

  class Impl;

 private:
  explicit CoordinatorServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_COORDINATOR_SERVICE_H_
