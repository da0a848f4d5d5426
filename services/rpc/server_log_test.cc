#include "services/rpc/server_log.h"

#include <grpc/support/log.h>

#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

namespace carvemap {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;

// A logger writing into `out` with the JSON formatter of `component`.
std::shared_ptr<spdlog::logger> JsonLogger(std::ostringstream& out, const std::string& component) {
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  auto logger = std::make_shared<spdlog::logger>("test", sink);
  logger->set_formatter(MakeJsonLogFormatter(component));
  logger->set_level(spdlog::level::trace);
  return logger;
}

std::vector<nlohmann::ordered_json> Lines(const std::string& text) {
  std::vector<nlohmann::ordered_json> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    lines.push_back(nlohmann::ordered_json::parse(line));  // throws (fails) if not JSON
  }
  return lines;
}

std::vector<std::string> Keys(const nlohmann::ordered_json& j) {
  std::vector<std::string> keys;
  for (auto it = j.begin(); it != j.end(); ++it) keys.push_back(it.key());
  return keys;
}

TEST(ServerLogTest, OneJsonObjectPerLineWithTheFixedKeysFirst) {
  std::ostringstream out;
  auto logger = JsonLogger(out, "coordinator");
  logger->info("coordinator: job {} CARVING -> MERGING", "j-1");
  logger->warn("second");
  logger->debug("third");
  const auto lines = Lines(out.str());
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_THAT(Keys(lines[0]), ElementsAre("time", "level", "component", "message"));
  EXPECT_EQ(lines[0]["component"], "coordinator");
  EXPECT_EQ(lines[0]["message"], "coordinator: job j-1 CARVING -> MERGING");
  EXPECT_EQ(lines[0]["level"], "info");
  EXPECT_EQ(lines[1]["level"], "warning");
  EXPECT_EQ(lines[2]["level"], "debug");
  // ISO 8601, UTC, milliseconds.
  const std::regex iso(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z)");
  EXPECT_TRUE(std::regex_match(lines[0]["time"].get<std::string>(), iso)) << lines[0]["time"];
}

TEST(ServerLogTest, MessagesThatWouldBreakALineStayOneLine) {
  std::ostringstream out;
  auto logger = JsonLogger(out, "worker");
  // An HDF5 error text carries newlines; a tenant's path may carry quotes, backslashes,
  // control characters, and bytes that are not UTF-8.
  const std::string nasty = "a \"quoted\" \\path\\\nsecond line\ttab \x01 \xff\xfe end";
  logger->error("{}", nasty);
  const std::string text = out.str();
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << text;
  const auto lines = Lines(text);
  ASSERT_EQ(lines.size(), 1u);
  const std::string message = lines[0]["message"];
  EXPECT_THAT(message, HasSubstr("a \"quoted\" \\path\\\nsecond line\ttab \x01 "));
  EXPECT_THAT(message, HasSubstr("\xEF\xBF\xBD"));  // U+FFFD for the invalid bytes
  EXPECT_THAT(message, HasSubstr(" end"));
}

TEST(ServerLogTest, ScopesAddFieldsOnTheirThreadOnly) {
  std::ostringstream out;
  auto logger = JsonLogger(out, "coordinator");
  {
    LogScope job({{"job", "j-7"}});
    logger->info("in the job");
    {
      LogScope lease(LeaseLogFields("j-7/1,-2,0/3", "w-ab-1"));
      logger->info("a chunk");
      // Another thread (a gRPC handler) has scopes of its own, not these.
      std::thread([&] { logger->info("elsewhere"); }).join();
    }
    logger->info("back in the job");
  }
  logger->info("after");
  const auto lines = Lines(out.str());
  ASSERT_EQ(lines.size(), 5u);
  EXPECT_EQ(lines[0]["job"], "j-7");
  EXPECT_FALSE(lines[0].contains("chunk"));
  EXPECT_THAT(Keys(lines[1]),
              ElementsAre("time", "level", "component", "message", "job", "chunk", "lease",
                          "worker"));
  EXPECT_EQ(lines[1]["chunk"], "1,-2,0");
  EXPECT_EQ(lines[1]["lease"], "j-7/1,-2,0/3");
  EXPECT_EQ(lines[1]["worker"], "w-ab-1");
  EXPECT_EQ(Keys(lines[2]).size(), 4u) << lines[2];  // the other thread
  EXPECT_EQ(lines[3]["job"], "j-7");
  EXPECT_FALSE(lines[3].contains("chunk"));
  EXPECT_EQ(Keys(lines[4]).size(), 4u) << lines[4];
}

TEST(ServerLogTest, ScopeFieldsNeverReplaceTheFixedKeys) {
  std::ostringstream out;
  auto logger = JsonLogger(out, "worker");
  LogScope scope({{"message", "forged"}, {"component", "x"}, {"job", "j-1"}});
  logger->info("real");
  const auto lines = Lines(out.str());
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0]["message"], "real");
  EXPECT_EQ(lines[0]["component"], "worker");
  EXPECT_EQ(lines[0]["job"], "j-1");
}

TEST(ServerLogTest, LeaseFields) {
  EXPECT_THAT(LeaseLogFields("j-1/0,0,0/1", ""),
              ElementsAre(std::pair<std::string, std::string>("job", "j-1"),
                          std::pair<std::string, std::string>("chunk", "0,0,0"),
                          std::pair<std::string, std::string>("lease", "j-1/0,0,0/1")));
  // Job ids may hold '/': the id is read from the right (coordinator/lease_id.h).
  EXPECT_THAT(LeaseLogFields("a/b/1,-2,3/4", ""),
              ElementsAre(std::pair<std::string, std::string>("job", "a/b"),
                          std::pair<std::string, std::string>("chunk", "1,-2,3"),
                          std::pair<std::string, std::string>("lease", "a/b/1,-2,3/4")));
  // Not a lease id: kept as it is, nothing made up.
  EXPECT_THAT(LeaseLogFields("garbage", "w-1"),
              ElementsAre(std::pair<std::string, std::string>("lease", "garbage"),
                          std::pair<std::string, std::string>("worker", "w-1")));
  EXPECT_TRUE(LeaseLogFields("", "").empty());
}

TEST(ServerLogTest, ParseLogFormat) {
  EXPECT_EQ(*ParseLogFormat("text"), LogFormat::kText);
  EXPECT_EQ(*ParseLogFormat("json"), LogFormat::kJson);
  EXPECT_EQ(ParseLogFormat("JSON").status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ParseLogFormat("").status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(ServerLogTest, GrpcMessagesGoThroughTheJsonLogger) {
  std::ostringstream out;
  auto previous = spdlog::default_logger();
  spdlog::set_default_logger(JsonLogger(out, "worker"));
  SetUpServerLogging(LogFormat::kJson, "worker", /*verbose=*/false);
  // What grpc_init does in a server (before it gRPC prints nothing); GRPC_VERBOSITY's default
  // is ERROR.
  gpr_log_verbosity_init();
  gpr_log(GPR_ERROR, "boom %d", 7);
  spdlog::info("plain");
  gpr_set_log_function(nullptr);
  spdlog::set_default_logger(previous);
  const auto lines = Lines(out.str());
  ASSERT_EQ(lines.size(), 2u) << out.str();
  EXPECT_EQ(lines[0]["level"], "error");
  EXPECT_EQ(lines[0]["component"], "worker");
  EXPECT_EQ(lines[0]["source"], "grpc");
  EXPECT_THAT(lines[0]["message"].get<std::string>(), HasSubstr("boom 7"));
  EXPECT_FALSE(lines[1].contains("source"));
}

}  // namespace
}  // namespace carvemap
