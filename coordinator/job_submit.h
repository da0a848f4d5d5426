// A submit's checks and the job it stores (docs/RPC.md "SubmitJob"): the input path's text, the
// parameters, the output name, the idempotency key (the same request again is the first job;
// another request with the key is ALREADY_EXISTS), the scan readable under the tenant's folder,
// the output folders writable and not a link out of the tenant's; then the job in the store,
// QUEUED. Plain code over the store and the folders; the service converts its messages and
// starts the job.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "absl/status/statusor.h"
#include "coordinator/job_folders.h"
#include "coordinator/job_params.h"
#include "storage/job_store.h"

namespace carvemap {

struct SubmitRequest {
  std::string tenant, tenant_dir;  // the caller's
  std::string input_path;          // under the tenant's data folder (an upload's: uploads/<name>)
  std::string output_name;         // "" = the job id
  JobParamsRequest params;
  std::string idempotency_key;  // "" = none
};

struct SubmitOutcome {
  JobRecord job;              // as stored
  bool deduplicated = false;  // the key matched an earlier job: no new one
};

struct SubmitContext {
  JobStore* store = nullptr;
  CoordinatorFolders folders;
  int max_jobs_per_tenant = 0;
  int64_t now_unix_ms = 0;
  std::function<std::string()> new_job_id;  // for a submit without a key
  // What the tenant is not told (the server's folders when one cannot be written); the
  // service logs it.
  std::function<void(const std::string&)> server_note;
};

// INVALID_ARGUMENT: a bad path text, parameter, output name or key; NOT_FOUND /
// PERMISSION_DENIED: the scan missing or a link out (storage/confined_path.h);
// ALREADY_EXISTS: the key with another request, or the output name taken;
// RESOURCE_EXHAUSTED: the tenant's unfinished jobs at the limit; FAILED_PRECONDITION: an
// output folder that cannot be written. A refused submit leaves no folder it made.
[[nodiscard]] absl::StatusOr<SubmitOutcome> SubmitJob(const SubmitRequest& req,
                                                      const SubmitContext& ctx);

// Makes `dir` and checks files can be written into it: a job whose outputs cannot be written
// fails at submit, not after an hour of carving. FAILED_PRECONDITION naming `what` and `dir`.
absl::Status CheckWritableDir(const std::string& dir, const std::string& what);

// `output_name`'s rule: [A-Za-z0-9._-]{1,128}, not "." or "..".
[[nodiscard]] bool ValidOutputName(const std::string& name);

}  // namespace carvemap
