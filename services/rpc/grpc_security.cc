#include "services/rpc/grpc_security.h"

#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>
#include <openssl/bio.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include <fstream>
#include <memory>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "services/rpc/bearer_tokens.h"

namespace carvemap {
namespace {

absl::StatusOr<std::string> ReadPem(const std::string& path, absl::string_view what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::InvalidArgumentError(absl::StrCat(what, " ", path, ": cannot read"));
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

struct BioDeleter {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Deleter {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyDeleter {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};

std::unique_ptr<BIO, BioDeleter> Bio(const std::string& pem) {
  return std::unique_ptr<BIO, BioDeleter>(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
}

// gRPC only reports a bad PEM when the server starts (in its log); these checks name the file.
absl::StatusOr<std::unique_ptr<X509, X509Deleter>> ParseCertificate(const std::string& pem,
                                                                    const std::string& path,
                                                                    absl::string_view what) {
  auto bio = Bio(pem);
  std::unique_ptr<X509, X509Deleter> cert(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
  if (cert == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, " ", path, ": no PEM certificate (\"BEGIN CERTIFICATE\") in it"));
  }
  return cert;
}

absl::StatusOr<std::string> ReadCertificateFile(const std::string& path, absl::string_view what) {
  absl::StatusOr<std::string> pem = ReadPem(path, what);
  if (!pem.ok()) return pem.status();
  if (absl::StatusOr<std::unique_ptr<X509, X509Deleter>> c = ParseCertificate(*pem, path, what);
      !c.ok()) {
    return c.status();
  }
  return pem;
}

// The key must be a PEM private key and belong to the first certificate of the chain.
absl::Status CheckKeyMatches(const std::string& cert_pem, const std::string& cert_path,
                             const std::string& key_pem, const std::string& key_path) {
  auto bio = Bio(key_pem);
  std::unique_ptr<EVP_PKEY, KeyDeleter> key(
      PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr));
  if (key == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("TLS key ", key_path, ": no unencrypted PEM private key in it"));
  }
  absl::StatusOr<std::unique_ptr<X509, X509Deleter>> cert =
      ParseCertificate(cert_pem, cert_path, "TLS certificate");
  if (!cert.ok()) return cert.status();
  if (X509_check_private_key(cert->get(), key.get()) != 1) {
    return absl::InvalidArgumentError(absl::StrCat("TLS key ", key_path,
                                                   " does not belong to the certificate ",
                                                   cert_path));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ChannelSecurity::Validate() const {
  if (cert_file.empty() != key_file.empty()) {
    return absl::InvalidArgumentError("a client certificate needs both --tls-cert and --tls-key");
  }
  if (!bearer.empty()) {
    if (absl::Status s = ValidateSecret(bearer, "bearer token"); !s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const std::string& address,
                                                           const ChannelSecurity& security,
                                                           grpc::ChannelArguments args) {
  if (absl::Status s = security.Validate(); !s.ok()) return s;
  grpc_channel_args raw = args.c_channel_args();
  bool has_limit = false;
  for (size_t i = 0; i < raw.num_args; ++i) {
    has_limit = has_limit || std::string(raw.args[i].key) == GRPC_ARG_MAX_RECEIVE_MESSAGE_LENGTH;
  }
  if (!has_limit) args.SetMaxReceiveMessageSize(kClientMaxReceiveBytes);
  std::shared_ptr<grpc::ChannelCredentials> creds;
  if (security.UsesTls()) {
    grpc::SslCredentialsOptions options;
    if (!security.ca_file.empty()) {
      absl::StatusOr<std::string> ca = ReadCertificateFile(security.ca_file, "TLS CA");
      if (!ca.ok()) return ca.status();
      options.pem_root_certs = *ca;
    }
    if (!security.cert_file.empty()) {
      absl::StatusOr<std::string> cert =
          ReadCertificateFile(security.cert_file, "TLS certificate");
      if (!cert.ok()) return cert.status();
      absl::StatusOr<std::string> key = ReadPem(security.key_file, "TLS key");
      if (!key.ok()) return key.status();
      if (absl::Status s = CheckKeyMatches(*cert, security.cert_file, *key, security.key_file);
          !s.ok()) {
        return s;
      }
      options.pem_cert_chain = *cert;
      options.pem_private_key = *key;
    }
    creds = grpc::SslCredentials(options);
    if (!security.server_name.empty()) args.SetSslTargetNameOverride(security.server_name);
  } else {
    creds = grpc::InsecureChannelCredentials();
  }
  return grpc::CreateCustomChannel(address, creds, args);
}

void AttachBearer(grpc::ClientContext& ctx, const std::string& bearer) {
  if (!bearer.empty()) ctx.AddMetadata("authorization", absl::StrCat("Bearer ", bearer));
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const std::string& cert_file, const std::string& key_file,
    const std::string& client_ca_file) {
  if (cert_file.empty() || key_file.empty()) {
    return absl::InvalidArgumentError("TLS needs both --tls-cert and --tls-key");
  }
  absl::StatusOr<std::string> cert = ReadCertificateFile(cert_file, "TLS certificate");
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = ReadPem(key_file, "TLS key");
  if (!key.ok()) return key.status();
  if (absl::Status s = CheckKeyMatches(*cert, cert_file, *key, key_file); !s.ok()) return s;
  grpc::SslServerCredentialsOptions options(
      client_ca_file.empty() ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                             : GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY);
  if (!client_ca_file.empty()) {
    absl::StatusOr<std::string> ca = ReadCertificateFile(client_ca_file, "TLS client CA");
    if (!ca.ok()) return ca.status();
    options.pem_root_certs = *ca;
  }
  options.pem_key_cert_pairs.push_back({*key, *cert});
  return grpc::SslServerCredentials(options);
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(
    const std::string& cert_file, const std::string& key_file,
    const std::string& client_ca_file) {
  if (cert_file.empty()) return grpc::InsecureServerCredentials();
  return MakeServerCredentials(cert_file, key_file, client_ca_file);
}

CallerBearer BearerOf(const grpc::ServerContext& ctx) {
  CallerBearer out;
  const auto& md = ctx.client_metadata();
  auto it = md.find("authorization");
  if (it == md.end()) return out;
  out.present = true;
  // Two authorization values are ambiguous: refuse rather than pick one.
  if (md.count("authorization") != 1) return out;
  out.token = ParseBearer(absl::string_view(it->second.data(), it->second.size()));
  return out;
}

bool HasVerifiedClientCertificate(const grpc::ServerContext& ctx) {
  std::shared_ptr<const grpc::AuthContext> auth = ctx.auth_context();
  if (auth == nullptr) return false;
  // With GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY a presented certificate that does not
  // verify fails the handshake; one that verifies makes the peer authenticated (its
  // identity is the certificate's subject names).
  bool ssl = false;
  for (const grpc::string_ref& v : auth->FindPropertyValues("transport_security_type")) {
    ssl = ssl || std::string(v.data(), v.size()) == "ssl";
  }
  return ssl && auth->IsPeerAuthenticated();
}

bool IsClusterPeer(const grpc::ServerContext& ctx, const std::string& cluster_secret,
                   const std::string& client_ca_file) {
  if (cluster_secret.empty() && client_ca_file.empty()) return true;
  if (!client_ca_file.empty() && HasVerifiedClientCertificate(ctx)) return true;
  if (!cluster_secret.empty()) {
    const CallerBearer bearer = BearerOf(ctx);
    if (bearer.token && SecretEquals(*bearer.token, cluster_secret)) return true;
  }
  return false;
}

}  // namespace carvemap
