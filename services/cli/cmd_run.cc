// `carvemap run SCAN.h5 -o OUT`: the whole distributed job on one machine (docs/DESIGN.md §9).
// Starts the merge service, the coordinator and N workers as separate processes on loopback,
// submits the job over RPC, shows its progress, and stops them.
//
// OUT/ gets the outputs (tiles/, octree.bt, level_0/, job.json); OUT/.carvemap/ holds the job
// store, the partial sums while the job runs, the servers' logs and their pid/port files.
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/synchronization/mutex.h"
#include "services/cli/commands.h"
#include "services/cli/north_flags.h"
#include "services/cli/progress.h"
#include "services/cli/security_flags.h"
#include "services/rpc/bearer_tokens.h"
#include "services/rpc/job_client.h"
#include "services/rpc/process_util.h"
#include "services/system/process_memory.h"

namespace carvemap {
namespace {
namespace fs = std::filesystem;

struct RunFlags {
  std::string scan;
  std::string output_dir;
  int workers = 2;
  double resolution_m = 0.0625;
  double object_resolution_m = 0;  // 0 = resolution / 2
  std::string floorplan_method = "rooms";
  bool trimmed_points = false;
  double min_object_volume_m3 = 0;  // 0 = the merge's default
  std::string evaluation = "fast";  // eq 4.7 in the workers
  NorthFlags north;                 // §2.3 (geometry/north_alignment.h)
  std::string storage_root;
  // Short defaults on one machine: a killed worker's chunks come back within seconds.
  double heartbeat_interval_s = 1.0;
  double worker_timeout_s = 5.0;
  double lease_timeout_s = 30.0;
  double merge_memory_mb = 0;  // the merge service's --memory-mb; 0: its default
  bool quiet = false;
};

// Children and the job, shared with the signal thread.
struct RunState {
  absl::Mutex mu;
  std::vector<pid_t> workers ABSL_GUARDED_BY(mu);
  pid_t coordinator ABSL_GUARDED_BY(mu) = -1;
  pid_t merger ABSL_GUARDED_BY(mu) = -1;
  std::string job_id ABSL_GUARDED_BY(mu);
  std::unique_ptr<JobClient> client;  // set once, before the job is submitted
  std::atomic<bool> interrupted{false};
};

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream(path) << text << "\n";
}

// `who` ("the coordinator", "the merge service") for the messages.
absl::StatusOr<std::string> WaitForPortFile(const fs::path& path, pid_t server, const char* who,
                                            const fs::path& log, double timeout_s) {
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(int(timeout_s * 1000));
  while (std::chrono::steady_clock::now() < deadline) {
    std::ifstream in(path);
    std::string address;
    if (in >> address && !address.empty()) return address;
    int status = 0;
    if (waitpid(server, &status, WNOHANG) == server) {
      return absl::UnavailableError(absl::StrCat(who, " exited during start-up (status ", status,
                                                 "); see ", log.string()));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return absl::DeadlineExceededError(
      absl::StrCat(who, " did not start within ", timeout_s, " s; see ", log.string()));
}

void StopAll(RunState& state) {
  std::vector<pid_t> workers;
  pid_t coordinator, merger;
  {
    absl::MutexLock lock(&state.mu);
    workers.swap(state.workers);
    coordinator = state.coordinator;
    state.coordinator = -1;
    merger = state.merger;
    state.merger = -1;
  }
  // Workers first: they finish the chunk in hand; then the coordinator (which cancels a merge
  // still running); then the merge service.
  std::vector<std::thread> stoppers;
  for (pid_t pid : workers) stoppers.emplace_back([pid] { StopChild(pid, 10.0); });
  for (std::thread& t : stoppers) t.join();
  if (coordinator > 0) StopChild(coordinator, 10.0);
  if (merger > 0) StopChild(merger, 10.0);
}

absl::Status Run(const RunFlags& flags, RunState& state) {
  if (flags.workers < 1) return absl::InvalidArgumentError("--workers must be >= 1");
  const fs::path scan = fs::absolute(flags.scan).lexically_normal();
  const fs::path out = fs::absolute(flags.output_dir).lexically_normal();
  if (out.filename().empty() || out == out.root_path()) {
    return absl::InvalidArgumentError(absl::StrCat("output ", flags.output_dir, ": not a folder name"));
  }
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) {
    return absl::FailedPreconditionError(
        absl::StrCat("output ", out.string(), ": cannot create: ", ec.message()));
  }
  if (::access(out.c_str(), W_OK | X_OK) != 0) {
    return absl::FailedPreconditionError(absl::StrCat("output ", out.string(), ": not writable"));
  }
  // A fresh job store per run: the output name is this run's, whatever ran here before.
  const fs::path work = out / ".carvemap";
  fs::remove_all(work, ec);
  fs::create_directories(work, ec);
  if (ec) return absl::FailedPreconditionError(absl::StrCat(work.string(), ": ", ec.message()));

  // The security variables a user may have set for a remote coordinator (docs/RPC.md) are
  // not for these servers: the children would pick them up.
  for (const char* name :
       {"CARVEMAP_SERVER", "CARVEMAP_TOKEN", "CARVEMAP_TOKEN_FILE", "CARVEMAP_TOKENS",
        "CARVEMAP_TOKENS_FILE", "CARVEMAP_CLUSTER_SECRET", "CARVEMAP_CLUSTER_SECRET_FILE",
        "CARVEMAP_TLS_CA", "CARVEMAP_TLS_CERT", "CARVEMAP_TLS_KEY", "CARVEMAP_TLS_SERVER_NAME",
        "CARVEMAP_MERGE_SERVER"}) {
    ::unsetenv(name);
  }
  // Our own servers get our own secrets, made fresh for this run: a tenant token for the job
  // API and the cluster secret for the workers and the merge service. Other users of this
  // machine cannot talk to them (the files are 0600), and nobody has to set anything up.
  absl::StatusOr<std::string> token = RandomSecret();
  if (!token.ok()) return token.status();
  absl::StatusOr<std::string> secret = RandomSecret();
  if (!secret.ok()) return secret.status();
  const fs::path tokens_file = work / "tokens";
  const fs::path secret_file = work / "cluster-secret";
  if (absl::Status s = WritePrivateFile(tokens_file.string(), *token + " local\n"); !s.ok()) {
    return s;
  }
  if (absl::Status s = WritePrivateFile(secret_file.string(), *secret + "\n"); !s.ok()) return s;

  // The merge service first: the coordinator is told where it is. It reads the tiles and
  // writes the outputs by path, as on a cluster's shared volume.
  const fs::path merger_log = work / "merger.log";
  std::vector<std::string> merger_args = {
      "merger", "--listen", "127.0.0.1:0", "--port-file", (work / "merger-port").string(),
      "--cluster-secret-file", secret_file.string()};
  if (flags.merge_memory_mb != 0) {
    merger_args.push_back("--memory-mb");
    merger_args.push_back(absl::StrCat(flags.merge_memory_mb));
  }
  absl::StatusOr<pid_t> merger = SpawnSelf(merger_args, merger_log.string());
  if (!merger.ok()) return merger.status();
  {
    absl::MutexLock lock(&state.mu);
    state.merger = *merger;
  }
  WriteText(work / "merger.pid", absl::StrCat(*merger));
  absl::StatusOr<std::string> merger_address =
      WaitForPortFile(work / "merger-port", *merger, "the merge service", merger_log, 30.0);
  if (!merger_address.ok()) return merger_address.status();

  std::vector<std::string> args = {
      "coordinator", "--listen", "127.0.0.1:0", "--port-file", (work / "port").string(),
      "--merge-server", *merger_address,
      "--tokens", tokens_file.string(), "--cluster-secret-file", secret_file.string(),
      "--shared-dirs",
      "--data-root", scan.parent_path().string(), "--output-root", out.parent_path().string(),
      "--work-dir", work.string(),
      "--heartbeat-interval-s", absl::StrCat(flags.heartbeat_interval_s),
      "--worker-timeout-s", absl::StrCat(flags.worker_timeout_s),
      "--lease-timeout-s", absl::StrCat(flags.lease_timeout_s)};
  if (!flags.storage_root.empty()) {
    args.push_back("--storage-root");
    args.push_back(fs::absolute(flags.storage_root).string());
  }
  const fs::path coordinator_log = work / "coordinator.log";
  absl::StatusOr<pid_t> coordinator = SpawnSelf(args, coordinator_log.string());
  if (!coordinator.ok()) return coordinator.status();
  {
    absl::MutexLock lock(&state.mu);
    state.coordinator = *coordinator;
  }
  WriteText(work / "coordinator.pid", absl::StrCat(*coordinator));
  absl::StatusOr<std::string> address =
      WaitForPortFile(work / "port", *coordinator, "the coordinator", coordinator_log, 30.0);
  if (!address.ok()) return address.status();

  for (int i = 0; i < flags.workers; ++i) {
    const fs::path log = work / absl::StrCat("worker-", i + 1, ".log");
    absl::StatusOr<pid_t> pid =
        SpawnSelf({"worker", "--coordinator", *address, "--listen", "127.0.0.1:0",
                   "--cluster-secret-file", secret_file.string()},
                  log.string());
    if (!pid.ok()) return pid.status();
    WriteText(work / absl::StrCat("worker-", i + 1, ".pid"), absl::StrCat(*pid));
    absl::MutexLock lock(&state.mu);
    state.workers.push_back(*pid);
  }
  if (!flags.quiet) {
    std::fprintf(stderr,
                 "carvemap run: coordinator on %s, %d worker(s), merge service on %s; logs in "
                 "%s\n",
                 address->c_str(), flags.workers, merger_address->c_str(), work.c_str());
  }

  ChannelSecurity security;
  security.bearer = *token;
  state.client = std::make_unique<JobClient>(*address, security);
  if (absl::Status s = state.client->WaitForReady(10.0); !s.ok()) return s;
  if (state.interrupted) return absl::CancelledError("interrupted");
  SubmitParams submit;
  submit.input_path = scan.filename().string();
  submit.output_name = out.filename().string();
  submit.resolution_m = flags.resolution_m;
  submit.object_resolution_m = flags.object_resolution_m;
  submit.floorplan_method = flags.floorplan_method;
  submit.trimmed_points = flags.trimmed_points;
  submit.min_object_volume_m3 = flags.min_object_volume_m3;
  submit.evaluation = flags.evaluation;
  submit.north = flags.north.mode;
  submit.location = flags.north.location;
  submit.survey_date = flags.north.survey_date;
  // The job id follows from the key (and tiles record it), so repeated runs of the same scan
  // and resolutions give byte-identical tiles whatever the number of workers. The method,
  // --points, --min-object-volume, --evaluation and --north are in the key only when not the
  // default, so the default's job ids stay as they were.
  submit.idempotency_key = absl::StrCat(
      "carvemap run ", scan.filename().string(), " ", flags.resolution_m, " ",
      flags.object_resolution_m,
      flags.floorplan_method == "rooms" ? "" : absl::StrCat(" ", flags.floorplan_method),
      flags.trimmed_points ? " points" : "",
      flags.min_object_volume_m3 > 0 ? absl::StrCat(" ", flags.min_object_volume_m3) : "",
      flags.evaluation == "fast" ? "" : absl::StrCat(" ", flags.evaluation),
      flags.north.mode == "auto" ? "" : absl::StrCat(" north=", flags.north.mode),
      flags.north.location.empty()
          ? ""
          : absl::StrCat(" at ", flags.north.location, " ", flags.north.survey_date));
  absl::StatusOr<JobInfo> job = state.client->Submit(submit);
  if (!job.ok()) return job.status();
  {
    absl::MutexLock lock(&state.mu);
    state.job_id = job->job_id;
  }
  if (state.interrupted) {
    (void)state.client->Cancel(job->job_id, "interrupted");
    return absl::CancelledError("interrupted");
  }
  if (!flags.quiet) std::fprintf(stderr, "carvemap run: job %s\n", job->job_id.c_str());

  const auto start = std::chrono::steady_clock::now();
  ProgressLine line(!flags.quiet);
  std::string last_state;
  absl::StatusOr<JobInfo> done =
      state.client->Watch(job->job_id, 0.5, [&](const WatchUpdate& u) {
        if (u.state != last_state && !last_state.empty()) line.Finish();
        last_state = u.state;
        line.Update("%s", FormatProgress(u).c_str());
      });
  line.Finish();
  if (state.interrupted) return absl::CancelledError("interrupted; job cancelled");
  if (!done.ok()) {
    return absl::UnavailableError(absl::StrCat("lost the coordinator: ", done.status().message(),
                                               "; see ", coordinator_log.string()));
  }
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (done->state != "SUCCEEDED") {
    return absl::AbortedError(absl::StrCat("job ", done->job_id, " ", done->state, ": ",
                                           done->error));
  }
  const fs::path tiles = flags.storage_root.empty()
                             ? out / "tiles"
                             : fs::absolute(flags.storage_root) / done->job_id / "tiles";
  std::printf("carvemap run: job %s SUCCEEDED in %.1f s: %lld tasks (slices and chunks; %lld "
              "retried)\n",
              done->job_id.c_str(), elapsed, static_cast<long long>(done->chunks_total),
              static_cast<long long>(done->chunk_retries));
  std::printf("  outputs in %s\n  tiles in %s\n", out.c_str(), tiles.c_str());
  return absl::OkStatus();
}

void RegisterRun(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "run",
      "Carve and merge a scan with a local coordinator, workers and merge service (separate "
      "processes on loopback)");
  auto flags = std::make_shared<RunFlags>();
  cmd->add_option("scan", flags->scan, "Input scan.h5")->required();
  cmd->add_option("-o,--output", flags->output_dir, "Output directory")->required();
  cmd->add_option("--workers", flags->workers, "Worker processes")->capture_default_str();
  cmd->add_option("--resolution", flags->resolution_m,
                  "Leaf size in metres: 0.0625, 0.03125, 0.015625 or 0.0078125")
      ->capture_default_str();
  cmd->add_option("--object-resolution", flags->object_resolution_m,
                  "Leaf size the chunks holding furniture are carved again at before the "
                  "objects are meshed (§5.6.1); 0 = half of --resolution (at least "
                  "0.0078125), equal to --resolution = no re-carving")
      ->capture_default_str();
  cmd->add_option("--floorplan", flags->floorplan_method,
                  "Floor-plan method of the merge: rooms (§3.3 room partitioning) or "
                  "eigencrust (§3.2, with §3.3's rooms on its interior)")
      ->check(CLI::IsMember({"rooms", "eigencrust"}))
      ->capture_default_str();
  cmd->add_flag("--points", flags->trimmed_points,
                "Also write OUT/points.ply: the scan's points in the world frame without those "
                "farther than 1 m from the floor plans (§5.5: seen through windows and doors)");
  cmd->add_option("--min-object-volume", flags->min_object_volume_m3,
                  "Objects with less volume than this, m³, are specks and dropped (§5.6); "
                  "0 = the default, 0.005 (5 litres)")
      ->check(CLI::Range(0.0, 1000.0));
  cmd->add_option("--evaluation", flags->evaluation,
                  "How the workers evaluate eq 4.7: fast (single precision, the default) or exact (double "
                  "precision, the reference; the same votes, within the tolerance in "
                  "worker/chunk_octree.h)")
      ->check(CLI::IsMember({"fast", "exact"}))
      ->capture_default_str();
  AddNorthFlags(cmd, flags->north);
  cmd->add_option("--storage-root", flags->storage_root,
                  "Keep tiles under <storage-root>/<job>/tiles instead of OUT/tiles");
  cmd->add_option("--heartbeat-interval-s", flags->heartbeat_interval_s,
                  "Worker heartbeat interval")
      ->capture_default_str();
  cmd->add_option("--worker-timeout-s", flags->worker_timeout_s,
                  "A silent worker is lost after this long and its chunks are requeued")
      ->capture_default_str();
  cmd->add_option("--lease-timeout-s", flags->lease_timeout_s, "Lease deadline")
      ->capture_default_str();
  cmd->add_option("--merge-memory-mb", flags->merge_memory_mb, kMergeMemoryBudgetHelp)
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress line");
  cmd->callback([flags, &exit_code] {
    auto state = std::make_shared<RunState>();
    // Ctrl-C / SIGTERM: cancel the job and stop the children (the job's own cleanup removes
    // its partial tiles), then exit non-zero.
    HandleTerminationSignals([state](int) {
      if (state->interrupted.exchange(true)) return;
      std::string job_id;
      {
        absl::MutexLock lock(&state->mu);
        job_id = state->job_id;
      }
      if (state->client != nullptr) {
        if (!job_id.empty()) (void)state->client->Cancel(job_id, "interrupted");
        state->client->CancelWatch();
      }
    });
    absl::Status s = Run(*flags, *state);
    StopAll(*state);
    bool submitted;
    {
      absl::MutexLock lock(&state->mu);
      submitted = !state->job_id.empty();
    }
    if (!s.ok() && submitted && flags->storage_root.empty()) {
      // The coordinator removes a failed job's tiles; a worker stopped mid-chunk may still
      // have written one after that. No partial tiles dir may look like a result.
      std::error_code ec;
      fs::remove_all(fs::absolute(flags->output_dir) / "tiles", ec);
    }
    exit_code = ReportStatus("run", s);
  });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(55, RegisterRun);

}  // namespace carvemap
