// Process plumbing for the server commands and `carvemap run`: signals and child processes.
#ifndef CARVEMAP_SERVICES_RPC_PROCESS_UTIL_H_
#define CARVEMAP_SERVICES_RPC_PROCESS_UTIL_H_

#include <sys/types.h>

#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace carvemap {

// Blocks SIGINT and SIGTERM in this thread (and the threads it starts later) and calls
// `on_signal(signo)` from a dedicated thread for each one that arrives. Call it before any
// thread is started (gRPC starts threads), so no other thread gets the signal.
void HandleTerminationSignals(std::function<void(int)> on_signal);

// Starts `/proc/self/exe args...` in its own process group (Ctrl-C reaches only the parent,
// which stops the children in order), with stdout and stderr appended to `log_path` ("" =
// inherited) and SIGTERM delivered to it if the parent dies.
absl::StatusOr<pid_t> SpawnSelf(const std::vector<std::string>& args, const std::string& log_path);

// SIGTERM, then SIGKILL after `grace_s`; reaps the child. Returns its wait status.
int StopChild(pid_t pid, double grace_s);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_PROCESS_UTIL_H_
