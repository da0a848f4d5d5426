#include "services/rpc/merge_client.h"

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <thread>
#include <utility>

#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "absl/time/time.h"
#include "proto/carvemap/v1/merge.grpc.pb.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/grpc_status.h"
#include "services/rpc/merge_params_proto.h"

namespace carvemap {
namespace fs = std::filesystem;
namespace pb = ::carvemap::v1;

namespace {

using Clock = std::chrono::steady_clock;

// How often `progress` is asked whether to go on while nothing else calls it.
constexpr auto kTick = std::chrono::milliseconds(250);
// RecarveRequest parts are ~1 MiB (services/rpc/merge_service.cc); room for a few.
constexpr int kMaxReceiveBytes = 16 << 20;

struct Shared {
  MergeClientSpec spec;
  std::vector<std::shared_ptr<grpc::Channel>> channels;
  std::vector<std::unique_ptr<pb::MergeService::Stub>> stubs;
  std::atomic<size_t> next{0};
};

grpc::ChannelArguments ChannelArgs() {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxReceiveBytes);
  // A merge stage can run for minutes without a message: pings find a merge service whose
  // host or network is gone (a killed process is seen at once: its socket closes).
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 10000);
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 10000);
  args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  // A restarted merge service is found within ~2 s (gRPC's default backoff grows to 2 min).
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  return args;
}

// What one attempt came to.
enum class Outcome {
  kVerdict,    // the service finished the merge: its status is final
  kCancelled,  // `progress` said stop
  kRefused,    // the service refused the call (wrong secret, bad request): not retried
  kLost,       // unreachable, or the stream ended without a verdict: retried
};

// The request's key for the re-carve cache: resolution, chunks and their regions.
std::string RecarveKey(const std::vector<RecarveChunk>& chunks, double resolution_m) {
  std::string key = absl::StrCat(resolution_m, ";");
  for (const RecarveChunk& c : chunks) {
    absl::StrAppend(&key, c.chunk.x(), ",", c.chunk.y(), ",", c.chunk.z(), ",",
                    c.depth, ",", c.cells.size(), ":", c.cells, ";");
  }
  return key;
}

// One job's merge: its attempts, the progress it forwards, the re-carve it remembers.
class MergeCall {
 public:
  MergeCall(Shared& shared, const MergeJobRequest& req) : sh_(shared), req_(req) {}

  absl::Status Run() {
    const size_t n = sh_.channels.size();
    const size_t first = sh_.next.fetch_add(1) % n;  // jobs spread over the services
    std::vector<std::string> lost;
    const int attempts = sh_.spec.attempts;
    for (int attempt = 1; attempt <= attempts; ++attempt) {
      const size_t i = (first + attempt - 1) % n;
      const std::string& address = sh_.spec.addresses[i];
      auto [outcome, status] = Attempt(i, attempt);
      switch (outcome) {
        case Outcome::kVerdict:
          if (attempt > 1 && status.ok()) {
            spdlog::info("coordinator: job {}: merge done on {} (attempt {} of {})", req_.job_id,
                         address, attempt, attempts);
          }
          return status;
        case Outcome::kCancelled:
          return absl::CancelledError("merge cancelled");
        case Outcome::kRefused:
          return absl::Status(status.code(), absl::StrCat("the merge service ", address,
                                                          " refused the merge: ",
                                                          status.message()));
        case Outcome::kLost:
          break;
      }
      lost.push_back(absl::StrCat(address, ": ", status.message()));
      spdlog::warn("coordinator: job {}: merge service {} lost (attempt {} of {}): {}{}",
                   req_.job_id, address, attempt, attempts, std::string(status.message()),
                   attempt < attempts ? "; merging again" : "");
      if (attempt < attempts && !Pause(sh_.spec.retry_delay_s)) {
        return absl::CancelledError("merge cancelled");
      }
    }
    RemoveLeftovers();
    return absl::UnavailableError(absl::StrCat(
        "the merge service was lost ", attempts, " time(s) (", absl::StrJoin(lost, "; "),
        "); the merge did not finish (no job.json)"));
  }

 private:
  // `progress` with the latest report (calls never overlap).
  bool Report(const std::string& stage, uint64_t done, uint64_t total) {
    absl::MutexLock lock(&progress_mu_);
    stage_ = stage;
    done_ = done;
    total_ = total;
    return !req_.progress || req_.progress(stage_, done_, total_);
  }
  bool Tick() {
    absl::MutexLock lock(&progress_mu_);
    return !req_.progress || req_.progress(stage_, done_, total_);
  }
  // Sleeps `seconds`, asking `progress` every tick; false = cancelled.
  bool Pause(double seconds) {
    const Clock::time_point end =
        Clock::now() + std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
    while (Clock::now() < end) {
      if (!Tick()) return false;
      std::this_thread::sleep_for(std::min<Clock::duration>(kTick, end - Clock::now()));
    }
    return Tick();
  }

  // Answers one re-carve request of the service, once per distinct request across attempts.
  absl::StatusOr<std::string> Recarve(const std::vector<RecarveChunk>& chunks,
                                      double resolution_m) {
    if (!req_.recarve) return absl::FailedPreconditionError("no re-carving offered");
    const std::string key = RecarveKey(chunks, resolution_m);
    if (recarved_ && recarved_->first == key) {
      spdlog::info("coordinator: job {}: the {} object chunks were carved again for an earlier "
                   "attempt; reusing them", req_.job_id, chunks.size());
      return recarved_->second;
    }
    absl::StatusOr<std::string> dir = req_.recarve(chunks, resolution_m);
    if (dir.ok()) recarved_.emplace(key, *dir);
    return dir;
  }

  std::pair<Outcome, absl::Status> Attempt(size_t i, int attempt) {
    const std::string& address = sh_.spec.addresses[i];
    grpc::Channel& channel = *sh_.channels[i];
    Report(attempt == 1 ? "connect" : "reconnect", 0, 1);
    const Clock::time_point give_up =
        Clock::now() +
        std::chrono::milliseconds(static_cast<int64_t>(sh_.spec.connect_timeout_s * 1000));
    while (!channel.WaitForConnected(std::chrono::system_clock::now() + kTick)) {
      if (!Tick()) return {Outcome::kCancelled, absl::CancelledError("")};
      if (Clock::now() > give_up) {
        return {Outcome::kLost,
                absl::UnavailableError(absl::StrCat("not reachable within ",
                                                    sh_.spec.connect_timeout_s, " s"))};
      }
    }
    grpc::ClientContext ctx;
    AttachBearer(ctx, sh_.spec.security.bearer);
    std::unique_ptr<grpc::ClientReaderWriter<pb::MergeClientMessage, pb::MergeServerMessage>>
        stream = sh_.stubs[i]->Merge(&ctx);
    {
      pb::MergeClientMessage start;
      pb::MergeJob* job = start.mutable_start();
      job->set_job_id(req_.job_id);
      job->set_tiles_dir(req_.tiles_dir);
      job->set_output_dir(req_.output_dir);
      job->set_scan_root(req_.scan_root);
      job->set_scan_path(req_.scan_input);
      MergeParamsToProto(req_.params, job);
      job->set_recarve_available(static_cast<bool>(req_.recarve));
      job->set_job_json(req_.job_json);
      job->set_attempt(attempt);
      stream->Write(start);  // a failure shows in Read/Finish below
    }
    spdlog::info("coordinator: job {}: merging on {}{}", req_.job_id, address,
                 attempt > 1 ? absl::StrCat(" (attempt ", attempt, ")") : "");

    // Between the service's reports: ask `progress` (a cancelled job, a stopping coordinator).
    std::atomic<bool> cancelled{false};
    absl::Notification finished;
    std::thread ticker([&] {
      while (!finished.WaitForNotificationWithTimeout(absl::FromChrono(kTick))) {
        if (!Tick()) {
          cancelled = true;
          ctx.TryCancel();
          return;
        }
      }
    });

    std::optional<absl::Status> verdict;
    std::vector<RecarveChunk> pending;
    uint64_t pending_id = 0;
    double pending_resolution = 0;
    absl::Status pending_error;
    pb::MergeServerMessage msg;
    while (stream->Read(&msg)) {
      if (msg.has_progress()) {
        const pb::MergeProgress& p = msg.progress();
        if (!Report(p.stage(), p.done(), p.total())) {
          cancelled = true;
          ctx.TryCancel();
        }
      } else if (msg.has_recarve()) {
        pb::RecarveRequest& r = *msg.mutable_recarve();
        if (pending.empty() && pending_error.ok()) {
          pending_id = r.request_id();
          pending_resolution = r.resolution_m();
        }
        for (pb::RecarveChunk& c : *r.mutable_chunks()) {
          // Checked, not decoded: the coordinator only writes the regions for the workers.
          if (absl::Status s = ChunkRegion::CheckEncoding(c.region_depth(), c.region()); !s.ok()) {
            pending_error = absl::InvalidArgumentError(
                absl::StrCat("RecarveRequest chunk (", c.chunk().x(), ",", c.chunk().y(), ",",
                             c.chunk().z(), "): ", s.message()));
            continue;
          }
          pending.push_back(RecarveChunk{ChunkKey(c.chunk().x(), c.chunk().y(), c.chunk().z()),
                                         c.region_depth(), std::move(*c.mutable_region())});
        }
        if (!r.last()) continue;
        absl::StatusOr<std::string> dir =
            pending_error.ok() ? Recarve(pending, pending_resolution) : pending_error;
        pb::MergeClientMessage answer;
        pb::RecarveResult* result = answer.mutable_recarve_result();
        result->set_request_id(pending_id);
        result->set_code(static_cast<int>(dir.status().code()));
        result->set_message(std::string(dir.status().message()));
        if (dir.ok()) result->set_tiles_dir(*dir);
        pending.clear();
        pending_error = absl::OkStatus();
        if (!stream->Write(answer)) break;  // the service is gone: Finish says how
      } else if (msg.has_result()) {
        verdict = absl::Status(static_cast<absl::StatusCode>(msg.result().code()),
                               msg.result().message());
      }
    }
    stream->WritesDone();
    const grpc::Status status = stream->Finish();
    finished.Notify();
    ticker.join();
    if (cancelled) return {Outcome::kCancelled, absl::CancelledError("")};
    if (verdict) return {Outcome::kVerdict, *verdict};
    absl::Status s = FromGrpcStatus(status);
    if (s.ok()) s = absl::UnavailableError("the call ended without the merge's result");
    switch (s.code()) {
      case absl::StatusCode::kUnauthenticated:
      case absl::StatusCode::kPermissionDenied:
      case absl::StatusCode::kInvalidArgument:
      case absl::StatusCode::kUnimplemented:
      case absl::StatusCode::kFailedPrecondition:
        return {Outcome::kRefused, s};
      default:
        return {Outcome::kLost, s};
    }
  }

  // After the last lost service: no temporary files of the interrupted merges stay behind
  // (they never look complete, but they are not the job's). What the merge finished before
  // it was lost stays: complete files, without job.json.
  void RemoveLeftovers() {
    std::error_code ec;
    fs::remove_all(fs::path(req_.output_dir) / ".segment", ec);
    std::vector<fs::path> partial;
    for (fs::recursive_directory_iterator it(req_.output_dir, ec), end; !ec && it != end;
         it.increment(ec)) {
      if (it->path().filename().string().ends_with(".partial")) partial.push_back(it->path());
    }
    for (const fs::path& p : partial) fs::remove(p, ec);
  }

  Shared& sh_;
  const MergeJobRequest& req_;
  absl::Mutex progress_mu_;
  std::string stage_ ABSL_GUARDED_BY(progress_mu_);
  uint64_t done_ ABSL_GUARDED_BY(progress_mu_) = 0;
  uint64_t total_ ABSL_GUARDED_BY(progress_mu_) = 0;
  std::optional<std::pair<std::string, std::string>> recarved_;  // key, tiles dir
};

}  // namespace

absl::Status MergeClientSpec::Validate() const {
  if (addresses.empty()) return absl::InvalidArgumentError("no merge service address");
  for (const std::string& a : addresses) {
    if (a.empty()) return absl::InvalidArgumentError("an empty merge service address");
  }
  if (attempts < 1) return absl::InvalidArgumentError("merge attempts must be >= 1");
  if (!(connect_timeout_s > 0) || !(retry_delay_s >= 0)) {
    return absl::InvalidArgumentError(
        "merge connect timeout must be > 0 and the retry delay >= 0");
  }
  return security.Validate();
}

absl::StatusOr<MergeFunction> RemoteMerge(MergeClientSpec spec) {
  if (absl::Status s = spec.Validate(); !s.ok()) return s;
  auto shared = std::make_shared<Shared>();
  for (const std::string& address : spec.addresses) {
    absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
        MakeChannel(address, spec.security, ChannelArgs());
    if (!channel.ok()) return channel.status();
    shared->stubs.push_back(pb::MergeService::NewStub(*channel));
    shared->channels.push_back(*std::move(channel));
  }
  shared->spec = std::move(spec);
  return MergeFunction([shared](const MergeJobRequest& req) {
    return MergeCall(*shared, req).Run();
  });
}

}  // namespace carvemap
