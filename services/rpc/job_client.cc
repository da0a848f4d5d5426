#include "services/rpc/job_client.h"

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <thread>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/synchronization/mutex.h"
#include "proto/carvemap/v1/jobs.grpc.pb.h"
#include "services/rpc/grpc_security.h"
#include "services/rpc/grpc_status.h"
#include "storage/atomic_file.h"
#include "storage/file_hash.h"

namespace carvemap {
namespace pb = ::carvemap::v1;

namespace {

std::string StateName(pb::JobState s) {
  std::string name = pb::JobState_Name(s);
  const std::string prefix = "JOB_STATE_";
  return name.rfind(prefix, 0) == 0 ? name.substr(prefix.size()) : name;
}

bool IsTerminal(pb::JobState s) {
  return s == pb::JOB_STATE_SUCCEEDED || s == pb::JOB_STATE_FAILED ||
         s == pb::JOB_STATE_CANCELLED;
}

JobInfo FromProto(const pb::Job& j) {
  JobInfo info;
  info.job_id = j.job_id();
  info.state = StateName(j.state());
  info.terminal = IsTerminal(j.state());
  info.input_path = j.input_path();
  info.output_name = j.output_name();
  info.error = j.error();
  info.resolution_m = j.params().resolution_m();
  info.chunks_total = j.progress().chunks_total();
  info.chunks_done = j.progress().chunks_done();
  info.chunks_leased = j.progress().chunks_leased();
  info.chunk_retries = j.progress().chunk_retries();
  info.created_unix_ms = j.created_unix_ms();
  info.finished_unix_ms = j.finished_unix_ms();
  return info;
}

}  // namespace

class JobClient::Impl {
 public:
  Impl(const std::string& address, const ChannelSecurity& security) : bearer(security.bearer) {
    absl::StatusOr<std::shared_ptr<grpc::Channel>> made = MakeChannel(address, security);
    if (!made.ok()) {
      init = made.status();
      // A channel that never connects, so the stub is always usable; calls return `init`.
      made = grpc::CreateChannel("unix:/nonexistent", grpc::InsecureChannelCredentials());
    }
    channel = *made;
    stub = pb::JobService::NewStub(channel);
  }
  std::unique_ptr<grpc::ClientContext> Context(double timeout_s = 30) const {
    auto ctx = std::make_unique<grpc::ClientContext>();
    ctx->set_deadline(std::chrono::system_clock::now() +
                      std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
    AttachBearer(*ctx, bearer);
    return ctx;
  }
  absl::Status init;
  std::string bearer;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<pb::JobService::Stub> stub;
  absl::Mutex mu;
  grpc::ClientContext* watch_ctx ABSL_GUARDED_BY(mu) = nullptr;
  bool watch_cancelled ABSL_GUARDED_BY(mu) = false;
};

JobClient::JobClient(const std::string& address, const ChannelSecurity& security)
    : impl_(std::make_unique<Impl>(address, security)) {}
JobClient::~JobClient() = default;

absl::Status JobClient::WaitForReady(double timeout_s) {
  if (!impl_->init.ok()) return impl_->init;
  const auto deadline = std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000));
  if (!impl_->channel->WaitForConnected(deadline)) {
    return absl::UnavailableError("coordinator not reachable");
  }
  return absl::OkStatus();
}

absl::StatusOr<JobInfo> JobClient::Submit(const SubmitParams& params) {
  pb::SubmitJobRequest req;
  if (!params.upload_id.empty()) {
    req.set_upload_id(params.upload_id);
  } else {
    req.set_input_path(params.input_path);
  }
  req.set_output_name(params.output_name);
  req.mutable_params()->set_resolution_m(params.resolution_m);
  req.mutable_params()->set_object_resolution_m(params.object_resolution_m);
  req.mutable_params()->set_floorplan_method(params.floorplan_method);
  req.mutable_params()->set_trimmed_points(params.trimmed_points);
  req.mutable_params()->set_min_object_volume_m3(params.min_object_volume_m3);
  if (params.evaluation == "fast") {
    req.mutable_params()->set_evaluation(pb::CARVE_EVALUATION_FAST);
  } else if (params.evaluation == "exact") {
    req.mutable_params()->set_evaluation(pb::CARVE_EVALUATION_EXACT);
  } else if (!params.evaluation.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("evaluation '", params.evaluation, "': must be fast or exact"));
  }
  req.mutable_params()->set_north(params.north);  // these three checked by the coordinator
  req.mutable_params()->set_location(params.location);
  req.mutable_params()->set_survey_date(params.survey_date);
  req.set_idempotency_key(params.idempotency_key);
  pb::SubmitJobResponse resp;
  if (!impl_->init.ok()) return impl_->init;
  auto ctx = impl_->Context();
  if (absl::Status s = FromGrpcStatus(impl_->stub->SubmitJob(ctx.get(), req, &resp)); !s.ok()) {
    return s;
  }
  return FromProto(resp.job());
}

absl::StatusOr<JobInfo> JobClient::Get(const std::string& job_id) {
  pb::GetJobRequest req;
  req.set_job_id(job_id);
  pb::Job resp;
  if (!impl_->init.ok()) return impl_->init;
  auto ctx = impl_->Context();
  if (absl::Status s = FromGrpcStatus(impl_->stub->GetJob(ctx.get(), req, &resp)); !s.ok()) {
    return s;
  }
  return FromProto(resp);
}

absl::StatusOr<std::vector<JobInfo>> JobClient::List(const std::string& state_filter,
                                                     int limit) {
  pb::ListJobsRequest req;
  if (!state_filter.empty()) {
    pb::JobState s;
    if (!pb::JobState_Parse(absl::StrCat("JOB_STATE_", state_filter), &s)) {
      return absl::InvalidArgumentError(absl::StrCat("unknown state '", state_filter, "'"));
    }
    req.set_state_filter(s);
  }
  std::vector<JobInfo> jobs;
  do {
    req.set_page_size(std::min(limit - static_cast<int>(jobs.size()), 500));
    pb::ListJobsResponse resp;
    if (!impl_->init.ok()) return impl_->init;
  auto ctx = impl_->Context();
    if (absl::Status s = FromGrpcStatus(impl_->stub->ListJobs(ctx.get(), req, &resp)); !s.ok()) {
      return s;
    }
    for (const pb::Job& j : resp.jobs()) jobs.push_back(FromProto(j));
    req.set_page_token(resp.next_page_token());
  } while (!req.page_token().empty() && static_cast<int>(jobs.size()) < limit);
  return jobs;
}

absl::StatusOr<JobInfo> JobClient::Cancel(const std::string& job_id, const std::string& reason) {
  pb::CancelJobRequest req;
  req.set_job_id(job_id);
  req.set_reason(reason);
  pb::CancelJobResponse resp;
  if (!impl_->init.ok()) return impl_->init;
  auto ctx = impl_->Context();
  if (absl::Status s = FromGrpcStatus(impl_->stub->CancelJob(ctx.get(), req, &resp)); !s.ok()) {
    return s;
  }
  return FromProto(resp.job());
}

absl::StatusOr<JobInfo> JobClient::Watch(
    const std::string& job_id, double min_interval_s,
    const std::function<void(const WatchUpdate&)>& on_update) {
  pb::WatchJobRequest req;
  req.set_job_id(job_id);
  req.set_min_interval_s(min_interval_s);
  if (!impl_->init.ok()) return impl_->init;
  grpc::ClientContext ctx;
  AttachBearer(ctx, impl_->bearer);
  {
    absl::MutexLock lock(&impl_->mu);
    if (impl_->watch_cancelled) return absl::CancelledError("watch cancelled");
    impl_->watch_ctx = &ctx;
  }
  std::unique_ptr<grpc::ClientReader<pb::JobEvent>> reader = impl_->stub->WatchJob(&ctx, req);
  WatchUpdate u;
  pb::JobEvent e;
  while (reader->Read(&e)) {
    if (e.has_snapshot()) {
      const JobInfo j = FromProto(e.snapshot());
      u.state = j.state;
      u.chunks_total = j.chunks_total;
      u.chunks_done = j.chunks_done;
    } else if (e.has_state_change()) {
      u.state = StateName(e.state_change().to_state());
    } else if (e.has_progress()) {
      const auto& p = e.progress();
      u.chunks_total = p.chunks().chunks_total();
      u.chunks_done = p.chunks().chunks_done();
      u.chunks_leased = p.chunks().chunks_leased();
      u.chunk_retries = p.chunks().chunk_retries();
      u.rays_done = p.rays_done();
      u.rays_total = p.rays_total();
      u.rays_per_s = p.rays_per_s();
      u.active_workers = p.active_workers();
      u.eta_s = p.eta_s();
      u.stage_done = p.stage_done();
      u.stage_total = p.stage_total();
      for (const auto& st : p.stages()) {
        if (!st.finished()) {
          u.stage = st.stage();
          u.stage_elapsed_s = st.elapsed_s();
        }
      }
    }
    if (on_update) on_update(u);
  }
  grpc::Status status = reader->Finish();
  bool cancelled;
  {
    absl::MutexLock lock(&impl_->mu);
    impl_->watch_ctx = nullptr;
    cancelled = impl_->watch_cancelled;
  }
  if (cancelled) return absl::CancelledError("watch cancelled");
  if (absl::Status s = FromGrpcStatus(status); !s.ok()) return s;
  return Get(job_id);
}

namespace {

UploadInfo FromProto(const pb::Upload& u) {
  UploadInfo out;
  out.upload_id = u.upload_id();
  out.name = u.name();
  out.input_path = u.input_path();
  out.size_bytes = u.size_bytes();
  out.received_bytes = u.received_bytes();
  out.complete = u.complete();
  return out;
}

// What a broken connection or a restarting server looks like; worth resuming after.
bool Resumable(const absl::Status& s) {
  return absl::IsUnavailable(s) || absl::IsAborted(s) || absl::IsDeadlineExceeded(s) ||
         absl::IsInternal(s) || absl::IsUnknown(s) || absl::IsCancelled(s) ||
         (absl::IsFailedPrecondition(s) && absl::StrContains(s.message(), "resume from"));
}

}  // namespace

absl::StatusOr<UploadInfo> JobClient::Upload(const std::string& path,
                                             const UploadOptions& options) {
  if (!impl_->init.ok()) return impl_->init;
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return absl::NotFoundError(absl::StrCat(path, ": ", ec.message()));
  absl::StatusOr<std::string> sha = Sha256HexOfFile(path);
  if (!sha.ok()) return sha.status();
  pb::StartUploadRequest start;
  start.set_name(options.name.empty() ? std::filesystem::path(path).filename().string()
                                      : options.name);
  start.set_size_bytes(static_cast<int64_t>(size));
  start.set_sha256_hex(*sha);
  const int64_t chunk = std::clamp<int64_t>(options.chunk_bytes, 1, 4 << 20);
  std::string buf(static_cast<size_t>(chunk), '\0');
  int idle_attempts = 0;
  double wait_s = 0.5;
  absl::Status last;
  // Until the server has answered once, an error is the answer: a wrong address or a server
  // that is down should not look like a connection to ride out.
  bool answered = false;
  while (true) {
    if (!last.ok()) {
      if (!Resumable(last) || ++idle_attempts >= options.max_attempts) return last;
      if (options.on_retry) options.on_retry(last, wait_s);
      std::this_thread::sleep_for(std::chrono::duration<double>(wait_s));
      wait_s = std::min(wait_s * 2, 8.0);
    }
    // Where the server stands; once it has answered, wait_for_ready rides out a reconnect.
    pb::Upload state;
    auto ctx = impl_->Context(answered ? 60 : 30);
    ctx->set_wait_for_ready(answered);
    last = FromGrpcStatus(impl_->stub->StartUpload(ctx.get(), start, &state));
    if (!last.ok() && !answered) return last;
    if (!last.ok()) continue;
    answered = true;
    if (options.on_progress) options.on_progress(state.received_bytes(), state.size_bytes());
    if (state.complete()) return FromProto(state);
    const int64_t from = state.received_bytes();
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
    if (f == nullptr || ::fseeko(f.get(), static_cast<off_t>(from), SEEK_SET) != 0) {
      return absl::NotFoundError(absl::StrCat(path, ": cannot read: ", std::strerror(errno)));
    }
    grpc::ClientContext stream_ctx;
    AttachBearer(stream_ctx, impl_->bearer);
    pb::Upload result;
    std::unique_ptr<grpc::ClientWriter<pb::UploadScanRequest>> writer =
        impl_->stub->UploadScan(&stream_ctx, &result);
    pb::UploadScanRequest msg;
    msg.set_upload_id(state.upload_id());
    int64_t offset = from;
    bool short_file = false;
    // At least one message, empty when the server holds every byte already (it stopped before
    // it could check and place the file): the stream's end makes it finish.
    for (bool first = true; offset < state.size_bytes() || first; first = false) {
      const size_t n =
          offset < state.size_bytes() ? std::fread(buf.data(), 1, buf.size(), f.get()) : 0;
      if (n == 0 && offset < state.size_bytes()) {
        short_file = true;
        break;
      }
      msg.set_offset(offset);
      msg.set_data(buf.data(), n);
      if (!writer->Write(msg)) break;  // the stream broke: Finish says why
      offset += static_cast<int64_t>(n);
      if (options.on_progress) options.on_progress(offset, state.size_bytes());
    }
    writer->WritesDone();
    last = FromGrpcStatus(writer->Finish());
    if (short_file) {
      return absl::DataLossError(absl::StrCat(path, ": the file got shorter while it was sent"));
    }
    if (last.ok() && result.complete()) return FromProto(result);
    if (last.ok()) last = absl::UnavailableError("the upload stream ended early");
    if (result.received_bytes() > from || offset > from) {
      idle_attempts = 0;  // it moved: the next stream is a fresh try
      wait_s = 0.5;
    }
  }
}

void JobClient::CancelWatch() {
  absl::MutexLock lock(&impl_->mu);
  impl_->watch_cancelled = true;
  if (impl_->watch_ctx != nullptr) impl_->watch_ctx->TryCancel();
}

absl::Status JobClient::Fetch(const std::string& job_id, const std::string& name,
                              const std::string& dest_path) {
  pb::FetchArtifactRequest req;
  req.set_job_id(job_id);
  req.set_name(name);
  if (!impl_->init.ok()) return impl_->init;
  grpc::ClientContext ctx;
  AttachBearer(ctx, impl_->bearer);
  std::unique_ptr<grpc::ClientReader<pb::ArtifactChunk>> reader =
      impl_->stub->FetchArtifact(&ctx, req);
  const std::string partial = dest_path + ".partial";
  std::error_code ec;
  if (auto parent = std::filesystem::path(dest_path).parent_path(); !parent.empty()) {
    std::filesystem::create_directories(parent, ec);
  }
  std::FILE* f = std::fopen(partial.c_str(), "wb");
  if (f == nullptr) return absl::FailedPreconditionError(absl::StrCat("cannot write ", partial));
  pb::ArtifactChunk chunk;
  std::string sha;
  bool write_ok = true;
  while (reader->Read(&chunk)) {
    write_ok &= std::fwrite(chunk.data().data(), 1, chunk.data().size(), f) == chunk.data().size();
    if (chunk.last()) sha = chunk.sha256_hex();
  }
  write_ok &= std::fclose(f) == 0;
  absl::Status s = FromGrpcStatus(reader->Finish());
  if (s.ok() && !write_ok) s = absl::DataLossError(absl::StrCat("writing ", partial, " failed"));
  if (s.ok()) {
    absl::StatusOr<std::string> got = Sha256HexOfFile(partial);
    if (!got.ok()) {
      s = got.status();
    } else if (*got != sha) {
      s = absl::DataLossError(absl::StrCat(name, ": SHA-256 mismatch after download"));
    }
  }
  if (!s.ok()) {
    std::filesystem::remove(partial, ec);
    return s;
  }
  if (absl::Status renamed = RenameDurably(partial, dest_path); !renamed.ok()) {
    std::filesystem::remove(partial, ec);
    return renamed;
  }
  return absl::OkStatus();
}

std::string FormatProgress(const WatchUpdate& u) {
  const auto eta = [&u](std::string& line) {
    if (u.eta_s >= 0) {
      const int s = static_cast<int>(u.eta_s + 0.5);
      absl::StrAppendFormat(&line, "  ETA %d:%02d", s / 60, s % 60);
    } else {
      absl::StrAppend(&line, "  ETA --:--");
    }
  };
  std::string line = absl::StrFormat("%-9s", u.state);
  if (u.chunks_total > 0) {
    constexpr int kWidth = 24;
    const int filled = static_cast<int>(kWidth * u.chunks_done / u.chunks_total);
    absl::StrAppend(&line, " [", std::string(filled, '#'), std::string(kWidth - filled, '.'), "] ");
    // Tasks: a carve's slices, then its chunks (docs/RPC.md "Slices").
    absl::StrAppendFormat(&line, "%d/%d tasks", u.chunks_done, u.chunks_total);
    if (u.rays_total > 0 && u.rays_done >= u.rays_total && u.chunks_done < u.chunks_total) {
      // Every ray carved: the tasks left add up the chunks' partial sums.
      absl::StrAppendFormat(&line, "  %.1f M rays carved, combining chunks  %d worker(s)",
                            u.rays_total * 1e-6, u.active_workers);
      eta(line);
    } else if (u.state == "CARVING" || u.rays_per_s > 0) {
      absl::StrAppendFormat(&line, "  %.1f/%.1f M rays  %.2f M rays/s  %d worker(s)",
                            u.rays_done * 1e-6, u.rays_total * 1e-6, u.rays_per_s * 1e-6,
                            u.active_workers);
      eta(line);
    } else if (u.stage_total > 0) {
      absl::StrAppendFormat(&line, "  %d/%d", u.stage_done, u.stage_total);
      eta(line);
    }
    if (u.chunk_retries > 0) absl::StrAppendFormat(&line, "  %d retried", u.chunk_retries);
  }
  if (!u.stage.empty()) absl::StrAppendFormat(&line, "  (%s %.0f s)", u.stage, u.stage_elapsed_s);
  return line;
}

std::string FormatJob(const JobInfo& j) {
  std::string line = absl::StrFormat("%-18s %-10s %5d/%-5d tasks  %-24s -> %s", j.job_id, j.state,
                                     j.chunks_done, j.chunks_total, j.input_path, j.output_name);
  if (!j.error.empty()) absl::StrAppend(&line, "\n    ", j.error);
  return line;
}

}  // namespace carvemap
