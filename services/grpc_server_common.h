// Setup shared by every carvemap gRPC server (DESIGN §8): the standard health service
// (grpc.health.v1.Health) and server reflection.
#ifndef CARVEMAP_SERVICES_GRPC_SERVER_COMMON_H_
#define CARVEMAP_SERVICES_GRPC_SERVER_COMMON_H_

#include <grpcpp/server.h>

#include <string_view>

namespace carvemap {

// Enables gRPC's built-in health service and the reflection plugin for servers built after
// this call. Both are process-wide switches in gRPC, so call it once before the first
// grpc::ServerBuilder::BuildAndStart(); calling it again is harmless. Thread-safe.
void EnableHealthAndReflection();

// Marks `service` ("" = the whole server) SERVING or NOT_SERVING on the health service.
// REQUIRES: `server` was built after EnableHealthAndReflection().
void SetServing(grpc::Server& server, std::string_view service, bool serving);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_GRPC_SERVER_COMMON_H_
