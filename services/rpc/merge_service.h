// The merge service (docs/DESIGN.md §6, §8; `carvemap merger`): serves MergeService
// (proto/carvemap/v1/merge.proto) to the coordinator. Each call runs one job's merge
// (LocalMerge, i.e. RunMerge, by default) over the job's tiles on the shared storage, streams
// its progress, asks the coordinator to carve the object chunks again when the merge wants
// that (§5.6.1), and ends with the merge's verdict. One merge at a time per process (HDF5 is
// not thread-safe in Debian's build); later calls wait, reporting stage "queued".
// Serves gRPC health + reflection like the other servers. Shape as the coordinator's: Spec ➜
// Start ➜ port() ➜ Wait/Shutdown; gRPC behind the pimpl.
#ifndef CARVEMAP_SERVICES_RPC_MERGE_SERVICE_H_
#define CARVEMAP_SERVICES_RPC_MERGE_SERVICE_H_

#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/rpc/merge_request.h"

namespace carvemap {

struct MergeServerSpec {
  // "host:port"; port 0 picks a free port (see MergeServer::port()).
  std::string listen_address = "127.0.0.1:0";
  // The shared secret the coordinator presents as "authorization: Bearer <secret>" (the
  // cluster secret of the carve-task API). Empty and no tls_client_ca_file: the service is
  // open (refused on a non-loopback address unless `insecure`).
  std::string cluster_secret;
  // TLS from PEM files (both or neither); tls_client_ca_file: a client certificate verified
  // against it authenticates the coordinator as the secret does (mutual TLS); requires TLS.
  std::string tls_cert_file;
  std::string tls_key_file;
  std::string tls_client_ca_file;
  bool insecure = false;
  // A second, plaintext listener serving only grpc.health.v1 (Kubernetes' gRPC probes
  // cannot speak TLS). "" = none.
  std::string health_listen_address;
  // Prometheus metrics over HTTP at /metrics (merge_metrics.h); "" = none, port 0: any.
  std::string metrics_listen_address;
  // Largest message accepted from the coordinator (the MergeJob and re-carve answers are
  // small).
  int max_request_bytes = 1 << 20;
  // LocalMerge's MergeOptions::memory_budget_bytes: a merge whose planar mesh would not fit
  // fails with why before it starts it (0: no budget).
  uint64_t memory_budget_bytes = 0;
  // What a call runs; empty = LocalMerge(memory_budget_bytes). Tests put their own in front.
  MergeFunction merge;

  absl::Status Validate() const;
};

// Thread-safe. Destroying it shuts it down.
class MergeServer {
 public:
  static absl::StatusOr<std::unique_ptr<MergeServer>> Start(MergeServerSpec spec);
  ~MergeServer();
  MergeServer(const MergeServer&) = delete;
  MergeServer& operator=(const MergeServer&) = delete;

  [[nodiscard]] int port() const;
  [[nodiscard]] int health_port() const;  // 0 without a health listener
  [[nodiscard]] int metrics_port() const;  // 0 without a metrics endpoint
  // Stops accepting calls; a running merge is stopped at its next progress step and its call
  // ends UNAVAILABLE without a result, so the coordinator runs it again elsewhere (or here,
  // after a restart). Idempotent.
  void Shutdown();
  // Blocks until Shutdown() has been called.
  void Wait();

  class Impl;

 private:
  explicit MergeServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_MERGE_SERVICE_H_
