#include "services/grpc_server_common.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>

#include <cassert>
#include <mutex>
#include <string>

namespace carvemap {

void EnableHealthAndReflection() {
  static std::once_flag once;
  std::call_once(once, [] {
    grpc::EnableDefaultHealthCheckService(true);
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  });
}

void SetServing(grpc::Server& server, std::string_view service, bool serving) {
  grpc::HealthCheckServiceInterface* health = server.GetHealthCheckService();
  // Null only if the server was built before EnableHealthAndReflection(): a programmer error.
  assert(health != nullptr);
  if (health == nullptr) return;
  health->SetServingStatus(std::string(service), serving);
}

}  // namespace carvemap
