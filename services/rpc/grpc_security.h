// The gRPC side of authentication and TLS (docs/RPC.md, "Authentication"): channels from a
// ChannelSecurity, server credentials from certificate files, and what a ServerContext says
// about its caller. Used by the coordinator, the worker and the job client only (it includes
// gRPC); the rules themselves are in bearer_tokens.h.
#ifndef CARVEMAP_SERVICES_RPC_GRPC_SECURITY_H_
#define CARVEMAP_SERVICES_RPC_GRPC_SECURITY_H_

#include <grpcpp/grpcpp.h>

#include <memory>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "services/rpc/channel_security.h"

namespace carvemap {

// Largest message a carvemap client accepts: FetchArtifact chunks are up to 4 MiB of data
// plus their fields.
inline constexpr int kClientMaxReceiveBytes = 8 << 20;

// A channel to `address` as `security` says (TLS or plaintext), with `args` (keepalive,
// backoff; the receive limit is set to kClientMaxReceiveBytes unless `args` sets one). Files
// that cannot be read or are not PEM are INVALID_ARGUMENT naming the file. The bearer is not
// part of the channel: AttachBearer adds it to each call.
absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(
    const std::string& address, const ChannelSecurity& security,
    grpc::ChannelArguments args = grpc::ChannelArguments());
void AttachBearer(grpc::ClientContext& ctx, const std::string& bearer);

// TLS credentials of a server from PEM files: certificate chain and key (which must match),
// and optionally the CA whose client certificates identify internal peers (mutual TLS:
// client certificates are requested and, when presented, verified against it; clients
// without one still connect and authenticate with a token). Errors name the file.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const std::string& cert_file, const std::string& key_file, const std::string& client_ca_file);
// Plaintext when `cert_file` is empty, else MakeServerCredentials: what a server's --tls-cert,
// --tls-key and --tls-client-ca flags ask for.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(
    const std::string& cert_file, const std::string& key_file, const std::string& client_ca_file);

// The caller's "authorization" metadata: absent, not a bearer token, or the token.
struct CallerBearer {
  bool present = false;              // any authorization metadata at all
  std::optional<std::string> token;  // set when it is "Bearer <token>"
};
[[nodiscard]] CallerBearer BearerOf(const grpc::ServerContext& ctx);

// True when the caller presented a client certificate that the server verified against its
// client CA (MakeServerCredentials' client_ca_file).
[[nodiscard]] bool HasVerifiedClientCertificate(const grpc::ServerContext& ctx);

// The rule of the internal APIs (carve-task, merge): open when the server has neither a cluster
// secret nor a client CA (loopback only, or --insecure: the specs' Validate); else the caller
// needs a client certificate verified against `client_ca_file`, or `cluster_secret` as its
// bearer token.
[[nodiscard]] bool IsClusterPeer(const grpc::ServerContext& ctx, const std::string& cluster_secret,
                                 const std::string& client_ca_file);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_GRPC_SECURITY_H_
