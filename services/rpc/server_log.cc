#include "services/rpc/server_log.h"

#include <grpc/support/log.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <ctime>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "coordinator/lease_id.h"

namespace carvemap {
namespace {

// The open LogScopes' fields, innermost last (per thread: spdlog's default logger formats on
// the thread that logs).
thread_local LogFields t_fields;

std::string IsoTimeUtc(std::chrono::system_clock::time_point t) {
  const auto ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(t.time_since_epoch()).count();
  const std::time_t secs = static_cast<std::time_t>(ms / 1000);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[40];
  const size_t n = std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%S", &tm);
  return absl::StrCat(absl::string_view(buf, n), ".", absl::Dec(ms % 1000, absl::kZeroPad3), "Z");
}

class JsonFormatter final : public spdlog::formatter {
 public:
  explicit JsonFormatter(std::string component) : component_(std::move(component)) {}

  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override {
    // Ordered: the four fixed keys first, as documented; later scopes override earlier ones.
    nlohmann::ordered_json j;
    j["time"] = IsoTimeUtc(msg.time);
    const auto level = spdlog::level::to_string_view(msg.level);
    j["level"] = std::string(level.data(), level.size());
    j["component"] = component_;
    j["message"] = std::string(msg.payload.data(), msg.payload.size());
    for (const auto& [key, value] : t_fields) {
      if (key == "time" || key == "level" || key == "component" || key == "message") continue;
      j[key] = value;
    }
    // Invalid UTF-8 (a path from a tenant, a worker's error text) becomes U+FFFD instead of
    // an exception: a log line must never be lost.
    const std::string line = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    dest.append(line.data(), line.data() + line.size());
    dest.push_back('\n');
  }

  std::unique_ptr<spdlog::formatter> clone() const override {
    return std::make_unique<JsonFormatter>(component_);
  }

 private:
  std::string component_;
};

void GrpcToSpdlog(gpr_log_func_args* args) {
  LogScope scope({{"source", "grpc"}});
  const spdlog::level::level_enum level =
      args->severity == GPR_LOG_SEVERITY_ERROR  ? spdlog::level::err
      : args->severity == GPR_LOG_SEVERITY_INFO ? spdlog::level::info
                                                : spdlog::level::debug;
  spdlog::log(level, "grpc: {} ({}:{})", args->message ? args->message : "",
              args->file ? args->file : "?", args->line);
}

}  // namespace

absl::StatusOr<LogFormat> ParseLogFormat(std::string_view name) {
  if (name == "text") return LogFormat::kText;
  if (name == "json") return LogFormat::kJson;
  return absl::InvalidArgumentError(absl::StrCat(
      "log format '", absl::string_view(name.data(), name.size()), "': must be 'text' or 'json'"));
}

std::unique_ptr<spdlog::formatter> MakeJsonLogFormatter(std::string component) {
  return std::make_unique<JsonFormatter>(std::move(component));
}

void SetUpServerLogging(LogFormat format, const std::string& component, bool verbose) {
  spdlog::set_level(verbose ? spdlog::level::debug : spdlog::level::info);
  if (format == LogFormat::kJson) {
    spdlog::set_formatter(MakeJsonLogFormatter(component));
    // Otherwise gRPC writes its own "E1126 00:35:32 ..." lines to stderr, which no JSON
    // reader can parse.
    gpr_set_log_function(GrpcToSpdlog);
  } else {
    spdlog::set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%n] [%l] %v");
  }
}

LogScope::LogScope(LogFields fields) : restore_size_(t_fields.size()) {
  for (auto& field : fields) t_fields.push_back(std::move(field));
}

LogScope::~LogScope() { t_fields.resize(restore_size_); }

LogFields LeaseLogFields(std::string_view lease_id, std::string_view worker_id) {
  LogFields fields;
  // Debian's absl has its own string_view.
  if (absl::StatusOr<LeaseId> id =
          LeaseId::Parse(absl::string_view(lease_id.data(), lease_id.size()));
      id.ok()) {
    fields.emplace_back("job", id->job_id);
    fields.emplace_back("chunk", absl::StrCat(id->chunk.x, ",", id->chunk.y, ",", id->chunk.z));
  }
  if (!lease_id.empty()) fields.emplace_back("lease", std::string(lease_id));
  if (!worker_id.empty()) fields.emplace_back("worker", std::string(worker_id));
  return fields;
}

}  // namespace carvemap
