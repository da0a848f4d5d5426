// Setup shared by every carvemap gRPC server (docs/DESIGN.md §8): the standard health service
// (grpc.health.v1.Health), server reflection, and the start and stop of a service's server
// with its optional plaintext health port. Included by the services' .cc files only (gRPC
// headers are slow to compile; the service headers keep gRPC behind their pimpl).
#ifndef CARVEMAP_SERVICES_GRPC_SERVER_COMMON_H_
#define CARVEMAP_SERVICES_GRPC_SERVER_COMMON_H_

#include <grpcpp/server.h>

#include <chrono>
#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"

namespace grpc {
class ServerCredentials;
class Service;
}  // namespace grpc

namespace carvemap {

// Enables gRPC's built-in health service and the reflection plugin for servers built after
// this call. Both are process-wide switches in gRPC, so call it once before the first
// grpc::ServerBuilder::BuildAndStart(); calling it again is harmless. Thread-safe.
void EnableHealthAndReflection();

// Marks `service` ("" = the whole server) SERVING or NOT_SERVING on the health service.
// REQUIRES: `server` was built after EnableHealthAndReflection().
void SetServing(grpc::Server& server, std::string_view service, bool serving);

// What StartGrpcServer builds: `services` on `listen_address` and, when `health_listen_address`
// is set, a second server in plaintext that has only health and reflection (Kubernetes probes
// cannot speak TLS).
struct GrpcServerSpec {
  std::string component;       // "coordinator", "merger": starts the error messages
  std::string listen_address;  // "host:port"; port 0 picks a free port
  std::shared_ptr<grpc::ServerCredentials> credentials;
  int max_receive_message_bytes = 4 << 20;  // larger requests: RESOURCE_EXHAUSTED from gRPC
  std::vector<grpc::Service*> services;     // borrowed: must outlive the servers
  std::vector<std::pair<std::string, int>> channel_args;  // of the main server
  std::string health_listen_address;                      // "" = no health server
};

// The servers StartGrpcServer started. Moving is fine; the servers stop in Shutdown() or when
// destroyed (gRPC's own destructor then waits for calls without a deadline).
struct GrpcServers {
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<grpc::Server> health_server;  // null without a health_listen_address
  int port = 0;
  int health_port = 0;

  // Marks the whole server and each of `names` SERVING on both servers' health services.
  void MarkServing(std::initializer_list<std::string_view> names);
  // Marks both NOT_SERVING and shuts them down: the health server within 100 ms, the main one
  // within `grace` (calls still running then are cancelled). Call it once.
  void Shutdown(std::chrono::milliseconds grace);
};

// Enables health and reflection, then builds and starts the servers of `spec`. An address that
// cannot be bound is UNAVAILABLE "<component>: cannot listen on <address>[ (health)]".
absl::StatusOr<GrpcServers> StartGrpcServer(const GrpcServerSpec& spec);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_GRPC_SERVER_COMMON_H_
