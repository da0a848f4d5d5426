// A JobService client for the CLI (`carvemap run|submit|watch|status|list|cancel|fetch`):
// plain structs in and out, gRPC behind the pimpl. Thread-safe, except that one Watch runs at
// a time; CancelWatch may be called from any thread (e.g. a signal handling thread).
#ifndef CARVEMAP_SERVICES_RPC_JOB_CLIENT_H_
#define CARVEMAP_SERVICES_RPC_JOB_CLIENT_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/rpc/channel_security.h"

namespace carvemap {

struct JobInfo {
  std::string job_id;
  std::string state;  // "QUEUED", ..., "SUCCEEDED", "FAILED", "CANCELLED"
  bool terminal = false;
  std::string input_path;
  std::string output_name;
  std::string error;
  double resolution_m = 0;
  int64_t chunks_total = 0, chunks_done = 0, chunks_leased = 0, chunk_retries = 0;
  int64_t created_unix_ms = 0, finished_unix_ms = 0;
};

struct WatchUpdate {
  std::string state;
  int64_t chunks_total = 0, chunks_done = 0, chunks_leased = 0, chunk_retries = 0;
  int64_t rays_done = 0, rays_total = 0;
  double rays_per_s = 0;
  int active_workers = 0;
  std::string stage;       // the running stage ("ingest", "carve", "merge/<stage>")
  double stage_elapsed_s = 0;
  double eta_s = -1;       // the running stage's estimated seconds left; < 0: not known
  int64_t stage_done = 0, stage_total = 0;  // a merge stage's own counts (0 total: none)
};

struct SubmitParams {
  std::string input_path;  // relative to the coordinator's data root
  std::string upload_id;   // instead of input_path: a finished upload (JobClient::Upload)
  std::string output_name;  // "" = the job id
  double resolution_m = 0;  // 0 = default
  double object_resolution_m = 0;  // §5.6.1 re-carving of the object chunks; 0 = default
  std::string floorplan_method;    // "rooms" (§3.3) or "eigencrust" (§3.2); "" = rooms
  bool trimmed_points = false;     // §5.5 on request: the merge also writes points.ply
  double min_object_volume_m3 = 0;  // §5.6: smaller objects are dropped, m³; 0 = default
  std::string evaluation;           // eq 4.7 in the workers: "fast" or "exact"; "" = fast
  std::string north;                // §2.3: "auto", "magnetic" or "none"; "" = auto
  std::string location;             // §2.3 true north: "LAT,LON" in degrees; "" = magnetic
  std::string survey_date;          // with location: "YYYY-MM-DD"; "" = from the scan's times
  std::string idempotency_key;
};

struct UploadInfo {
  std::string upload_id;
  std::string name;
  std::string input_path;  // "uploads/<name>" in the tenant's folder
  int64_t size_bytes = 0, received_bytes = 0;
  bool complete = false;
};

struct UploadOptions {
  std::string name;  // the name in the tenant's uploads/ folder; "" = the file's own name
  int64_t chunk_bytes = 256 << 10;  // per message: under the server's 1 MiB request limit
  // Streams in a row that move no byte before giving up (a stream that moves some starts
  // the count again).
  int max_attempts = 8;
  // (bytes the server holds, file size): after the hash, after every message sent.
  std::function<void(int64_t, int64_t)> on_progress;
  // A broken stream about to be resumed: why, and the seconds waited first.
  std::function<void(const absl::Status&, double)> on_retry;
};

class JobClient {
 public:
  // Does not connect yet; calls fail UNAVAILABLE if nothing listens. `security.bearer` is the
  // tenant's token; a bad TLS file makes every call fail with the reason.
  explicit JobClient(const std::string& address, const ChannelSecurity& security = {});
  ~JobClient();
  JobClient(const JobClient&) = delete;
  JobClient& operator=(const JobClient&) = delete;

  // Waits until the channel is connected.
  absl::Status WaitForReady(double timeout_s);
  absl::StatusOr<JobInfo> Submit(const SubmitParams& params);
  absl::StatusOr<JobInfo> Get(const std::string& job_id);
  // state_filter "" = all; newest first; follows pages up to `limit` jobs.
  absl::StatusOr<std::vector<JobInfo>> List(const std::string& state_filter, int limit);
  absl::StatusOr<JobInfo> Cancel(const std::string& job_id, const std::string& reason);
  // Streams the job's events into `on_update` until it is terminal; returns the final job.
  // CANCELLED if CancelWatch was called.
  absl::StatusOr<JobInfo> Watch(const std::string& job_id, double min_interval_s,
                                const std::function<void(const WatchUpdate&)>& on_update);
  void CancelWatch();
  // Uploads the file at `path` into the tenant's uploads/ folder (docs/RPC.md "Uploads"):
  // hashes it, starts (or finds) the upload, streams what the server does not hold yet, and
  // after a broken connection resumes from what it holds. Errors: the server's (ALREADY_EXISTS,
  // RESOURCE_EXHAUSTED, DATA_LOSS when the file changed while it was sent), NOT_FOUND for a
  // missing file, the last stream's error after max_attempts streams without progress.
  absl::StatusOr<UploadInfo> Upload(const std::string& path, const UploadOptions& options);
  // Downloads artifact `name` of the job to `dest_path` (through "<dest>.partial" and a
  // rename), checking the SHA-256 the server sends.
  absl::Status Fetch(const std::string& job_id, const std::string& name,
                     const std::string& dest_path);

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

// One progress line: the state, the tasks done, then while carving the rays carved and their
// rate ("CARVING   [###.....] 2/9 tasks  3.8/9.5 M rays  0.08 M rays/s  2 worker(s)  ETA 1:09"),
// once every ray is carved the chunks' combines ("9.5 M rays carved, combining chunks"), while
// merging the stage's own counts; each with its ETA, and the running stage and its seconds.
std::string FormatProgress(const WatchUpdate& u);
// One line per job for `list`/`status`.
std::string FormatJob(const JobInfo& job);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_JOB_CLIENT_H_
