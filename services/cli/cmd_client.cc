// `carvemap upload|submit|watch|status|list|cancel|fetch --server HOST:PORT`: talk to a running
// coordinator's JobService (docs/RPC.md). Thin shells over services/rpc/job_client.h.
#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/cli/north_flags.h"
#include "services/cli/progress.h"
#include "services/cli/security_flags.h"
#include "services/rpc/http_get.h"
#include "services/rpc/job_client.h"
#include "services/rpc/metrics_text.h"
#include "services/rpc/process_util.h"

namespace carvemap {
namespace {

constexpr char kDefaultServer[] = "127.0.0.1:7600";

struct ClientFlags {
  std::string server = kDefaultServer;
  std::string job_id;
  SubmitParams submit;
  NorthFlags north;  // §2.3, copied into `submit`
  bool watch = false;
  bool quiet = false;
  std::string state;
  int limit = 50;
  std::string reason;
  std::string artifact;
  std::string dest;
  SecurityFlags security;
  std::string upload;       // a local file to upload (`upload`, `submit --upload`)
  std::string upload_name;  // its name in the tenant's uploads/ folder; "" = its own
  std::string metrics;  // host:port or URL of the coordinator's /metrics
  double interval_s = 2;
  int count = 0;
};

// The coordinator's metrics as one line (services/rpc/metrics_text.h), or why not.
std::string MetricsLine(const std::string& where) {
  absl::StatusOr<std::string> text = HttpGet(where, 5.0);
  if (!text.ok()) return absl::StrCat("metrics: ", text.status().message());
  absl::StatusOr<std::vector<MetricSample>> samples = ParsePrometheusText(*text);
  if (!samples.ok()) return absl::StrCat("metrics: ", samples.status().message());
  return FormatCoordinatorMetrics(*samples);
}

void AddServer(CLI::App* cmd, ClientFlags& flags) {
  cmd->add_option("--server", flags.server, "host:port of the coordinator")
      ->envname("CARVEMAP_SERVER")
      ->capture_default_str();
  AddSecurityFlags(cmd, flags.security, /*worker=*/false);
}

// The client of the command, or null after reporting why not (a token file that cannot be
// read, a bad TLS file).
std::unique_ptr<JobClient> Connect(const ClientFlags& flags, const char* command,
                                   int& exit_code) {
  absl::StatusOr<ChannelSecurity> security = ResolveSecurity(flags.security, /*worker=*/false);
  if (!security.ok()) {
    exit_code = ReportStatus(command, security.status());
    return nullptr;
  }
  return std::make_unique<JobClient>(flags.server, *security);
}

// Exit status of a finished job: its error, if any, as the command's error.
absl::Status JobOutcome(const JobInfo& job) {
  if (job.state == "SUCCEEDED") return absl::OkStatus();
  if (job.state == "CANCELLED") return absl::CancelledError(absl::StrCat("job ", job.job_id, ": ", job.error));
  return absl::AbortedError(absl::StrCat("job ", job.job_id, " ", job.state, ": ", job.error));
}

// `metrics` (optional): also show the coordinator's metrics every `interval_s`.
absl::Status WatchWithProgress(JobClient& client, const std::string& job_id, bool quiet,
                               const std::string& metrics = "", double interval_s = 2) {
  HandleTerminationSignals([&client](int) { client.CancelWatch(); });
  ProgressLine line(!quiet);
  std::string last_state;
  std::chrono::steady_clock::time_point last_metrics{};
  absl::StatusOr<JobInfo> job = client.Watch(job_id, 0.5, [&](const WatchUpdate& u) {
    if (u.state != last_state && !last_state.empty()) line.Finish();
    last_state = u.state;
    line.Update("%s", FormatProgress(u).c_str());
    const auto now = std::chrono::steady_clock::now();
    if (!metrics.empty() && !quiet &&
        now - last_metrics >= std::chrono::duration<double>(interval_s)) {
      last_metrics = now;
      line.Finish();
      std::fprintf(stderr, "  coordinator: %s\n", MetricsLine(metrics).c_str());
    }
  });
  line.Finish();
  if (!job.ok()) return job.status();
  std::printf("%s\n", FormatJob(*job).c_str());
  return JobOutcome(*job);
}

// Uploads flags.upload with a progress line (docs/RPC.md "Uploads"), resuming after broken
// connections.
absl::StatusOr<UploadInfo> UploadWithProgress(JobClient& client, const ClientFlags& flags) {
  ProgressLine line(!flags.quiet);
  if (!flags.quiet) line.Update("hashing %s", flags.upload.c_str());
  UploadOptions options;
  options.name = flags.upload_name;
  const auto start = std::chrono::steady_clock::now();
  int64_t first = -1;
  options.on_progress = [&](int64_t done, int64_t total) {
    if (first < 0) first = done;
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double rate = s > 0 ? double(done - first) / s : 0;
    line.Update("uploading %s  %.1f/%.1f MB  %.1f MB/s", flags.upload.c_str(), done / 1e6,
                total / 1e6, rate / 1e6);
  };
  options.on_retry = [&](const absl::Status& why, double wait_s) {
    line.Finish();
    std::fprintf(stderr, "upload: %s; resuming in %.1f s\n", std::string(why.message()).c_str(),
                 wait_s);
  };
  absl::StatusOr<UploadInfo> up = client.Upload(flags.upload, options);
  line.Finish();
  return up;
}

void RegisterClientCommands(CLI::App& app, int& exit_code) {
  auto flags = std::make_shared<ClientFlags>();

  CLI::App* submit = app.add_subcommand("submit", "Submit a carving job to a coordinator");
  AddServer(submit, *flags);
  CLI::Option* input =
      submit->add_option("input", flags->submit.input_path,
                         "scan.h5, relative to the coordinator's data root (your tenant's folder)");
  CLI::Option* upload = submit->add_option(
      "--upload", flags->upload,
      "Upload this local scan.h5 first (resumable; see `carvemap upload`), then submit it");
  input->excludes(upload);
  submit
      ->add_option("--upload-name", flags->upload_name,
                   "With --upload: its name in your uploads/ folder (default: its own)")
      ->needs(upload);
  submit->add_option("-o,--output-name", flags->submit.output_name,
                     "Output folder name under the coordinator's output root (default: job id)");
  submit->add_option("--resolution", flags->submit.resolution_m,
                     "Leaf size in metres: 0.0625, 0.03125, 0.015625 or 0.0078125 (0: default)");
  submit->add_option("--object-resolution", flags->submit.object_resolution_m,
                     "Leaf size the object chunks are carved again at (§5.6.1); 0: half "
                     "of --resolution, equal to it: no re-carving");
  submit->add_option("--floorplan", flags->submit.floorplan_method,
                     "Floor-plan method of the merge: rooms (§3.3 room partitioning, the "
                     "default) or eigencrust (§3.2, with §3.3's rooms on its interior)")
      ->check(CLI::IsMember({"rooms", "eigencrust"}));
  submit->add_flag("--points", flags->submit.trimmed_points,
                   "The merge also writes points.ply: the scan's points without those farther "
                   "than 1 m from the floor plans (§5.5)");
  submit->add_option("--min-object-volume", flags->submit.min_object_volume_m3,
                     "Objects with less volume than this, m³, are dropped (§5.6); 0: the "
                     "default, 0.005")
      ->check(CLI::Range(0.0, 1000.0));
  submit->add_option("--evaluation", flags->submit.evaluation,
                     "How the workers evaluate eq 4.7: fast (single precision, the default) or exact (double "
                     "precision, the reference; the same votes, within the tolerance in "
                     "worker/chunk_octree.h)")
      ->check(CLI::IsMember({"fast", "exact"}));
  AddNorthFlags(submit, flags->north, /*optional_mode=*/true);
  submit->add_option("--idempotency-key", flags->submit.idempotency_key,
                     "Submitting twice with the same key returns the first job");
  submit->add_flag("--watch", flags->watch, "Watch the job until it ends");
  submit->add_flag("-q,--quiet", flags->quiet, "No progress line");
  submit->callback([flags, &exit_code] {
    std::unique_ptr<JobClient> connected = Connect(*flags, "submit", exit_code);
    if (connected == nullptr) return;
    JobClient& client = *connected;
    flags->submit.north = flags->north.mode;
    flags->submit.location = flags->north.location;
    flags->submit.survey_date = flags->north.survey_date;
    if (flags->submit.input_path.empty() && flags->upload.empty()) {
      exit_code = ReportStatus(
          "submit",
          absl::InvalidArgumentError("give the scan's path on the server, or --upload FILE"));
      return;
    }
    if (!flags->upload.empty()) {
      absl::StatusOr<UploadInfo> up = UploadWithProgress(client, *flags);
      if (!up.ok()) {
        exit_code = ReportStatus("submit", up.status());
        return;
      }
      flags->submit.upload_id = up->upload_id;
    }
    absl::StatusOr<JobInfo> job = client.Submit(flags->submit);
    if (!job.ok()) {
      exit_code = ReportStatus("submit", job.status());
      return;
    }
    std::printf("%s\n", job->job_id.c_str());
    if (flags->watch) {
      exit_code = ReportStatus("submit", WatchWithProgress(client, job->job_id, flags->quiet));
    }
  });

  CLI::App* up = app.add_subcommand(
      "upload",
      "Upload a local scan.h5 into your folder on the coordinator (uploads/NAME), resumable: "
      "after a broken connection it goes on from what the server holds, also when run again");
  AddServer(up, *flags);
  up->add_option("file", flags->upload, "The local file")->required()->check(CLI::ExistingFile);
  up->add_option("--name", flags->upload_name,
                 "Its name in your uploads/ folder, [A-Za-z0-9._-]{1,128} (default: its own)");
  up->add_flag("-q,--quiet", flags->quiet, "No progress line");
  up->callback([flags, &exit_code] {
    std::unique_ptr<JobClient> connected = Connect(*flags, "upload", exit_code);
    if (connected == nullptr) return;
    absl::StatusOr<UploadInfo> info = UploadWithProgress(*connected, *flags);
    if (!info.ok()) {
      exit_code = ReportStatus("upload", info.status());
      return;
    }
    std::printf("%s %s\n", info->upload_id.c_str(), info->input_path.c_str());
    if (!flags->quiet) {
      std::fprintf(stderr, "uploaded %s (%lld bytes): submit it with `carvemap submit %s`\n",
                   flags->upload.c_str(), static_cast<long long>(info->size_bytes),
                   info->input_path.c_str());
    }
  });

  CLI::App* watch = app.add_subcommand(
      "watch",
      "Follow a job's progress until it ends; with --metrics also (or, without a job id, "
      "only) the coordinator's metrics: workers, chunks queued/leased/done, rays/s, lease "
      "expiries, refused calls, RPC latencies");
  AddServer(watch, *flags);
  watch->add_option("job", flags->job_id, "Job id");
  watch->add_flag("-q,--quiet", flags->quiet, "No progress line");
  watch->add_option("--metrics", flags->metrics,
                    "The coordinator's metrics endpoint, host:port or URL (its --metrics-listen)")
      ->envname("CARVEMAP_METRICS");
  watch->add_option("--interval", flags->interval_s, "Seconds between metrics lines")
      ->capture_default_str();
  watch->add_option("--count", flags->count,
                    "Without a job id: stop after this many metrics lines (0: until Ctrl-C)");
  watch->callback([flags, &exit_code] {
    if (flags->job_id.empty()) {
      if (flags->metrics.empty()) {
        exit_code = ReportStatus(
            "watch", absl::InvalidArgumentError("give a job id, or --metrics HOST:PORT"));
        return;
      }
      auto stop = std::make_shared<std::atomic<bool>>(false);
      HandleTerminationSignals([stop](int) { stop->store(true); });
      for (int n = 0; !stop->load() && (flags->count <= 0 || n < flags->count); ++n) {
        if (n > 0) {
          for (double slept = 0; slept < flags->interval_s && !stop->load(); slept += 0.1) {
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
          }
          if (stop->load()) break;
        }
        absl::StatusOr<std::string> text = HttpGet(flags->metrics, 5.0);
        absl::StatusOr<std::vector<MetricSample>> samples =
            text.ok() ? ParsePrometheusText(*text)
                      : absl::StatusOr<std::vector<MetricSample>>(text.status());
        if (!samples.ok()) {
          exit_code = ReportStatus("watch", samples.status());
          return;
        }
        std::printf("%s\n", FormatCoordinatorMetrics(*samples).c_str());
        std::fflush(stdout);
      }
      return;
    }
    std::unique_ptr<JobClient> connected = Connect(*flags, "watch", exit_code);
    if (connected == nullptr) return;
    JobClient& client = *connected;
    exit_code = ReportStatus("watch", WatchWithProgress(client, flags->job_id, flags->quiet,
                                                        flags->metrics, flags->interval_s));
  });

  CLI::App* status = app.add_subcommand("status", "Show a job");
  AddServer(status, *flags);
  status->add_option("job", flags->job_id, "Job id")->required();
  status->callback([flags, &exit_code] {
    std::unique_ptr<JobClient> connected = Connect(*flags, "status", exit_code);
    if (connected == nullptr) return;
    JobClient& client = *connected;
    absl::StatusOr<JobInfo> job = client.Get(flags->job_id);
    if (!job.ok()) {
      exit_code = ReportStatus("status", job.status());
      return;
    }
    std::printf("%s\n", FormatJob(*job).c_str());
    std::printf("  resolution %g m, %lld chunk(s) leased, %lld retried\n", job->resolution_m,
                static_cast<long long>(job->chunks_leased),
                static_cast<long long>(job->chunk_retries));
  });

  CLI::App* list = app.add_subcommand("list", "List jobs, newest first");
  AddServer(list, *flags);
  list->add_option("--state", flags->state,
                   "Only jobs in this state (QUEUED, INGESTING, CARVING, MERGING, SUCCEEDED, "
                   "FAILED, CANCELLED)");
  list->add_option("--limit", flags->limit, "At most this many jobs")->capture_default_str();
  list->callback([flags, &exit_code] {
    std::unique_ptr<JobClient> connected = Connect(*flags, "list", exit_code);
    if (connected == nullptr) return;
    JobClient& client = *connected;
    absl::StatusOr<std::vector<JobInfo>> jobs = client.List(flags->state, flags->limit);
    if (!jobs.ok()) {
      exit_code = ReportStatus("list", jobs.status());
      return;
    }
    for (const JobInfo& j : *jobs) std::printf("%s\n", FormatJob(j).c_str());
  });

  CLI::App* cancel = app.add_subcommand("cancel", "Cancel a job");
  AddServer(cancel, *flags);
  cancel->add_option("job", flags->job_id, "Job id")->required();
  cancel->add_option("--reason", flags->reason, "Stored with the job's error");
  cancel->callback([flags, &exit_code] {
    std::unique_ptr<JobClient> connected = Connect(*flags, "cancel", exit_code);
    if (connected == nullptr) return;
    JobClient& client = *connected;
    absl::StatusOr<JobInfo> job = client.Cancel(flags->job_id, flags->reason);
    if (!job.ok()) {
      exit_code = ReportStatus("cancel", job.status());
      return;
    }
    std::printf("%s\n", FormatJob(*job).c_str());
  });

  CLI::App* fetch = app.add_subcommand("fetch", "Download an output file of a job");
  AddServer(fetch, *flags);
  fetch->add_option("job", flags->job_id, "Job id")->required();
  fetch->add_option("name", flags->artifact, "Output path under out/<job>/, e.g. job.json")
      ->required();
  fetch->add_option("-o,--output", flags->dest, "Destination file (default: the name's basename)");
  fetch->callback([flags, &exit_code] {
    std::unique_ptr<JobClient> connected = Connect(*flags, "fetch", exit_code);
    if (connected == nullptr) return;
    JobClient& client = *connected;
    std::string dest = flags->dest;
    if (dest.empty()) dest = flags->artifact.substr(flags->artifact.rfind('/') + 1);
    absl::Status s = client.Fetch(flags->job_id, flags->artifact, dest);
    if (s.ok()) std::printf("%s\n", dest.c_str());
    exit_code = ReportStatus("fetch", s);
  });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(62, RegisterClientCommands);

}  // namespace carvemap
