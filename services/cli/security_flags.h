// The security flags shared by the commands that talk to a server (`submit|watch|status|list|
// cancel|fetch` with a tenant's token, `worker` with the cluster secret): flags ➜
// ChannelSecurity (services/rpc/channel_security.h). docs/RPC.md, "Authentication".
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "services/rpc/channel_security.h"

namespace CLI {
class App;
}

namespace carvemap {

struct SecurityFlags {
  std::string token;        // --token (or CARVEMAP_TOKEN); job commands only
  std::string token_file;   // --token-file
  std::string secret_file;  // --cluster-secret-file; worker only
  bool tls = false;
  std::string tls_ca;
  std::string tls_cert;
  std::string tls_key;
  std::string tls_server_name;
};

// `worker` = true: the cluster secret and a client certificate (mutual TLS) instead of a
// tenant's token.
void AddSecurityFlags(CLI::App* cmd, SecurityFlags& flags, bool worker);

// Reads the token or secret files (the worker's secret: --cluster-secret-file, else the
// CARVEMAP_CLUSTER_SECRET variable). Errors name the file, never the secret.
absl::StatusOr<ChannelSecurity> ResolveSecurity(const SecurityFlags& flags, bool worker);

// Writes `text` to a new file readable by its owner only (0600): `carvemap run`'s own token
// and cluster secret.
absl::Status WritePrivateFile(const std::string& path, const std::string& text);

}  // namespace carvemap
