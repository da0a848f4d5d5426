#include "services/rpc/grpc_server_common.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_builder.h>

#include <cassert>
#include <mutex>
#include <string>

#include "absl/strings/str_cat.h"

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

void GrpcServers::MarkServing(std::initializer_list<std::string_view> names) {
  for (grpc::Server* s : {server.get(), health_server.get()}) {
    if (s == nullptr) continue;
    SetServing(*s, "", true);
    for (std::string_view name : names) SetServing(*s, name, true);
  }
}

void GrpcServers::Shutdown(std::chrono::milliseconds grace) {
  if (health_server != nullptr) {
    SetServing(*health_server, "", false);
    health_server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(100));
  }
  if (server != nullptr) {
    SetServing(*server, "", false);
    server->Shutdown(std::chrono::system_clock::now() + grace);
  }
}

absl::StatusOr<GrpcServers> StartGrpcServer(const GrpcServerSpec& spec) {
  EnableHealthAndReflection();
  GrpcServers out;
  grpc::ServerBuilder builder;
  builder.AddListeningPort(spec.listen_address, spec.credentials, &out.port);
  builder.SetMaxReceiveMessageSize(spec.max_receive_message_bytes);
  for (const auto& [name, value] : spec.channel_args) builder.AddChannelArgument(name, value);
  for (grpc::Service* service : spec.services) builder.RegisterService(service);
  out.server = builder.BuildAndStart();
  if (out.server == nullptr || out.port == 0) {
    return absl::UnavailableError(
        absl::StrCat(spec.component, ": cannot listen on ", spec.listen_address));
  }
  if (!spec.health_listen_address.empty()) {
    // Health (and reflection) only: the default health service comes with every server.
    grpc::ServerBuilder health;
    health.AddListeningPort(spec.health_listen_address, grpc::InsecureServerCredentials(),
                            &out.health_port);
    health.SetMaxReceiveMessageSize(4096);
    out.health_server = health.BuildAndStart();
    if (out.health_server == nullptr || out.health_port == 0) {
      out.Shutdown(std::chrono::milliseconds(0));  // the start failed: serve nothing
      return absl::UnavailableError(absl::StrCat(spec.component, ": cannot listen on ",
                                                 spec.health_listen_address, " (health)"));
    }
  }
  return out;
}

}  // namespace carvemap
