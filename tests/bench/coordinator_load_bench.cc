// The coordinator's own capacity: a real CoordinatorServer (its own process, with its SQLite job
// store) on loopback, a real job on a real scan, and W simulated workers that speak the carve-task
// protocol as services/rpc/worker_service.cc does but do no carving:
//   coordinator_load_bench [workers = 8,64,512] [chunks = 814] [walk seconds = 0: whole walk]
// 1. simulates the `office` preset at 3 Hz, 2° beams (seed 1) for the job's scan;
// 2. per worker count W, starts this program again as the coordinator (`--serve`, so its CPU
//    and I/O are its own in /proc), registers W workers (each on its own connection), then
//    measures three phases:
//    - heartbeats: every worker sends Heartbeat back to back for 3 s (capacity, not the 1 per
//      5 s a real worker sends);
//    - idle: every worker long-polls LeaseChunk with no job, as a real worker does between jobs
//      (wait 1 s, then retry_after_s);
//    - the job: SubmitJob, and the workers lease, "carve" and complete until it SUCCEEDED, each
//      heartbeating every 5 s (the default interval). A slice's lease is answered with a valid
//      partial-sums file (storage/partial_sums.h) naming `chunks` chunks with one leaf each,
//      because the coordinator reads those files to list the chunks to combine; a combine's lease
//      is completed at once with a made-up tile (the coordinator never opens tiles).
//    It prints leases/s and completes/s, the coordinator's CPU seconds per task (lease +
//    complete, from /proc/<pid>/stat), its bytes written to disk (/proc/<pid>/io: the job
//    store's WAL), its threads, client-side latencies, the server-side handler times from its
//    /metrics, and the payload bytes of each message (protobuf, without gRPC framing);
// 3. times the job store alone (storage/job_store.h UpdateChunks, the write behind every lease
//    and every completion) against the number of tasks in the job.
// The simulated workers share the machine's cores with the coordinator: the rates are what the
// coordinator sustained on what the workers left it (their CPU is printed too).
#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "proto/carvemap/v1/jobs.grpc.pb.h"
#include "services/rpc/coordinator_service.h"
#include "services/rpc/http_get.h"
#include "services/sim/simulator.h"
#include "spdlog/spdlog.h"
#include "storage/job_store.h"
#include "storage/partial_sums.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;
using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

int Fail(const std::string& what) {
  std::fprintf(stderr, "coordinator_load_bench: %s\n", what.c_str());
  return 1;
}

// ---- the coordinator's side: `--serve DIR DATA_ROOT`

// Serves until stdin closes (the parent's end of the pipe), so an abandoned child does not
// outlive the bench.
int Serve(const std::string& dir, const std::string& data_root) {
  spdlog::set_level(spdlog::level::info);  // what `carvemap coordinator` logs by default
  CoordinatorSpec spec;
  spec.data_root = data_root;
  spec.output_root = dir + "/out";
  spec.work_dir = dir + "/work";
  spec.metrics_listen_address = "127.0.0.1:0";
  // No merge: the job goes from CARVING to SUCCEEDED with its tiles only.
  absl::StatusOr<std::unique_ptr<CoordinatorServer>> server = CoordinatorServer::Start(spec);
  if (!server.ok()) return Fail(server.status().ToString());
  {
    std::ofstream out(dir + "/port.tmp");
    out << (*server)->port() << " " << (*server)->metrics_port() << "\n";
  }
  fs::rename(dir + "/port.tmp", dir + "/port");
  char c;
  while (read(0, &c, 1) > 0) {
  }
  (*server)->Shutdown();
  return 0;
}

// ---- the bench's side

struct ProcSample {
  double cpu_s = 0;         // utime + stime
  int64_t write_bytes = 0;  // to the block layer (the job store's WAL and partial files)
  int threads = 0;
};

ProcSample SampleProc(pid_t pid) {
  ProcSample s;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
  // Fields after the command name, which may hold spaces: (14) utime, (15) stime, (20) threads.
  const size_t close = text.rfind(')');
  if (close != std::string::npos) {
    std::vector<std::string> f = absl::StrSplit(text.substr(close + 2), ' ');
    const double tick = double(sysconf(_SC_CLK_TCK));
    if (f.size() > 17) {
      s.cpu_s = (std::atof(f[11].c_str()) + std::atof(f[12].c_str())) / tick;
      s.threads = std::atoi(f[17].c_str());
    }
  }
  std::ifstream io("/proc/" + std::to_string(pid) + "/io");
  std::string key;
  int64_t value;
  while (io >> key >> value) {
    if (key == "write_bytes:") s.write_bytes = value;
  }
  return s;
}

double SelfCpuS() {
  rusage u;
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Latencies of one kind of call, gathered from every worker thread.
struct Latencies {
  std::mutex mu;
  std::vector<double> ms;
  void Add(std::vector<double>& local) {
    std::lock_guard<std::mutex> lock(mu);
    ms.insert(ms.end(), local.begin(), local.end());
    local.clear();
  }
  [[nodiscard]] std::string Text() {
    std::lock_guard<std::mutex> lock(mu);
    if (ms.empty()) return "-";
    std::sort(ms.begin(), ms.end());
    auto q = [&](double p) { return ms[std::min(ms.size() - 1, size_t(p * double(ms.size())))]; };
    char buf[96];
    std::snprintf(buf, sizeof buf, "p50 %.2f / p99 %.2f / max %.1f ms (%zu)", q(0.5), q(0.99),
                  ms.back(), ms.size());
    return buf;
  }
};

// Largest payload of each message kind seen (bytes of the protobuf encoding).
struct Sizes {
  std::atomic<size_t> lease_req{0}, slice_lease{0}, combine_lease{0}, empty_lease{0};
  std::atomic<size_t> complete_req{0}, complete_resp{0}, heartbeat_req{0}, heartbeat_resp{0};
  static void Max(std::atomic<size_t>& a, size_t v) {
    size_t cur = a.load();
    while (v > cur && !a.compare_exchange_weak(cur, v)) {
    }
  }
};

struct RunResult {
  int workers = 0;
  double register_s = 0;
  double heartbeats_per_s = 0, cpu_per_heartbeat_ms = 0;
  double idle_polls_per_s = 0, idle_cpu_per_s = 0;
  int slices = 0, combines = 0;
  double job_s = 0, slice_phase_s = 0, combine_phase_s = 0;
  double combine_leases_per_s = 0;
  double cpu_per_task_ms = 0, job_cpu_s = 0, bench_cpu_s = 0;
  double write_bytes_per_task = 0;
  int64_t empty_polls = 0, heartbeats = 0, lease_deadlines = 0;
  int max_threads = 0;
};

class LoadRun {
 public:
  LoadRun(std::string dir, std::string data_root, int workers, int chunks)
      : dir_(std::move(dir)), data_root_(std::move(data_root)), chunks_(chunks) {
    result_.workers = workers;
  }
  ~LoadRun() { StopChild(); }

  absl::Status Run();
  [[nodiscard]] const RunResult& result() const { return result_; }
  Latencies lease_lat, complete_lat, heartbeat_lat;
  Sizes sizes;
  std::string server_times;  // from /metrics

 private:
  absl::Status StartChild();
  void StopChild();
  void Worker(int index);
  // The slice's partial sums: `chunks_` chunks, one leaf each.
  absl::Status WriteSlice(const pb::Lease& lease, pb::TileInfo& tile);

  enum class Phase { kHeartbeats, kIdle, kJob, kStop };

  std::string dir_, data_root_;
  int chunks_;
  RunResult result_;
  pid_t child_ = -1;
  int child_stdin_ = -1;
  std::string address_, metrics_address_;
  std::vector<std::string> worker_ids_;
  std::atomic<Phase> phase_{Phase::kHeartbeats};
  std::atomic<int64_t> heartbeats_{0}, polls_{0}, empty_polls_{0}, lease_deadlines_{0};
  std::atomic<int> slices_done_{0}, combines_done_{0};
  std::mutex times_mu_;
  Clock::time_point first_combine_lease_ = Clock::time_point::max();
  Clock::time_point last_slice_done_{}, last_combine_done_{};
};

absl::Status LoadRun::StartChild() {
  fs::remove_all(dir_);
  fs::create_directories(dir_);
  int in[2];
  if (pipe(in) != 0) return absl::InternalError("pipe");
  // Built before the fork: the child only calls what is safe between fork and exec.
  const std::string log_path = dir_ + "/coordinator.log";
  child_ = fork();
  if (child_ < 0) return absl::InternalError("fork");
  if (child_ == 0) {
    dup2(in[0], 0);
    close(in[1]);
    const int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(log, 1);
    dup2(log, 2);
    execl("/proc/self/exe", "coordinator_load_bench", "--serve", dir_.c_str(), data_root_.c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  close(in[0]);
  child_stdin_ = in[1];
  for (int i = 0; i < 300 && !fs::exists(dir_ + "/port"); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::ifstream port(dir_ + "/port");
  int p = 0, mp = 0;
  if (!(port >> p >> mp)) return absl::UnavailableError("the coordinator did not start: " + dir_);
  address_ = "127.0.0.1:" + std::to_string(p);
  metrics_address_ = "127.0.0.1:" + std::to_string(mp);
  return absl::OkStatus();
}

void LoadRun::StopChild() {
  if (child_ <= 0) return;
  close(child_stdin_);
  int status = 0;
  for (int i = 0; i < 100; ++i) {
    if (waitpid(child_, &status, WNOHANG) == child_) {
      child_ = -1;
      return;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  kill(child_, SIGKILL);
  waitpid(child_, &status, 0);
  child_ = -1;
}

absl::Status LoadRun::WriteSlice(const pb::Lease& lease, pb::TileInfo& tile) {
  const pb::SliceTask& task = lease.slice();
  const int depth = lease.params().leaf_depth();
  fs::create_directories(fs::path(task.partial_path()).parent_path());
  absl::StatusOr<std::unique_ptr<PartialSumsWriter>> w =
      PartialSumsWriter::Create(task.partial_path(), depth, task.index());
  if (!w.ok()) return w.status();
  TileLeaf leaf;
  leaf.node.depth = depth;
  leaf.stats.count = 1;
  leaf.stats.sum_w = 1;
  // Chunks on a 2-D grid, as a building's floors lie.
  const int side = std::max(1, int(std::ceil(std::sqrt(double(chunks_)))));
  for (int k = 0; k < chunks_; ++k) {
    const ChunkKey key(k % side, k / side, 0);
    if (absl::Status s = (*w)->AddSection(key, 1, {&leaf, 1}); !s.ok()) return s;
  }
  absl::StatusOr<uint64_t> size = (*w)->Finish();
  if (!size.ok()) return size.status();
  tile.set_path(fs::path(task.partial_path()).filename().string());
  tile.set_size_bytes(int64_t(*size));
  tile.set_sha256_hex(std::string(64, '0'));  // the coordinator stores it, never checks it
  return absl::OkStatus();
}

void LoadRun::Worker(int index) {
  // Its own connection, as a worker on its own machine has (distinct channel arguments keep
  // gRPC from sharing one subchannel between the stubs).
  grpc::ChannelArguments args;
  args.SetInt("carvemap.bench.worker", index);
  auto channel = grpc::CreateCustomChannel(address_, grpc::InsecureChannelCredentials(), args);
  auto stub = pb::CarveTaskService::NewStub(channel);
  const std::string& id = worker_ids_[index];
  std::vector<double> lease_ms, complete_ms, heartbeat_ms;
  auto heartbeat = [&] {
    pb::HeartbeatRequest req;
    req.set_worker_id(id);
    pb::HeartbeatResponse resp;
    grpc::ClientContext ctx;
    const auto t = Clock::now();
    grpc::Status s = stub->Heartbeat(&ctx, req, &resp);
    heartbeat_ms.push_back(1e3 * Since(t));
    if (s.ok()) ++heartbeats_;
    Sizes::Max(sizes.heartbeat_req, req.ByteSizeLong());
    Sizes::Max(sizes.heartbeat_resp, resp.ByteSizeLong());
  };
  while (phase_ == Phase::kHeartbeats) heartbeat();
  heartbeat_ms.clear();  // the storm's latencies are not the job's
  auto last_heartbeat = Clock::now();
  while (phase_ != Phase::kStop) {
    // Every heartbeat_interval_s (5 s by default), as the real worker's heartbeat thread does.
    if (Since(last_heartbeat) >= 5.0) {
      heartbeat();
      last_heartbeat = Clock::now();
    }
    pb::LeaseChunkRequest req;
    req.set_worker_id(id);
    req.set_wait_s(1.0);  // what worker_service.cc asks
    pb::LeaseChunkResponse resp;
    grpc::ClientContext ctx;
    // worker_service.cc's deadline for a lease call (its RPC timeout + 2 s).
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(12));
    const auto t = Clock::now();
    grpc::Status s = stub->LeaseChunk(&ctx, req, &resp);
    ++polls_;
    Sizes::Max(sizes.lease_req, req.ByteSizeLong());
    if (!s.ok()) {
      // A deadline here may leave a lease granted that no worker holds (see the report).
      if (s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) ++lease_deadlines_;
      std::fprintf(stderr, "worker %d: lease: %s\n", index, s.error_message().c_str());
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      continue;
    }
    if (!resp.has_lease()) {
      ++empty_polls_;
      Sizes::Max(sizes.empty_lease, resp.ByteSizeLong());
      std::this_thread::sleep_for(std::chrono::duration<double>(resp.retry_after_s()));
      continue;
    }
    lease_ms.push_back(1e3 * Since(t));
    const pb::Lease& lease = resp.lease();
    pb::CompleteChunkRequest done;
    done.set_worker_id(id);
    done.set_lease_id(lease.lease_id());
    done.set_generation(lease.generation());
    if (lease.has_slice()) {
      Sizes::Max(sizes.slice_lease, resp.ByteSizeLong());
      if (absl::Status w = WriteSlice(lease, *done.mutable_tile()); !w.ok()) {
        std::fprintf(stderr, "worker %d: %s\n", index, w.ToString().c_str());
        continue;
      }
      done.mutable_stats()->set_rays(lease.slice().own_rays());
      done.mutable_stats()->set_partial_bytes(done.tile().size_bytes());
    } else {
      Sizes::Max(sizes.combine_lease, resp.ByteSizeLong());
      std::lock_guard<std::mutex> lock(times_mu_);
      first_combine_lease_ = std::min(first_combine_lease_, Clock::now());
      done.mutable_tile()->set_path("c_" + std::to_string(lease.chunk().x()) + "_" +
                                    std::to_string(lease.chunk().y()) + "_" +
                                    std::to_string(lease.chunk().z()) + ".h5");
      done.mutable_tile()->set_size_bytes(190'000);  // office2's mean tile
      done.mutable_tile()->set_sha256_hex(std::string(64, '0'));
      done.mutable_stats()->set_leaves(20'000);
    }
    pb::CompleteChunkResponse done_resp;
    grpc::ClientContext done_ctx;
    const auto t2 = Clock::now();
    s = stub->CompleteChunk(&done_ctx, done, &done_resp);
    complete_ms.push_back(1e3 * Since(t2));
    Sizes::Max(sizes.complete_req, done.ByteSizeLong());
    Sizes::Max(sizes.complete_resp, done_resp.ByteSizeLong());
    if (!s.ok()) {
      std::fprintf(stderr, "worker %d: complete: %s\n", index, s.error_message().c_str());
      continue;
    }
    std::lock_guard<std::mutex> lock(times_mu_);
    if (lease.has_slice()) {
      ++slices_done_;
      last_slice_done_ = Clock::now();
    } else {
      ++combines_done_;
      last_combine_done_ = Clock::now();
    }
  }
  lease_lat.Add(lease_ms);
  complete_lat.Add(complete_ms);
  heartbeat_lat.Add(heartbeat_ms);
}

// Mean server-side handler time of `method` from the coordinator's histogram (all codes).
std::string ServerMeanMs(const std::string& metrics, const std::string& method) {
  double sum = 0, count = 0;
  std::istringstream in(metrics);
  std::string line;
  const std::string tag = "method=\"" + method + "\"";
  while (std::getline(in, line)) {
    if (line.find(tag) == std::string::npos) continue;
    const size_t space = line.rfind(' ');
    double v = 0;
    if (space == std::string::npos || !absl::SimpleAtod(line.substr(space + 1), &v)) continue;
    if (line.rfind("carvemap_rpc_duration_seconds_sum{", 0) == 0) sum += v;
    if (line.rfind("carvemap_rpc_duration_seconds_count{", 0) == 0) count += v;
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s %.3f ms (%.0f)", method.c_str(),
                count > 0 ? 1e3 * sum / count : 0.0, count);
  return buf;
}

absl::Status LoadRun::Run() {
  if (absl::Status s = StartChild(); !s.ok()) return s;
  auto channel = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  auto carve = pb::CarveTaskService::NewStub(channel);
  auto jobs = pb::JobService::NewStub(channel);
  const int w = result_.workers;
  auto t = Clock::now();
  for (int i = 0; i < w; ++i) {
    pb::RegisterWorkerRequest req;
    req.set_hostname("bench-" + std::to_string(i));
    req.set_threads(1);
    req.set_version("0.1.0");
    req.set_has_shared_storage(true);
    pb::RegisterWorkerResponse resp;
    grpc::ClientContext ctx;
    grpc::Status s = carve->RegisterWorker(&ctx, req, &resp);
    if (!s.ok()) return absl::UnavailableError("register: " + s.error_message());
    worker_ids_.push_back(resp.worker_id());
  }
  result_.register_s = Since(t);

  // The samples of the coordinator's /proc and this process's CPU, every 100 ms.
  struct Sample {
    Clock::time_point t;
    ProcSample coordinator;
    double bench_cpu_s;
  };
  std::vector<Sample> samples;
  std::mutex samples_mu;
  std::atomic<bool> sampling{true};
  std::thread sampler([&] {
    while (sampling) {
      Sample s{Clock::now(), SampleProc(child_), SelfCpuS()};
      {
        std::lock_guard<std::mutex> lock(samples_mu);
        samples.push_back(s);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });
  auto now_sample = [&] { return Sample{Clock::now(), SampleProc(child_), SelfCpuS()}; };
  // The sample nearest `at` (the samples are 100 ms apart).
  auto sample_at = [&](Clock::time_point at) {
    std::lock_guard<std::mutex> lock(samples_mu);
    Sample best = samples.front();
    for (const Sample& s : samples) {
      if (std::abs(std::chrono::duration<double>(s.t - at).count()) <
          std::abs(std::chrono::duration<double>(best.t - at).count())) {
        best = s;
      }
    }
    return best;
  };

  std::vector<std::thread> threads;
  for (int i = 0; i < w; ++i) threads.emplace_back([this, i] { Worker(i); });
  // Every return from here on stops and joins the workers and the sampler first.
  struct Joiner {
    std::function<void()> stop;
    ~Joiner() { stop(); }
  } joiner{[&] {
    phase_ = Phase::kStop;
    for (std::thread& th : threads) {
      if (th.joinable()) th.join();
    }
    sampling = false;
    if (sampler.joinable()) sampler.join();
  }};

  // Heartbeats back to back; the first half second lets every thread connect.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  Sample a = now_sample();
  int64_t h0 = heartbeats_;
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  Sample b = now_sample();
  int64_t h1 = heartbeats_;
  double span = std::chrono::duration<double>(b.t - a.t).count();
  result_.heartbeats_per_s = double(h1 - h0) / span;
  result_.cpu_per_heartbeat_ms =
      1e3 * (b.coordinator.cpu_s - a.coordinator.cpu_s) / double(h1 - h0);

  // Idle: every worker long-polls an empty queue.
  phase_ = Phase::kIdle;
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  a = now_sample();
  int64_t p0 = polls_;
  std::this_thread::sleep_for(std::chrono::milliseconds(3000));
  b = now_sample();
  int64_t p1 = polls_;
  span = std::chrono::duration<double>(b.t - a.t).count();
  result_.idle_polls_per_s = double(p1 - p0) / span;
  result_.idle_cpu_per_s = (b.coordinator.cpu_s - a.coordinator.cpu_s) / span;

  // The job, submitted as `carvemap submit` does.
  const int64_t empty0 = empty_polls_, heartbeats0 = heartbeats_;
  phase_ = Phase::kJob;
  const Sample submit = now_sample();
  pb::SubmitJobRequest req;
  req.set_input_path("sim/scan.h5");
  req.set_output_name("load-" + std::to_string(w));
  pb::SubmitJobResponse resp;
  {
    grpc::ClientContext ctx;
    grpc::Status s = jobs->SubmitJob(&ctx, req, &resp);
    if (!s.ok()) return absl::UnavailableError("submit: " + s.error_message());
  }
  pb::Job job;
  while (true) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    pb::GetJobRequest get;
    get.set_job_id(resp.job().job_id());
    grpc::ClientContext ctx;
    grpc::Status s = jobs->GetJob(&ctx, get, &job);
    if (!s.ok()) return absl::UnavailableError("get job: " + s.error_message());
    if (job.state() >= pb::JOB_STATE_SUCCEEDED) break;
    if (Since(submit.t) > 300) {
      return absl::DeadlineExceededError(
          "job " + job.job_id() +
          " not finished after 300 s: " + std::to_string(job.progress().chunks_done()) + " of " +
          std::to_string(job.progress().chunks_total()) + " tasks done, " +
          std::to_string(job.progress().chunks_leased()) + " leased; " +
          std::to_string(lease_deadlines_.load()) + " LeaseChunk calls ran out of time");
    }
  }
  const Sample end = now_sample();
  joiner.stop();
  if (job.state() != pb::JOB_STATE_SUCCEEDED) {
    return absl::InternalError("job " + job.job_id() + ": " + job.error());
  }
  if (absl::StatusOr<std::string> m = HttpGet(metrics_address_, 5); m.ok()) {
    server_times = ServerMeanMs(*m, "LeaseChunk") + ", " + ServerMeanMs(*m, "CompleteChunk") +
                   ", " + ServerMeanMs(*m, "Heartbeat");
  }

  RunResult& r = result_;
  r.slices = slices_done_;
  r.combines = combines_done_;
  r.empty_polls = empty_polls_ - empty0;
  r.heartbeats = heartbeats_ - heartbeats0;
  r.lease_deadlines = lease_deadlines_;
  r.job_s = std::chrono::duration<double>(end.t - submit.t).count();
  r.job_cpu_s = end.coordinator.cpu_s - submit.coordinator.cpu_s;
  r.slice_phase_s = std::chrono::duration<double>(last_slice_done_ - submit.t).count();
  r.combine_phase_s =
      std::chrono::duration<double>(last_combine_done_ - first_combine_lease_).count();
  r.combine_leases_per_s = double(r.combines) / r.combine_phase_s;
  const Sample c0 = sample_at(first_combine_lease_), c1 = sample_at(last_combine_done_);
  r.cpu_per_task_ms = 1e3 * (c1.coordinator.cpu_s - c0.coordinator.cpu_s) / double(r.combines);
  r.bench_cpu_s = c1.bench_cpu_s - c0.bench_cpu_s;
  r.write_bytes_per_task =
      double(c1.coordinator.write_bytes - c0.coordinator.write_bytes) / double(r.combines);
  for (const Sample& s : samples) r.max_threads = std::max(r.max_threads, s.coordinator.threads);
  StopChild();
  return absl::OkStatus();
}

// The job store alone: UpdateChunks as a lease writes it (one chunk, one transaction, fsynced),
// in a job of `tasks` tasks. Returns ms per write.
absl::StatusOr<double> StoreWriteMs(const std::string& dir, int tasks, int writes) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  absl::StatusOr<std::unique_ptr<JobStore>> store = JobStore::Open(dir + "/jobs.db");
  if (!store.ok()) return store.status();
  JobRecord job;
  job.id = "j-bench";
  job.tenant = "default";
  job.input_path = "sim/scan.h5";
  job.output_name = "bench";
  job.params_json = "{}";
  job.created_unix_ms = job.updated_unix_ms = 1;
  if (absl::Status s = (*store)->CreateJob(job); !s.ok()) return s;
  std::vector<ChunkRecord> chunks(static_cast<size_t>(tasks));
  for (int i = 0; i < tasks; ++i) {
    chunks[size_t(i)].job_id = job.id;
    chunks[size_t(i)].key = {i % 1000, i / 1000, 0};
  }
  if (absl::Status s = (*store)->AddChunks(job.id, chunks); !s.ok()) return s;
  const auto t = Clock::now();
  for (int i = 0; i < writes; ++i) {
    ChunkRecord next = chunks[size_t(i % tasks)];
    const int64_t expected = next.generation;
    next.state = ChunkState::kLeased;
    next.generation = expected + 1;
    next.lease_id = "j-bench/" + std::to_string(i) + "/1";
    next.worker_id = "w-1";
    next.deadline_unix_ms = 30'000;
    next.attempts = 1;
    const ChunkUpdate update{next, expected};
    if (absl::Status s = (*store)->UpdateChunks({&update, 1}, 2); !s.ok()) return s;
    chunks[size_t(i % tasks)] = next;
  }
  return 1e3 * Since(t) / double(writes);
}

int Main(int argc, char** argv) {
  if (argc == 4 && std::string(argv[1]) == "--serve") return Serve(argv[2], argv[3]);
  std::vector<int> worker_counts = {8, 64, 512};
  if (argc > 1) {
    worker_counts.clear();
    for (absl::string_view w : absl::StrSplit(argv[1], ',')) {
      int n = 0;
      if (!absl::SimpleAtoi(w, &n) || n < 1) return Fail("bad worker count list");
      worker_counts.push_back(n);
    }
  }
  const int chunks = argc > 2 ? std::atoi(argv[2]) : 814;
  const double walk_s = argc > 3 ? std::atof(argv[3]) : 0.0;
  const std::string root = (fs::temp_directory_path() / "coordinator_load_bench").string();
  fs::remove_all(root);
  spdlog::set_level(spdlog::level::warn);

  SimulateOptions so;
  so.preset = "office";
  so.seed = 1;
  so.rig.rate_hz = 3;
  so.rig.beam_step_deg = 2;
  so.max_duration_s = walk_s;
  so.output_dir = root + "/data/sim";
  absl::StatusOr<SimulationSummary> sim = Simulate(so);
  if (!sim.ok()) return Fail(sim.status().ToString());
  std::printf(
      "scan: office, seed 1, 3 Hz, 2 deg beams: %.1f s walk, %llu rays; %d chunks "
      "named by every slice's partial sums\n",
      sim->duration_s, static_cast<unsigned long long>(sim->rays), chunks);
  std::printf("(the coordinator: its own process, job store on %s; tasks = slices + chunks)\n\n",
              root.c_str());

  std::printf("%8s %9s %11s %10s %10s %11s %8s %9s %9s %11s %11s %11s %9s %8s %8s\n", "workers",
              "reg s", "hb/s storm", "cpu/hb ms", "idle po/s", "idle cpu/s", "slices", "combines",
              "job s", "slice ph s", "comb ph s", "leases/s", "cpu/task", "B/task", "threads");
  std::vector<std::unique_ptr<LoadRun>> runs;
  for (int w : worker_counts) {
    auto run =
        std::make_unique<LoadRun>(root + "/run_" + std::to_string(w), root + "/data", w, chunks);
    if (absl::Status s = run->Run(); !s.ok()) return Fail(s.ToString());
    const RunResult& r = run->result();
    std::printf(
        "%8d %9.2f %11.0f %10.3f %10.0f %11.3f %8d %9d %9.2f %11.2f %11.2f %11.0f %9.3f "
        "%8.0f %8d\n",
        r.workers, r.register_s, r.heartbeats_per_s, r.cpu_per_heartbeat_ms, r.idle_polls_per_s,
        r.idle_cpu_per_s, r.slices, r.combines, r.job_s, r.slice_phase_s, r.combine_phase_s,
        r.combine_leases_per_s, r.cpu_per_task_ms, r.write_bytes_per_task, r.max_threads);
    std::fflush(stdout);
    runs.push_back(std::move(run));
  }
  std::printf(
      "\ncolumns: reg s = RegisterWorker of all workers, one after the other; hb/s storm "
      "= heartbeats/s with every worker sending back to back; idle po/s, idle cpu/s = "
      "LeaseChunk long polls/s and coordinator CPU s/s with no job; job s = submit to "
      "SUCCEEDED (ingest, slices, combines); comb ph s = first combine lease to last "
      "combine completion; leases/s = combines / comb ph s (each a lease and a "
      "completion); cpu/task = coordinator CPU ms per combine task in that phase; "
      "B/task = coordinator's bytes written to disk per combine task; threads = the "
      "coordinator's peak thread count\n\n");
  for (auto& run : runs) {
    const RunResult& r = run->result();
    std::printf(
        "W=%d: coordinator CPU over the whole job %.2f s; this process (the simulated "
        "workers) %.2f CPU s in the combine phase; %lld empty lease polls and %lld "
        "heartbeats during the job; %lld lease calls past their deadline\n",
        r.workers, r.job_cpu_s, r.bench_cpu_s, static_cast<long long>(r.empty_polls),
        static_cast<long long>(r.heartbeats), static_cast<long long>(r.lease_deadlines));
    std::printf("  client-side: LeaseChunk granted %s\n", run->lease_lat.Text().c_str());
    std::printf("  client-side: CompleteChunk %s\n", run->complete_lat.Text().c_str());
    std::printf("  client-side: Heartbeat (5 s apart) %s\n", run->heartbeat_lat.Text().c_str());
    std::printf("  server-side mean handler time (its /metrics): %s\n", run->server_times.c_str());
  }
  const Sizes& z = runs.back()->sizes;
  std::printf(
      "\npayload bytes (protobuf, largest seen; gRPC adds a 5-byte frame and HTTP/2 "
      "headers): LeaseChunkRequest %zu, LeaseChunkResponse with a slice %zu, with a "
      "combine %zu, empty %zu; CompleteChunkRequest %zu, response %zu; "
      "HeartbeatRequest %zu, response %zu\n",
      z.lease_req.load(), z.slice_lease.load(), z.combine_lease.load(), z.empty_lease.load(),
      z.complete_req.load(), z.complete_resp.load(), z.heartbeat_req.load(),
      z.heartbeat_resp.load());

  std::printf(
      "\njob store alone (UpdateChunks of one task, one fsynced transaction, as every "
      "lease and completion writes):\n%10s %12s %10s\n",
      "tasks", "ms/write", "writes/s");
  for (int tasks : {100, 1000, 10000, 100000}) {
    absl::StatusOr<double> ms = StoreWriteMs(root + "/store", tasks, 200);
    if (!ms.ok()) return Fail(ms.status().ToString());
    std::printf("%10d %12.3f %10.0f\n", tasks, *ms, 1e3 / *ms);
  }
  fs::remove_all(root);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
