#include "services/cli/security_flags.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include <CLI/CLI.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "services/rpc/bearer_tokens.h"

namespace carvemap {

void AddSecurityFlags(CLI::App* cmd, SecurityFlags& f, bool worker) {
  if (worker) {
    cmd->add_option("--cluster-secret-file", f.secret_file,
                    "File holding the cluster secret the coordinator requires of workers (else "
                    "the CARVEMAP_CLUSTER_SECRET variable)")
        ->envname("CARVEMAP_CLUSTER_SECRET_FILE");
    cmd->add_option("--tls-cert", f.tls_cert,
                    "Client certificate (PEM) for mutual TLS with the coordinator")
        ->envname("CARVEMAP_TLS_CERT");
    cmd->add_option("--tls-key", f.tls_key, "Private key (PEM) of --tls-cert")
        ->envname("CARVEMAP_TLS_KEY");
  } else {
    cmd->add_option("--token-file", f.token_file,
                    "File holding your bearer token (docs/RPC.md, \"Authentication\")")
        ->envname("CARVEMAP_TOKEN_FILE");
    cmd->add_option("--token", f.token,
                    "Your bearer token (visible to other users in `ps`: prefer --token-file or "
                    "the CARVEMAP_TOKEN variable)")
        ->envname("CARVEMAP_TOKEN");
  }
  cmd->add_flag("--tls", f.tls, "Connect with TLS, trusting the system's root certificates");
  cmd->add_option("--tls-ca", f.tls_ca,
                  "Connect with TLS, trusting the CA certificate(s) in this PEM file")
      ->envname("CARVEMAP_TLS_CA");
  cmd->add_option("--tls-server-name", f.tls_server_name,
                  "Name the server's certificate must carry, when it is not the --server host "
                  "(e.g. carvemap-coordinator through a port-forward)")
      ->envname("CARVEMAP_TLS_SERVER_NAME");
}

absl::StatusOr<ChannelSecurity> ResolveSecurity(const SecurityFlags& f, bool worker) {
  ChannelSecurity s;
  s.tls = f.tls;
  s.ca_file = f.tls_ca;
  s.cert_file = f.tls_cert;
  s.key_file = f.tls_key;
  s.server_name = f.tls_server_name;
  if (worker) {
    if (!f.secret_file.empty()) {
      absl::StatusOr<std::string> secret = ReadSecretFile(f.secret_file, "cluster secret file");
      if (!secret.ok()) return secret.status();
      s.bearer = *secret;
    } else if (const char* env = std::getenv("CARVEMAP_CLUSTER_SECRET"); env && *env) {
      s.bearer = std::string(absl::StripAsciiWhitespace(env));
      if (absl::Status st = ValidateSecret(s.bearer, "CARVEMAP_CLUSTER_SECRET"); !st.ok()) {
        return st;
      }
    }
  } else if (!f.token_file.empty()) {
    absl::StatusOr<std::string> token = ReadSecretFile(f.token_file, "token file");
    if (!token.ok()) return token.status();
    s.bearer = *token;
  } else if (!f.token.empty()) {
    s.bearer = std::string(absl::StripAsciiWhitespace(f.token));
    if (absl::Status st = ValidateSecret(s.bearer, "--token"); !st.ok()) return st;
  }
  if (absl::Status st = s.Validate(); !st.ok()) return st;
  return s;
}

absl::Status WritePrivateFile(const std::string& path, const std::string& text) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) {
    return absl::FailedPreconditionError(
        absl::StrCat("cannot write ", path, ": ", std::strerror(errno)));
  }
  // An existing file keeps its mode through O_CREAT: make sure.
  ::fchmod(fd, 0600);
  const bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  ::close(fd);
  if (!ok) return absl::FailedPreconditionError(absl::StrCat("cannot write ", path));
  return absl::OkStatus();
}

}  // namespace carvemap
