#include "services/rpc/bearer_tokens.h"

#include <openssl/crypto.h>
#include <openssl/rand.h>
#include <openssl/sha.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace carvemap {
namespace {

std::array<uint8_t, 32> Digest(absl::string_view text) {
  std::array<uint8_t, 32> d{};
  SHA256(reinterpret_cast<const unsigned char*>(text.data()), text.size(), d.data());
  return d;
}

bool IsTokenChar(char c) {
  return absl::ascii_isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.' ||
         c == '_' || c == '~' || c == '+' || c == '/';
}

absl::StatusOr<std::string> ReadWholeFile(const std::string& path, absl::string_view what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return absl::NotFoundError(absl::StrCat(what, " ", path, ": cannot read: ",
                                            std::strerror(errno)));
  }
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

absl::Status ValidateTenantName(absl::string_view tenant) {
  bool ok = !tenant.empty() && tenant.size() <= 63;
  for (size_t i = 0; ok && i < tenant.size(); ++i) {
    const char c = tenant[i];
    const bool alnum = (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
    ok = alnum || (i > 0 && (c == '-' || c == '_'));
  }
  if (!ok) {
    return absl::InvalidArgumentError(
        absl::StrCat("tenant '", tenant, "': must match [a-z0-9][a-z0-9_-]{0,62}"));
  }
  return absl::OkStatus();
}

absl::Status ValidateSecret(absl::string_view secret, absl::string_view what) {
  if (secret.size() < kMinSecretBytes || secret.size() > kMaxSecretBytes) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": ", secret.size(),
                                                   " characters; need ", kMinSecretBytes, "..",
                                                   kMaxSecretBytes));
  }
  size_t end = secret.size();
  while (end > 0 && secret[end - 1] == '=') --end;  // b64token's trailing padding
  for (size_t i = 0; i < end; ++i) {
    if (!IsTokenChar(secret[i])) {
      return absl::InvalidArgumentError(absl::StrCat(
          what, ": character ", i + 1, " is not one of A-Z a-z 0-9 - . _ ~ + / (or trailing =)"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<TenantToken>> ParseTokens(absl::string_view text,
                                                     absl::string_view source) {
  std::vector<TenantToken> out;
  const absl::string_view trimmed = absl::StripAsciiWhitespace(text);
  if (absl::StartsWith(trimmed, "{")) {
    nlohmann::json doc = nlohmann::json::parse(trimmed.begin(), trimmed.end(), nullptr,
                                               /*allow_exceptions=*/false);
    if (doc.is_discarded() || !doc.is_object() || !doc.contains("tokens") ||
        !doc["tokens"].is_array()) {
      return absl::InvalidArgumentError(absl::StrCat(
          source, ": not JSON of the form {\"tokens\": [{\"token\": ..., \"tenant\": ...}]}"));
    }
    int index = 0;
    for (const nlohmann::json& e : doc["tokens"]) {
      const std::string where = absl::StrCat(source, ": tokens[", index++, "]");
      if (!e.is_object() || !e.contains("token") || !e.contains("tenant") ||
          !e["token"].is_string() || !e["tenant"].is_string()) {
        return absl::InvalidArgumentError(
            absl::StrCat(where, ": needs string fields \"token\" and \"tenant\""));
      }
      out.push_back({e["token"].get<std::string>(), e["tenant"].get<std::string>()});
      if (absl::Status s = ValidateSecret(out.back().token, absl::StrCat(where, ": token"));
          !s.ok()) {
        return s;
      }
      if (absl::Status s = ValidateTenantName(out.back().tenant); !s.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", s.message()));
      }
    }
  } else {
    int line_no = 0;
    for (absl::string_view line : absl::StrSplit(text, absl::ByAnyChar("\n,"))) {
      ++line_no;
      line = absl::StripAsciiWhitespace(line);
      if (line.empty() || line.front() == '#') continue;
      std::vector<absl::string_view> fields =
          absl::StrSplit(line, absl::ByAnyChar(" \t"), absl::SkipEmpty());
      const std::string where = absl::StrCat(source, ": entry ", line_no);
      if (fields.size() != 2) {
        return absl::InvalidArgumentError(absl::StrCat(
            where, ": expected \"TOKEN TENANT\", got ", fields.size(), " field(s)"));
      }
      if (absl::Status s = ValidateSecret(fields[0], absl::StrCat(where, ": token")); !s.ok()) {
        return s;
      }
      if (absl::Status s = ValidateTenantName(fields[1]); !s.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", s.message()));
      }
      out.push_back({std::string(fields[0]), std::string(fields[1])});
    }
  }
  if (absl::StatusOr<TokenTable> table = TokenTable::Build(out); !table.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": ", table.status().message()));
  }
  return out;
}

absl::StatusOr<std::vector<TenantToken>> ReadTokensFile(const std::string& path) {
  absl::StatusOr<std::string> text = ReadWholeFile(path, "tokens file");
  if (!text.ok()) return text.status();
  absl::StatusOr<std::vector<TenantToken>> tokens =
      ParseTokens(*text, absl::StrCat("tokens file ", path));
  if (tokens.ok() && tokens->empty()) {
    return absl::InvalidArgumentError(absl::StrCat("tokens file ", path, ": no tokens"));
  }
  return tokens;
}

absl::StatusOr<std::string> ReadSecretFile(const std::string& path, absl::string_view what) {
  absl::StatusOr<std::string> text = ReadWholeFile(path, what);
  if (!text.ok()) return text.status();
  std::string secret(absl::StripAsciiWhitespace(*text));
  if (absl::Status s = ValidateSecret(secret, absl::StrCat(what, " ", path)); !s.ok()) return s;
  return secret;
}

absl::StatusOr<TokenTable> TokenTable::Build(const std::vector<TenantToken>& tokens) {
  TokenTable table;
  for (size_t i = 0; i < tokens.size(); ++i) {
    if (absl::Status s = ValidateSecret(tokens[i].token, absl::StrCat("token ", i + 1));
        !s.ok()) {
      return s;
    }
    if (absl::Status s = ValidateTenantName(tokens[i].tenant); !s.ok()) return s;
    Entry e{Digest(tokens[i].token), tokens[i].tenant};
    for (const Entry& other : table.entries_) {
      if (other.digest == e.digest) {
        return absl::InvalidArgumentError(
            absl::StrCat("token ", i + 1, " (tenant ", e.tenant, ") appears twice"));
      }
    }
    table.entries_.push_back(std::move(e));
  }
  return table;
}

std::optional<std::string> TokenTable::Lookup(absl::string_view token) const {
  const std::array<uint8_t, 32> d = Digest(token);
  const Entry* match = nullptr;
  for (const Entry& e : entries_) {
    // No early exit: every entry is compared, whatever matched before.
    const bool equal = CRYPTO_memcmp(e.digest.data(), d.data(), d.size()) == 0;
    if (equal) match = &e;
  }
  if (match == nullptr) return std::nullopt;
  return match->tenant;
}

std::set<std::string> TokenTable::tenants() const {
  std::set<std::string> out;
  for (const Entry& e : entries_) out.insert(e.tenant);
  return out;
}

bool SecretEquals(absl::string_view a, absl::string_view b) {
  const std::array<uint8_t, 32> da = Digest(a), db = Digest(b);
  return CRYPTO_memcmp(da.data(), db.data(), da.size()) == 0;
}

absl::StatusOr<std::string> RandomSecret() {
  unsigned char bytes[32];
  if (RAND_bytes(bytes, sizeof(bytes)) != 1) {
    return absl::InternalError("RAND_bytes failed: no random source for a secret");
  }
  std::string hex;
  for (unsigned char b : bytes) {
    hex.push_back("0123456789abcdef"[b >> 4]);
    hex.push_back("0123456789abcdef"[b & 15]);
  }
  return hex;
}

std::optional<std::string> ParseBearer(absl::string_view value) {
  value = absl::StripAsciiWhitespace(value);
  constexpr absl::string_view kScheme = "bearer";
  if (value.size() <= kScheme.size() + 1 ||
      !absl::EqualsIgnoreCase(value.substr(0, kScheme.size()), kScheme) ||
      value[kScheme.size()] != ' ') {
    return std::nullopt;
  }
  const absl::string_view token = absl::StripLeadingAsciiWhitespace(value.substr(kScheme.size()));
  if (token.empty()) return std::nullopt;
  return std::string(token);
}

bool IsLoopbackAddress(absl::string_view address) {
  if (absl::StartsWith(address, "unix:") || absl::StartsWith(address, "unix-abstract:")) {
    return true;
  }
  absl::string_view host = address;
  if (absl::ConsumePrefix(&host, "[")) {
    const size_t close = host.find(']');
    if (close == absl::string_view::npos) return false;
    host = host.substr(0, close);
  } else if (const size_t colon = host.rfind(':'); colon != absl::string_view::npos) {
    host = host.substr(0, colon);
  }
  if (absl::AsciiStrToLower(host) == "localhost" || host == "::1") return true;
  // 127.0.0.0/8: four decimal fields, the first 127.
  std::vector<absl::string_view> parts = absl::StrSplit(host, '.');
  if (parts.size() != 4) return false;
  for (absl::string_view p : parts) {
    int v = -1;
    if (!absl::SimpleAtoi(p, &v) || v < 0 || v > 255) return false;
  }
  return parts[0] == "127";
}

}  // namespace carvemap
