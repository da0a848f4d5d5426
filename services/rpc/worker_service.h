// A carve worker (docs/DESIGN.md §5, §8): registers with the coordinator, heartbeats, and loops
// LeaseChunk ➜ read the wedges ➜ CarveChunkToTile ➜ CompleteChunk (or FailChunk with the
// reason). Serves gRPC health + reflection on its own port so orchestration can probe it.
// Shape as the coordinator: Spec ➜ Start ➜ port() ➜ Wait/Shutdown; gRPC behind the pimpl.
#ifndef CARVEMAP_SERVICES_RPC_WORKER_SERVICE_H_
#define CARVEMAP_SERVICES_RPC_WORKER_SERVICE_H_

#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/rpc/channel_security.h"

namespace carvemap {

struct WorkerSpec {
  std::string coordinator_address;          // "host:port" of the CarveTaskService
  std::string listen_address = "127.0.0.1:0";  // health endpoint; "" = none
  // Prometheus metrics over HTTP at /metrics (worker_metrics.h); "" = none, port 0: any.
  std::string metrics_listen_address;
  int threads = 1;                          // tasks (slices, chunks) run in parallel
  // A slice's chunk sums held before they are written out (worker/slice_carver.h), per thread.
  size_t slice_memory_bytes = 256u << 20;
  // Give up (Wait returns UNAVAILABLE) after the coordinator has been unreachable this long.
  double coordinator_lost_s = 20.0;
  // How to reach the coordinator: `security.bearer` is the cluster secret (sent on every
  // carve-task call), TLS settings as for any client, a client certificate for mutual TLS.
  // The coordinator refusing it (UNAUTHENTICATED) ends the worker: Wait returns that status.
  ChannelSecurity security;
  absl::Status Validate() const;
};

// Thread-safe. Destroying it shuts it down.
class WorkerServer {
 public:
  static absl::StatusOr<std::unique_ptr<WorkerServer>> Start(WorkerSpec spec);
  ~WorkerServer();
  WorkerServer(const WorkerServer&) = delete;
  WorkerServer& operator=(const WorkerServer&) = delete;

  [[nodiscard]] int port() const;  // 0 without a health endpoint
  [[nodiscard]] int metrics_port() const;  // 0 without a metrics endpoint
  // The id the coordinator gave it; empty until registered (and again while registering anew).
  [[nodiscard]] std::string worker_id() const;
  // Stops leasing; a carve in progress finishes (its lease is then completed). Idempotent.
  void Shutdown();
  // Blocks until Shutdown() or until the coordinator is gone for good; returns why it ended
  // (OK after Shutdown).
  absl::Status Wait();

  class Impl;

 private:
  explicit WorkerServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_WORKER_SERVICE_H_
