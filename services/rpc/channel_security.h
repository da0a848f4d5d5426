// How a client (the CLI's job commands, a worker) reaches a carvemap server: bearer token
// and TLS settings for its channel (docs/RPC.md, "Authentication"; docs/CLUSTER.md). Plain
// struct: services/rpc/grpc_security.h turns it into a gRPC channel.
#ifndef CARVEMAP_SERVICES_RPC_CHANNEL_SECURITY_H_
#define CARVEMAP_SERVICES_RPC_CHANNEL_SECURITY_H_

#include <string>

#include "absl/status/status.h"

namespace carvemap {

struct ChannelSecurity {
  // Sent on every call as metadata "authorization: Bearer <bearer>": a tenant's token on the
  // job API, the cluster secret on the carve-task API. "" = none.
  std::string bearer;
  // TLS. Implied by any of the files below; alone it trusts the system's root certificates.
  bool tls = false;
  std::string ca_file;    // PEM root certificates that sign the server's certificate
  std::string cert_file;  // PEM client certificate chain (mutual TLS of internal peers)
  std::string key_file;   //   and its private key; both or neither
  // The name the server's certificate must carry, when it is not the host of the address
  // (e.g. "carvemap-coordinator" through `kubectl port-forward` to localhost).
  std::string server_name;

  [[nodiscard]] bool UsesTls() const {
    return tls || !ca_file.empty() || !cert_file.empty() || !key_file.empty();
  }
  absl::Status Validate() const;
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_CHANNEL_SECURITY_H_
