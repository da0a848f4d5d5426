// How the servers log (docs/DESIGN.md §8: "log with spdlog (text or JSON)"): `--log-format text`,
// the human line "[time] [level] message", or `--log-format json`, one JSON object per line for a
// log collector:
//
//   {"time":"2026-11-26T00:35:32.310Z","level":"info","component":"coordinator",
//    "message":"coordinator: job j-1 CARVING -> MERGING","job":"j-1"}
//
// time is UTC with milliseconds; level is spdlog's name (trace, debug, info, warning, error,
// critical); component is the process's role (coordinator, worker); then the fields of the
// LogScopes open on the logging thread (job, chunk "x,y,z", lease, worker), where known.
// gRPC's own messages go through the same logger (field "source": "grpc").
#ifndef CARVEMAP_SERVICES_RPC_SERVER_LOG_H_
#define CARVEMAP_SERVICES_RPC_SERVER_LOG_H_

#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <spdlog/formatter.h>

#include "absl/status/statusor.h"

namespace carvemap {

enum class LogFormat { kText, kJson };

// "text" or "json"; anything else is INVALID_ARGUMENT.
absl::StatusOr<LogFormat> ParseLogFormat(std::string_view name);

// Sets up spdlog's default logger for a server process: the format, the level (debug when
// verbose, else info), and, for JSON, gRPC's log messages routed through it.
void SetUpServerLogging(LogFormat format, const std::string& component, bool verbose);

// The JSON formatter alone (tests give it a logger of their own).
std::unique_ptr<spdlog::formatter> MakeJsonLogFormatter(std::string component);

using LogFields = std::vector<std::pair<std::string, std::string>>;

// Fields added to every JSON log line written on this thread while the scope is open; nested
// scopes add to (and may override) the outer ones. Text lines are unchanged.
class LogScope {
 public:
  explicit LogScope(LogFields fields);
  LogScope(std::initializer_list<std::pair<std::string, std::string>> fields)
      : LogScope(LogFields(fields)) {}
  ~LogScope();
  LogScope(const LogScope&) = delete;
  LogScope& operator=(const LogScope&) = delete;

 private:
  size_t restore_size_;
};

// The fields of a lease id "<job>/<x>,<y>,<z>/<generation>" (job, chunk, lease) plus the
// worker; just the lease when it does not parse.
LogFields LeaseLogFields(std::string_view lease_id, std::string_view worker_id);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_SERVER_LOG_H_
