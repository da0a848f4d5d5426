// Subcommands of the `carvemap` binary. Each cmd_<name>.cc registers itself (PDAL-style: a
// stage registers a name) and stays a thin shell: flags ➜ options struct ➜ library call.
#pragma once

#include <string>

#include "absl/status/status.h"

namespace CLI {
class App;
}

namespace carvemap {

// Adds a subcommand to `app`. The subcommand's callback stores its process exit code in
// `exit_code` (0 = success).
using CommandRegistrar = void (*)(CLI::App& app, int& exit_code);

// `order` sorts the commands in --help. Returns true so it can initialise a static.
bool RegisterCommand(int order, CommandRegistrar registrar);

// Prints "carvemap <command>: <message>" to stderr and returns the exit code for `status`
// (0 when ok; 2 for invalid input; 1 otherwise).
int ReportStatus(const std::string& command, const absl::Status& status);

// ReportStatus's exit code without printing (for a server that logs its error as JSON).
int StatusExitCode(const absl::Status& status);

}  // namespace carvemap

#define CARVEMAP_REGISTER_COMMAND(order, registrar) \
  static const bool carvemap_registered_##registrar = ::carvemap::RegisterCommand(order, registrar)
