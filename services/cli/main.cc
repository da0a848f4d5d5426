// carvemap: indoor laser scans ➜ building models (Turner 2015). Thin entry point; every
// subcommand lives in its own cmd_<name>.cc.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "services/cli/commands.h"

namespace carvemap {
namespace {

std::vector<std::pair<int, CommandRegistrar>>& Registry() {
  static std::vector<std::pair<int, CommandRegistrar>> registry;
  return registry;
}

}  // namespace

bool RegisterCommand(int order, CommandRegistrar registrar) {
  Registry().emplace_back(order, registrar);
  return true;
}

int ReportStatus(const std::string& command, const absl::Status& status) {
  if (status.ok()) return 0;
  std::cerr << "carvemap " << command << ": " << status.message() << "\n";
  return StatusExitCode(status);
}

int StatusExitCode(const absl::Status& status) {
  if (status.ok()) return 0;
  switch (status.code()) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kNotFound:
    case absl::StatusCode::kDataLoss:
    case absl::StatusCode::kFailedPrecondition:
      return 2;
    default:
      return 1;
  }
}

}  // namespace carvemap

int main(int argc, char** argv) {
  CLI::App app{
      "carvemap turns indoor laser scans of buildings into building models: occupancy octree,\n"
      "floor plans with rooms, 2.5D and 3D meshes (E. Turner, Berkeley 2015).\n"
      "Run `carvemap <command> --help` for a command's options."};
  // Line-buffered stdout keeps results and stderr progress in order when piped to a log.
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  app.require_subcommand(1);
  app.set_version_flag("--version", "carvemap 0.1.0");
  int exit_code = 0;
  auto& registry = carvemap::Registry();
  std::stable_sort(registry.begin(), registry.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [order, registrar] : registry) registrar(app, exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return exit_code;
}
