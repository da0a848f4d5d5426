// `carvemap coordinator`, `carvemap worker` and `carvemap merger`: the servers of docs/DESIGN.md §8
// on their own. Thin shells: flags ➜ Spec ➜ Start ➜ Wait (services/rpc/).
#include <malloc.h>
#include <sys/resource.h>

#include <atomic>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <type_traits>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "absl/functional/function_ref.h"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/cli/commands.h"
#include "services/cli/security_flags.h"
#include "services/rpc/bearer_tokens.h"
#include "services/rpc/coordinator_service.h"
#include "services/rpc/merge_client.h"
#include "services/rpc/merge_service.h"
#include "services/rpc/process_util.h"
#include "services/rpc/server_log.h"
#include "services/rpc/worker_service.h"
#include "services/system/process_memory.h"

namespace carvemap {
namespace {

// Written through a temporary name and a rename: whoever polls for the file (`carvemap run`)
// never reads half a line.
absl::Status WritePortFile(const std::string& path, const std::string& address) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    out << address << "\n";
    if (!out.good()) return absl::InternalError(absl::StrCat("cannot write ", tmp));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return absl::InternalError(absl::StrCat("rename to ", path, ": ", ec.message()));
  return absl::OkStatus();
}

std::string HostOf(const std::string& listen) {
  const std::string host = listen.substr(0, listen.rfind(':'));
  return host.empty() || host == "0.0.0.0" || host == "[::]" ? "127.0.0.1" : host;
}

// --log-format text|json (services/rpc/server_log.h); CARVEMAP_LOG_FORMAT sets it for every
// server of a `carvemap run` too.
void AddLogFlags(CLI::App* cmd, std::string& format, bool& verbose) {
  cmd->add_option("--log-format", format,
                  "text: '[time] [level] message' lines; json: one JSON object per line with "
                  "time, level, component, message and job/chunk/lease/worker where known")
      ->check(CLI::IsMember({"text", "json"}))
      ->envname("CARVEMAP_LOG_FORMAT")
      ->capture_default_str();
  cmd->add_flag("-v,--verbose", verbose, "Debug logging");
}

LogFormat SetUpLogging(const std::string& format, const char* component, bool verbose) {
  const LogFormat f = ParseLogFormat(format).value_or(LogFormat::kText);
  SetUpServerLogging(f, component, verbose);
  return f;
}

// The end of a server: in JSON, its error is a log record too, so that every line of the log
// parses; the exit code is ReportStatus's.
int ReportServerStatus(const char* command, LogFormat format, const absl::Status& status) {
  if (format != LogFormat::kJson || status.ok()) return ReportStatus(command, status);
  spdlog::critical("{}: {}", command, std::string(status.message()));
  spdlog::default_logger()->flush();
  return StatusExitCode(status);
}

// One line at exit with what the process used (benchmarks read it: tests/bench/pipeline_bench.sh).
void LogResourceUsage(const char* who) {
  rusage u{};
  if (getrusage(RUSAGE_SELF, &u) != 0) return;
  const double cpu_s = double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
                       1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
  spdlog::info("{}: resources: peak_rss_mib={:.1f} cpu_s={:.2f}", who, u.ru_maxrss / 1024.0,
               cpu_s);
}

// Runs a server of services/rpc/ (CoordinatorServer, WorkerServer, MergeServer) until SIGINT
// or SIGTERM, or until it ends by itself (a worker whose coordinator is gone). The signal
// handler comes first, before any thread exists (gRPC starts threads: process_util.h); then
// `start()` makes the server and `serving(server)` tells where it listens. A signal that
// arrives before the server exists stops it as soon as it does. Returns the first error, else
// what the server's Wait() returns (OK where Wait() returns nothing).
template <typename Server>
absl::Status ServeUntilSignal(const char* who,
                              absl::FunctionRef<absl::StatusOr<std::unique_ptr<Server>>()> start,
                              absl::FunctionRef<absl::Status(Server&)> serving) {
  auto stop = std::make_shared<std::atomic<Server*>>(nullptr);
  auto stop_requested = std::make_shared<std::atomic<bool>>(false);
  HandleTerminationSignals([who, stop, stop_requested](int signo) {
    spdlog::info("{}: signal {}, shutting down", who, signo);
    stop_requested->store(true);
    if (Server* s = stop->load()) s->Shutdown();
  });
  absl::StatusOr<std::unique_ptr<Server>> server = start();
  if (!server.ok()) return server.status();
  if (absl::Status s = serving(**server); !s.ok()) return s;
  stop->store(server->get());
  if (stop_requested->load()) (*server)->Shutdown();
  absl::Status ended = absl::OkStatus();
  if constexpr (std::is_void_v<decltype((*server)->Wait())>) {
    (*server)->Wait();
  } else {
    ended = (*server)->Wait();
  }
  (*server)->Shutdown();  // waits for a Shutdown still running on the signal thread
  stop->store(nullptr);
  LogResourceUsage(who);
  return ended;
}

// "listening on HOST:PORT" on stdout (text logs only: in JSON the logged "listening on" line
// says it) and in the port file, if any.
absl::Status AnnounceAddress(const std::string& listen_address, int port, LogFormat log_format,
                             const std::string& port_file) {
  const std::string address = absl::StrCat(HostOf(listen_address), ":", port);
  if (log_format == LogFormat::kText) {
    std::printf("listening on %s\n", address.c_str());
    std::fflush(stdout);
  }
  if (!port_file.empty()) return WritePortFile(port_file, address);
  return absl::OkStatus();
}

// The cluster secret from its file, or else from the CARVEMAP_CLUSTER_SECRET variable (the
// coordinator, the merge services and the workers read it alike); "" if neither is given.
absl::StatusOr<std::string> LoadClusterSecret(const std::string& secret_file) {
  if (!secret_file.empty()) return ReadSecretFile(secret_file, "cluster secret file");
  if (const char* env = std::getenv("CARVEMAP_CLUSTER_SECRET"); env && *env) {
    if (absl::Status s = ValidateSecret(env, "CARVEMAP_CLUSTER_SECRET"); !s.ok()) return s;
    return std::string(env);
  }
  return std::string();
}

struct CoordinatorFlags {
  CoordinatorSpec spec;
  std::string port_file;
  std::string tokens_file;
  std::string secret_file;
  bool no_merge = false;
  double upload_quota_gb = 100;
  // The merge services (`carvemap merger`) and how to reach them; the bearer is the
  // coordinator's own cluster secret.
  MergeClientSpec merge;
  std::string log_format = "text";
  bool verbose = false;
};

// Tokens and the cluster secret from their files, or else from the variables holding them
// (CARVEMAP_TOKENS: the tokens file's text; CARVEMAP_CLUSTER_SECRET: the secret).
absl::Status LoadSecrets(CoordinatorFlags& flags) {
  if (!flags.tokens_file.empty()) {
    absl::StatusOr<std::vector<TenantToken>> tokens = ReadTokensFile(flags.tokens_file);
    if (!tokens.ok()) return tokens.status();
    flags.spec.tokens = *std::move(tokens);
  } else if (const char* env = std::getenv("CARVEMAP_TOKENS"); env && *env) {
    absl::StatusOr<std::vector<TenantToken>> tokens = ParseTokens(env, "CARVEMAP_TOKENS");
    if (!tokens.ok()) return tokens.status();
    flags.spec.tokens = *std::move(tokens);
  }
  absl::StatusOr<std::string> secret = LoadClusterSecret(flags.secret_file);
  if (!secret.ok()) return secret.status();
  flags.spec.cluster_secret = *std::move(secret);
  return absl::OkStatus();
}

absl::Status RunCoordinator(CoordinatorFlags flags, LogFormat log_format) {
  if (absl::Status s = LoadSecrets(flags); !s.ok()) return s;
  if (!(flags.upload_quota_gb >= 0) || flags.upload_quota_gb > 1e9) {
    return absl::InvalidArgumentError(absl::StrCat("--upload-quota-gb ", flags.upload_quota_gb,
                                                   ": must be 0 (no limit) or more"));
  }
  flags.spec.upload_quota_bytes = static_cast<int64_t>(flags.upload_quota_gb * (1 << 30));
  // Each job's thread and gRPC's handler threads get a glibc malloc arena of their own (up to
  // eight per core), and an arena keeps what it once held: over 60 small jobs in a row the
  // coordinator's RSS grew 5.1 MiB after its first ten with the default, 1.3 MiB with two
  // arenas (docs/BENCHMARKS.md, "What a coordinator keeps per job"). It allocates little.
  mallopt(M_ARENA_MAX, 2);
  return ServeUntilSignal<CoordinatorServer>(
      "coordinator",
      [&]() -> absl::StatusOr<std::unique_ptr<CoordinatorServer>> {
        // The server's own rules first (an open service off loopback, bad TLS files): their
        // messages say more than a missing merge service.
        if (absl::Status s = flags.spec.Validate(); !s.ok()) return s;
        if (flags.no_merge) {
          if (!flags.merge.addresses.empty()) {
            return absl::InvalidArgumentError("--no-merge and --merge-server exclude each other");
          }
        } else {
          if (flags.merge.addresses.empty()) {
            return absl::InvalidArgumentError(
                "no merge service: give --merge-server HOST:PORT (a `carvemap merger`; "
                "docs/DESIGN.md §8 runs the merge as its own service), or --no-merge for tiles "
                "only");
          }
          flags.merge.security.bearer = flags.spec.cluster_secret;
          absl::StatusOr<MergeFunction> merge = RemoteMerge(flags.merge);
          if (!merge.ok()) return merge.status();
          flags.spec.merge = *std::move(merge);
          flags.spec.merge_in_process = false;
        }
        return CoordinatorServer::Start(flags.spec);
      },
      [&](CoordinatorServer& server) {
        return AnnounceAddress(flags.spec.listen_address, server.port(), log_format,
                               flags.port_file);
      });
}

void RegisterCoordinator(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "coordinator",
      "Run the coordinator server: job service and carve-task service (gRPC); jobs are "
      "merged by the merge service of --merge-server. On a non-loopback address it needs "
      "--tokens (tenants' bearer tokens) and --cluster-secret-file or --tls-client-ca "
      "(workers), or --insecure");
  auto flags = std::make_shared<CoordinatorFlags>();
  flags->spec.listen_address = "127.0.0.1:7600";
  CoordinatorSpec& s = flags->spec;
  cmd->add_option("--listen", s.listen_address, "host:port to serve on (port 0: any free port)")
      ->capture_default_str();
  cmd->add_option("--port-file", flags->port_file,
                  "Write the bound host:port to this file once serving");
  cmd->add_option("--data-root", s.data_root, "Input scan paths are relative to this directory")
      ->capture_default_str();
  cmd->add_option("--output-root", s.output_root, "Outputs go to <output-root>/<output_name>/")
      ->capture_default_str();
  cmd->add_option("--storage-root", s.storage_root,
                  "Tiles go to <storage-root>/<job>/tiles (default: <output>/tiles)");
  cmd->add_option("--work-dir", s.work_dir,
                  "Job store and partial sums (default: <storage-root or output-root>/.carvemap)");
  cmd->add_option("--heartbeat-interval-s", s.heartbeat_interval_s, "Worker heartbeat interval")
      ->capture_default_str();
  cmd->add_option("--worker-timeout-s", s.worker_timeout_s,
                  "A worker without heartbeat for this long is lost; its chunks are requeued")
      ->capture_default_str();
  cmd->add_option("--lease-timeout-s", s.lease_timeout_s, "Lease deadline without heartbeat")
      ->capture_default_str();
  cmd->add_option("--max-attempts", s.max_attempts, "Leases per chunk before the job fails")
      ->capture_default_str();
  cmd->add_flag("--keep-partials", s.keep_partials,
                "Keep the slices' partial sums (<work dir>/<job>/partials); by default each "
                "pass's are removed once all its chunks are combined");
  // The merge service (docs/DESIGN.md §8; docs/RPC.md "MergeService").
  MergeClientSpec& m = flags->merge;
  cmd->add_option("--merge-server", m.addresses,
                  "host:port of a merge service (`carvemap merger`); repeat or separate with "
                  "commas for several: a merge whose service is lost runs again on the next")
      ->delimiter(',')
      ->envname("CARVEMAP_MERGE_SERVER");
  cmd->add_option("--merge-attempts", m.attempts,
                  "Merge services lost (or unreachable) this many times in one job's merge: "
                  "the job fails")
      ->capture_default_str();
  cmd->add_option("--merge-connect-timeout-s", m.connect_timeout_s,
                  "How long one merge attempt waits for its service to accept a connection")
      ->capture_default_str();
  cmd->add_option("--merge-tls-ca", m.security.ca_file,
                  "Reach the merge services over TLS, trusting the CA certificate(s) in this "
                  "PEM file");
  cmd->add_option("--merge-tls-server-name", m.security.server_name,
                  "Name the merge service's certificate must carry, when it is not the "
                  "--merge-server host");
  cmd->add_option("--merge-tls-cert", m.security.cert_file,
                  "Client certificate (PEM) for mutual TLS with the merge services");
  cmd->add_option("--merge-tls-key", m.security.key_file, "Private key (PEM) of --merge-tls-cert");
  cmd->add_flag("--no-merge", flags->no_merge, "Skip the merge step (tiles only)");
  // Security (docs/RPC.md "Authentication", docs/CLUSTER.md).
  cmd->add_option("--tokens", flags->tokens_file,
                  "Bearer tokens of the job API: lines 'TOKEN TENANT' or JSON {\"tokens\": "
                  "[{\"token\", \"tenant\"}]}; else the CARVEMAP_TOKENS variable (same text). "
                  "Without tokens the job API is open (every caller is tenant 'default'): "
                  "allowed on a loopback address, elsewhere only with --insecure")
      ->envname("CARVEMAP_TOKENS_FILE");
  cmd->add_option("--cluster-secret-file", flags->secret_file,
                  "Secret that workers must present on the carve-task API (else the "
                  "CARVEMAP_CLUSTER_SECRET variable), and that the coordinator presents to the "
                  "merge services; required off loopback unless --tls-client-ca or --insecure")
      ->envname("CARVEMAP_CLUSTER_SECRET_FILE");
  cmd->add_option("--tls-cert", s.tls_cert_file, "Serve TLS with this PEM certificate chain")
      ->envname("CARVEMAP_TLS_CERT");
  cmd->add_option("--tls-key", s.tls_key_file, "PEM private key of --tls-cert")
      ->envname("CARVEMAP_TLS_KEY");
  cmd->add_option("--tls-client-ca", s.tls_client_ca_file,
                  "Mutual TLS: a client certificate signed by this CA authenticates a worker "
                  "(as the cluster secret does)");
  cmd->add_flag("--insecure", s.insecure,
                "Allow serving a non-loopback address without --tokens, or with an open "
                "carve-task API (anyone reaching the port can submit, fetch every output or "
                "act as a worker)");
  cmd->add_flag("--shared-dirs", s.shared_dirs,
                "All tenants share the data and output roots (only with a single tenant); "
                "default: each tenant's inputs in <data-root>/<tenant>/, outputs in "
                "<output-root>/<tenant>/");
  s.max_jobs_per_tenant = 16;
  cmd->add_option("--max-jobs-per-tenant", s.max_jobs_per_tenant,
                  "Unfinished jobs a tenant may have; one more is refused (RESOURCE_EXHAUSTED). "
                  "0: no limit")
      ->capture_default_str();
  cmd->add_option("--upload-quota-gb", flags->upload_quota_gb,
                  "GiB a tenant may hold in streamed uploads (`carvemap upload`, `submit "
                  "--upload`): its uploads/ folder and unfinished uploads. 0: no limit")
      ->capture_default_str();
  cmd->add_option("--max-request-bytes", s.max_request_bytes,
                  "Largest request message accepted (larger: RESOURCE_EXHAUSTED)")
      ->capture_default_str();
  cmd->add_option("--metrics-listen", s.metrics_listen_address,
                  "Serve Prometheus metrics over HTTP at http://HOST:PORT/metrics (chunks, "
                  "workers, rays/s, lease expiries, RPC latencies; no job ids or tenants)");
  cmd->add_option("--health-listen", s.health_listen_address,
                  "Also serve grpc.health.v1 alone, in plaintext, on this host:port (for "
                  "Kubernetes probes, which cannot speak TLS)");
  AddLogFlags(cmd, flags->log_format, flags->verbose);
  cmd->callback([flags, &exit_code] {
    const LogFormat format = SetUpLogging(flags->log_format, "coordinator", flags->verbose);
    exit_code = ReportServerStatus("coordinator", format, RunCoordinator(*flags, format));
  });
}

struct WorkerFlags {
  WorkerSpec spec;
  size_t slice_memory_mb = 256;
  SecurityFlags security;
  std::string log_format = "text";
  bool verbose = false;
};

absl::Status RunWorker(WorkerFlags flags) {
  absl::StatusOr<ChannelSecurity> security = ResolveSecurity(flags.security, /*worker=*/true);
  if (!security.ok()) return security.status();
  flags.spec.security = *std::move(security);
  return ServeUntilSignal<WorkerServer>(
      "worker", [&] {
        flags.spec.slice_memory_bytes = flags.slice_memory_mb << 20;
        return WorkerServer::Start(flags.spec);
      },
      [](WorkerServer&) { return absl::OkStatus(); });
}

void RegisterWorker(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "worker", "Run a carve worker: leases chunks from a coordinator and writes their tiles");
  auto flags = std::make_shared<WorkerFlags>();
  WorkerSpec& s = flags->spec;
  cmd->add_option("--coordinator,--server", s.coordinator_address,
                  "host:port of the coordinator")
      ->required();
  cmd->add_option("--listen", s.listen_address,
                  "host:port for the health endpoint (port 0: any; empty: none)")
      ->capture_default_str();
  cmd->add_option("--threads", s.threads, "Tasks (slices, chunks) run in parallel")
      ->capture_default_str();
  cmd->add_option("--metrics-listen", s.metrics_listen_address,
                  "Serve Prometheus metrics over HTTP at http://HOST:PORT/metrics (rays "
                  "carved, tasks and their seconds, memory, bytes read and written)");
  cmd->add_option("--slice-memory-mb", flags->slice_memory_mb,
                  "Memory for a slice's chunk sums before they are written out, MB per thread")
      ->check(CLI::Range(16, 1 << 16))
      ->capture_default_str();
  cmd->add_option("--coordinator-lost-s", s.coordinator_lost_s,
                  "Exit when the coordinator has been unreachable this long")
      ->capture_default_str();
  AddSecurityFlags(cmd, flags->security, /*worker=*/true);
  AddLogFlags(cmd, flags->log_format, flags->verbose);
  cmd->callback([flags, &exit_code] {
    const LogFormat format = SetUpLogging(flags->log_format, "worker", flags->verbose);
    exit_code = ReportServerStatus("worker", format, RunWorker(*flags));
  });
}

struct MergerFlags {
  MergeServerSpec spec;
  double memory_mb = 0;  // MemoryBudgetBytes
  std::string port_file;
  std::string secret_file;
  std::string log_format = "text";
  bool verbose = false;
};

absl::Status RunMerger(MergerFlags flags, LogFormat log_format) {
  // The cluster secret the coordinator presents.
  absl::StatusOr<std::string> secret = LoadClusterSecret(flags.secret_file);
  if (!secret.ok()) return secret.status();
  flags.spec.cluster_secret = *std::move(secret);
  flags.spec.memory_budget_bytes = MemoryBudgetBytes(flags.memory_mb);
  // The merge's stages run one after another: what one frees goes back to the system.
  MapLargeBuffersAlone();
  if (flags.spec.memory_budget_bytes > 0) {
    spdlog::info("merger: memory budget {:.0f} MiB",
                 double(flags.spec.memory_budget_bytes) / (1 << 20));
  }
  return ServeUntilSignal<MergeServer>(
      "merger", [&] { return MergeServer::Start(flags.spec); },
      [&](MergeServer& server) {
        return AnnounceAddress(flags.spec.listen_address, server.port(), log_format,
                               flags.port_file);
      });
}

void RegisterMerger(CLI::App& app, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "merger",
      "Run a merge service (gRPC): merges the jobs a coordinator hands it (--merge-server), "
      "reading tiles and writing outputs on the storage it shares with the coordinator, at the "
      "same paths. On a non-loopback address it needs --cluster-secret-file or "
      "--tls-client-ca, or --insecure");
  auto flags = std::make_shared<MergerFlags>();
  MergeServerSpec& s = flags->spec;
  s.listen_address = "127.0.0.1:7610";
  cmd->add_option("--listen", s.listen_address, "host:port to serve on (port 0: any free port)")
      ->capture_default_str();
  cmd->add_option("--port-file", flags->port_file,
                  "Write the bound host:port to this file once serving");
  cmd->add_option("--cluster-secret-file", flags->secret_file,
                  "Secret the coordinator must present (the cluster secret; else the "
                  "CARVEMAP_CLUSTER_SECRET variable); required off loopback unless "
                  "--tls-client-ca or --insecure")
      ->envname("CARVEMAP_CLUSTER_SECRET_FILE");
  cmd->add_option("--tls-cert", s.tls_cert_file, "Serve TLS with this PEM certificate chain")
      ->envname("CARVEMAP_TLS_CERT");
  cmd->add_option("--tls-key", s.tls_key_file, "PEM private key of --tls-cert")
      ->envname("CARVEMAP_TLS_KEY");
  cmd->add_option("--tls-client-ca", s.tls_client_ca_file,
                  "Mutual TLS: a client certificate signed by this CA authenticates the "
                  "coordinator (as the cluster secret does)");
  cmd->add_flag("--insecure", s.insecure,
                "Allow serving a non-loopback address without the cluster secret or mutual TLS "
                "(anyone reaching the port could have the merge read and write any path it can)");
  cmd->add_option("--max-request-bytes", s.max_request_bytes,
                  "Largest message accepted from the coordinator")
      ->capture_default_str();
  cmd->add_option("--health-listen", s.health_listen_address,
                  "Also serve grpc.health.v1 alone, in plaintext, on this host:port (for "
                  "Kubernetes probes, which cannot speak TLS)");
  cmd->add_option("--metrics-listen", s.metrics_listen_address,
                  "Serve Prometheus metrics over HTTP at http://HOST:PORT/metrics (merges "
                  "running and queued, seconds per stage, peak memory; no job ids or tenants)");
  cmd->add_option("--memory-mb", flags->memory_mb, kMergeMemoryBudgetHelp)
      ->capture_default_str();
  AddLogFlags(cmd, flags->log_format, flags->verbose);
  cmd->callback([flags, &exit_code] {
    const LogFormat format = SetUpLogging(flags->log_format, "merger", flags->verbose);
    exit_code = ReportServerStatus("merger", format, RunMerger(*flags, format));
  });
}

}  // namespace

CARVEMAP_REGISTER_COMMAND(60, RegisterCoordinator);
CARVEMAP_REGISTER_COMMAND(61, RegisterWorker);
CARVEMAP_REGISTER_COMMAND(62, RegisterMerger);

}  // namespace carvemap
