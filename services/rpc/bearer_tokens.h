// Bearer tokens mapped to tenants, and the shared cluster secret of the internal RPCs
// (docs/DESIGN.md §8: "Every call carries a bearer token; a token sees only its own tenant's jobs
// and paths"). Plain code, no gRPC: services/rpc/coordinator_service.cc reads the metadata and
// asks here. Formats and rules: docs/RPC.md, "Authentication".
#ifndef CARVEMAP_SERVICES_RPC_BEARER_TOKENS_H_
#define CARVEMAP_SERVICES_RPC_BEARER_TOKENS_H_

#include <array>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace carvemap {

// The tenant of every caller of a coordinator without tokens, and of the jobs a job store
// kept from before tenants existed (docs/JOB_STORE.md, version 2).
inline constexpr char kDefaultTenant[] = "default";
// Tokens and the cluster secret: at least this long (16 random bytes as text are still
// guessable only by brute force at 2^64+; `carvemap run` makes 64 hex digits).
inline constexpr size_t kMinSecretBytes = 16;
inline constexpr size_t kMaxSecretBytes = 512;

struct TenantToken {
  std::string token;
  std::string tenant;
};

// A tenant name: [a-z0-9][a-z0-9_-]{0,62}. It names the tenant's folder under the data and
// output roots, so nothing else is allowed.
absl::Status ValidateTenantName(absl::string_view tenant);
// A token or secret: kMinSecretBytes..kMaxSecretBytes of RFC 6750 token characters
// (A-Z a-z 0-9 - . _ ~ + / and trailing =). `what` names it in the error, never its value.
absl::Status ValidateSecret(absl::string_view secret, absl::string_view what);

// The tokens file (or the CARVEMAP_TOKENS variable): either lines "TOKEN TENANT" (blank lines
// and lines starting with # ignored; in the variable ',' also separates entries), or JSON
// {"tokens": [{"token": "...", "tenant": "..."}, ...]}. Errors name `source` and the line
// (or entry), never a token. A repeated token is an error; a tenant may have many tokens.
absl::StatusOr<std::vector<TenantToken>> ParseTokens(absl::string_view text,
                                                     absl::string_view source);
absl::StatusOr<std::vector<TenantToken>> ReadTokensFile(const std::string& path);
// A file holding one secret (the cluster secret); surrounding whitespace is dropped.
absl::StatusOr<std::string> ReadSecretFile(const std::string& path, absl::string_view what);

// Token ➜ tenant. Only SHA-256 digests of the tokens are kept. Lookup compares the digest of
// the presented token with every stored digest (CRYPTO_memcmp, no early exit), so its time
// says nothing about which token, or how much of one, matched. Immutable; thread-safe.
class TokenTable {
 public:
  TokenTable() = default;
  // INVALID_ARGUMENT for a repeated token or a bad tenant/token.
  static absl::StatusOr<TokenTable> Build(const std::vector<TenantToken>& tokens);

  [[nodiscard]] std::optional<std::string> Lookup(absl::string_view token) const;
  [[nodiscard]] bool empty() const { return entries_.empty(); }
  [[nodiscard]] size_t size() const { return entries_.size(); }
  [[nodiscard]] std::set<std::string> tenants() const;

 private:
  struct Entry {
    std::array<uint8_t, 32> digest;
    std::string tenant;
  };
  std::vector<Entry> entries_;
};

// Equality of two secrets in time independent of their contents (SHA-256 of both, then
// CRYPTO_memcmp of the digests).
[[nodiscard]] bool SecretEquals(absl::string_view a, absl::string_view b);

// 32 bytes from OpenSSL's RAND_bytes (the OS's CSPRNG) as 64 hex digits: the token and the
// cluster secret that `carvemap run` makes for its own loopback servers.
absl::StatusOr<std::string> RandomSecret();

// The token of an "authorization" metadata value "Bearer TOKEN" (scheme case-insensitive,
// RFC 6750 §2.1); nullopt for another scheme or an empty token.
[[nodiscard]] std::optional<std::string> ParseBearer(absl::string_view value);

// Whether a listen address ("host:port", "[v6]:port", "unix:...") accepts connections from
// this host only: 127.0.0.0/8, ::1, localhost, a unix socket.
[[nodiscard]] bool IsLoopbackAddress(absl::string_view listen_address);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_BEARER_TOKENS_H_
