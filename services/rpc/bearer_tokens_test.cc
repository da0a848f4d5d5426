#include "services/rpc/bearer_tokens.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {
using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kTokA[] = "acme-token-0123456789abcdef";
constexpr char kTokA2[] = "acme-second-token-0123456789";
constexpr char kTokB[] = "beta-token-0123456789abcdef";

TEST(BearerTokensTest, ParsesLinesWithCommentsAndCommas) {
  auto tokens = ParseTokens(
      absl::StrCat("# tenants\n\n", kTokA, " acme\n  ", kTokB, "\tbeta  \n", kTokA2, " acme\n"),
      "tokens file t");
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  ASSERT_EQ(tokens->size(), 3u);
  EXPECT_EQ((*tokens)[1].token, kTokB);
  EXPECT_EQ((*tokens)[1].tenant, "beta");
  // The environment variable's form: entries separated by commas.
  auto env = ParseTokens(absl::StrCat(kTokA, " acme,", kTokB, " beta"), "CARVEMAP_TOKENS");
  ASSERT_TRUE(env.ok()) << env.status();
  EXPECT_EQ(env->size(), 2u);
}

TEST(BearerTokensTest, ParsesJson) {
  auto tokens = ParseTokens(absl::StrCat(R"({"tokens": [{"token": ")", kTokA,
                                         R"(", "tenant": "acme"}]})"),
                            "tokens file t.json");
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  ASSERT_EQ(tokens->size(), 1u);
  EXPECT_EQ((*tokens)[0].tenant, "acme");
  EXPECT_FALSE(ParseTokens(R"({"tokens": [{"token": 3, "tenant": "acme"}]})", "f").ok());
  EXPECT_FALSE(ParseTokens(R"({"toks": []})", "f").ok());
  EXPECT_FALSE(ParseTokens(R"({"tokens": [)", "f").ok());
}

// Every error names the source and the entry, and never shows a token.
TEST(BearerTokensTest, BadEntriesNameTheLineNotTheToken) {
  struct Case {
    std::string text;
    std::string want;
  };
  const std::string short_tok = "short-tok";
  for (const Case& c : std::vector<Case>{
           {absl::StrCat(kTokA, " acme\n", short_tok, " beta\n"), "entry 2: token: 9 characters"},
           {absl::StrCat(kTokA, " Acme\n"), "entry 1: tenant 'Acme'"},
           {absl::StrCat(kTokA, " ../x\n"), "entry 1: tenant '../x'"},
           {absl::StrCat(kTokA, "\n"), "entry 1: expected \"TOKEN TENANT\", got 1"},
           {absl::StrCat(kTokA, " acme extra\n"), "got 3 field(s)"},
           {absl::StrCat(kTokA, " acme\n", kTokA, " beta\n"), "appears twice"},
           {"acme-token-with-a-quote\"-0123456 acme", "character 24 is not one of"}}) {
    auto tokens = ParseTokens(c.text, "tokens file /etc/t");
    ASSERT_FALSE(tokens.ok()) << c.text;
    EXPECT_EQ(tokens.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(tokens.status().message(), HasSubstr("tokens file /etc/t"));
    EXPECT_THAT(tokens.status().message(), HasSubstr(c.want));
    EXPECT_THAT(tokens.status().message(), Not(HasSubstr(kTokA)));
    EXPECT_THAT(tokens.status().message(), Not(HasSubstr(short_tok)));
  }
}

TEST(BearerTokensTest, FilesAndSecrets) {
  const std::filesystem::path dir = ::testing::TempDir();
  const std::string file = (dir / "tokens").string();
  std::ofstream(file) << kTokA << " acme\n";
  auto tokens = ReadTokensFile(file);
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  EXPECT_EQ(tokens->size(), 1u);
  std::ofstream(file) << "# nothing\n";
  EXPECT_THAT(ReadTokensFile(file).status().message(), HasSubstr("no tokens"));
  EXPECT_EQ(ReadTokensFile((dir / "none").string()).status().code(),
            absl::StatusCode::kNotFound);

  const std::string secret = (dir / "secret").string();
  std::ofstream(secret) << "  cluster-secret-0123456789abcdef\n\n";
  auto s = ReadSecretFile(secret, "cluster secret");
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(*s, "cluster-secret-0123456789abcdef");
  std::ofstream(secret) << "tiny\n";
  EXPECT_THAT(ReadSecretFile(secret, "cluster secret").status().message(),
              HasSubstr("cluster secret " + secret + ": 4 characters"));
}

TEST(BearerTokensTest, TableLooksUpExactTokensOnly) {
  auto table = TokenTable::Build({{kTokA, "acme"}, {kTokA2, "acme"}, {kTokB, "beta"}});
  ASSERT_TRUE(table.ok()) << table.status();
  EXPECT_EQ(table->Lookup(kTokA), "acme");
  EXPECT_EQ(table->Lookup(kTokA2), "acme");
  EXPECT_EQ(table->Lookup(kTokB), "beta");
  EXPECT_EQ(table->Lookup(""), std::nullopt);
  EXPECT_EQ(table->Lookup(std::string(kTokA) + "x"), std::nullopt);      // longer
  EXPECT_EQ(table->Lookup(std::string(kTokA).substr(1)), std::nullopt);  // shorter
  std::string near = kTokA;
  near.back() ^= 1;
  EXPECT_EQ(table->Lookup(near), std::nullopt);
  EXPECT_EQ(table->tenants(), (std::set<std::string>{"acme", "beta"}));
  EXPECT_TRUE(TokenTable().empty());
}

TEST(BearerTokensTest, SecretEqualsAndRandomSecret) {
  EXPECT_TRUE(SecretEquals("abc", "abc"));
  EXPECT_FALSE(SecretEquals("abc", "abd"));
  EXPECT_FALSE(SecretEquals("abc", "abcd"));
  EXPECT_FALSE(SecretEquals("", "a"));
  auto a = RandomSecret();
  auto b = RandomSecret();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->size(), 64u);
  EXPECT_NE(*a, *b);
  EXPECT_TRUE(ValidateSecret(*a, "x").ok());
}

TEST(BearerTokensTest, ParseBearer) {
  EXPECT_EQ(ParseBearer("Bearer abc"), "abc");
  EXPECT_EQ(ParseBearer("bearer   abc "), "abc");
  EXPECT_EQ(ParseBearer("BEARER abc"), "abc");
  EXPECT_EQ(ParseBearer("Bearer"), std::nullopt);
  EXPECT_EQ(ParseBearer("Bearer "), std::nullopt);
  EXPECT_EQ(ParseBearer("Basic YWxhZGRpbjpvcGVu"), std::nullopt);
  EXPECT_EQ(ParseBearer("Bearerabc"), std::nullopt);
  EXPECT_EQ(ParseBearer("abc"), std::nullopt);
}

TEST(BearerTokensTest, LoopbackAddresses) {
  for (const char* a : {"127.0.0.1:0", "127.1.2.3:7600", "localhost:7600", "LOCALHOST:1",
                        "[::1]:7600", "unix:/tmp/s.sock"}) {
    EXPECT_TRUE(IsLoopbackAddress(a)) << a;
  }
  for (const char* a : {"0.0.0.0:7600", "[::]:7600", "10.0.0.7:7600", "carvemap:7600",
                        "128.0.0.1:1", "127.0.0:1", "127.0.0.256:1", ":7600", "[::1:7600"}) {
    EXPECT_FALSE(IsLoopbackAddress(a)) << a;
  }
}

}  // namespace
}  // namespace carvemap
