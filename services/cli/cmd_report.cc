// `carvemap report OUT`: rebuilds a job's report (OUT/index.html, services/report/job_report.h)
// from OUT/job.json. `carvemap serve OUT`: serves OUT over HTTP on this machine, so that the
// report's 3D view can load mesh/model.glb (browsers do not let a page opened as a file read
// other files). Static files only, read-only, with civetweb (Debian's libcivetweb, already
// linked for the metrics endpoints).
#include <civetweb.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/report/job_report.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

absl::Status RunReport(const std::string& out_dir) {
  const fs::path job_path = fs::path(out_dir) / "job.json";
  std::ifstream in(job_path);
  if (!in) {
    return absl::NotFoundError(
        absl::StrCat(job_path.string(), ": no job.json (is this a job's output folder?)"));
  }
  const nlohmann::json job = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (!job.is_object()) {
    return absl::DataLossError(absl::StrCat(job_path.string(), ": not a JSON object"));
  }
  if (absl::Status s = WriteJobReport(out_dir, job); !s.ok()) return s;
  std::cout << (fs::path(out_dir) / "index.html").string() << "\n  open it, or run `carvemap serve "
            << out_dir << "` to see the 3D view\n";
  return absl::OkStatus();
}

std::atomic<bool> g_stop{false};

absl::Status RunServe(const std::string& out_dir, const std::string& listen) {
  if (!fs::is_regular_file(fs::path(out_dir) / "index.html")) {
    return absl::NotFoundError(
        absl::StrCat(out_dir, ": no index.html (run `carvemap report ", out_dir, "` first)"));
  }
  const std::string root = fs::absolute(out_dir).string();
  // civetweb's options: the folder, the address, no directory listings, no scripts.
  const char* options[] = {"document_root",
                           root.c_str(),
                           "listening_ports",
                           listen.c_str(),
                           "enable_directory_listing",
                           "no",
                           "num_threads",
                           "4",
                           "cgi_pattern",
                           "",
                           nullptr};
  mg_init_library(0);
  mg_callbacks callbacks{};
  mg_context* ctx = mg_start(&callbacks, nullptr, options);
  if (ctx == nullptr) {
    mg_exit_library();
    return absl::UnavailableError(absl::StrCat("serve: cannot listen on ", listen,
                                               " (in use, or not an address of this "
                                               "machine?)"));
  }
  mg_server_port port{};
  const int ports = mg_get_server_ports(ctx, 1, &port);
  std::cout << "serving " << root << " on http://127.0.0.1:" << (ports > 0 ? port.port : 0)
            << "/index.html (Ctrl-C stops)" << std::endl;
  std::signal(SIGINT, [](int) { g_stop = true; });
  std::signal(SIGTERM, [](int) { g_stop = true; });
  while (!g_stop) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  mg_stop(ctx);
  mg_exit_library();
  return absl::OkStatus();
}

void RegisterReport(CLI::App& app, int& exit_code) {
  CLI::App* report = app.add_subcommand(
      "report",
      "Rebuild a job's report, OUT/index.html (its numbers, where the time went, each level's "
      "floor plan over its top-down map, the 3D model to orbit and click), from OUT/job.json");
  auto out = std::make_shared<std::string>();
  report->add_option("out", *out, "The job's output folder")->required();
  report->callback([out, &exit_code] { exit_code = ReportStatus("report", RunReport(*out)); });

  CLI::App* serve = app.add_subcommand(
      "serve",
      "Serve a job's output folder over HTTP on this machine, to open its report "
      "(OUT/index.html) with its 3D view in a browser");
  auto folder = std::make_shared<std::string>();
  auto listen = std::make_shared<std::string>("127.0.0.1:8080");
  serve->add_option("out", *folder, "The job's output folder (with index.html)")->required();
  serve
      ->add_option("--listen", *listen,
                   "Address and port, civetweb's form (127.0.0.1:8080; port 0 takes a free one)")
      ->capture_default_str();
  serve->callback([folder, listen, &exit_code] {
    exit_code = ReportStatus("serve", RunServe(*folder, *listen));
  });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(53, RegisterReport);

}  // namespace carvemap
