#include "coordinator/job_submit.h"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <regex>

#include "absl/strings/str_cat.h"
#include "storage/confined_path.h"
#include "storage/file_hash.h"

namespace carvemap {

namespace fs = std::filesystem;

bool ValidOutputName(const std::string& name) {
  static const std::regex kName("[A-Za-z0-9._-]{1,128}");
  return name != "." && name != ".." && std::regex_match(name, kName);
}

absl::Status CheckWritableDir(const std::string& dir, const std::string& what) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    return absl::FailedPreconditionError(
        absl::StrCat(what, " ", dir, ": cannot create: ", ec.message()));
  }
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    return absl::FailedPreconditionError(
        absl::StrCat(what, " ", dir, ": not writable: ", std::strerror(errno)));
  }
  return absl::OkStatus();
}

absl::StatusOr<SubmitOutcome> SubmitJob(const SubmitRequest& req, const SubmitContext& ctx) {
  const std::string& input = req.input_path;
  // Text first (INVALID_ARGUMENT, nothing on disk looked at), the file after the parameters.
  if (absl::Status s = CheckConfinedPathText(input, "input_path"); !s.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(s.message(), " (input paths are relative to the data root)"));
  }
  if (*fs::path(input).lexically_normal().begin() == ".uploads") {
    return absl::InvalidArgumentError(
        "input_path: .uploads/ holds unfinished uploads; submit the upload_id once it is "
        "complete (or uploads/<name>)");
  }
  absl::StatusOr<JobParams> params = ResolveJobParams(req.params);
  if (!params.ok()) return params.status();
  if (!req.output_name.empty() && !ValidOutputName(req.output_name)) {
    return absl::InvalidArgumentError(
        absl::StrCat("output_name '", req.output_name, "': must match [A-Za-z0-9._-]{1,128}"));
  }
  if (req.idempotency_key.size() > 128) {
    return absl::InvalidArgumentError("idempotency_key longer than 128 bytes");
  }
  JobStore& store = *ctx.store;
  if (!req.idempotency_key.empty()) {
    absl::StatusOr<std::optional<JobRecord>> found =
        store.FindJobByIdempotencyKey(req.tenant, req.idempotency_key);
    if (!found.ok()) return found.status();
    if (found->has_value()) {
      const JobRecord& j = **found;
      if (j.input_path != input || j.params_json != params->ToJson() ||
          (!req.output_name.empty() && j.output_name != req.output_name)) {
        return absl::AlreadyExistsError(absl::StrCat("idempotency_key '", req.idempotency_key,
                                                     "' was used for job ", j.id,
                                                     " with a different request"));
      }
      return SubmitOutcome{j, true};
    }
  }

  // The scan, resolved under the tenant's folder: PERMISSION_DENIED if a symlink leads out,
  // NOT_FOUND if missing or unreadable (storage/confined_path.h); the same answers whatever
  // lies outside.
  if (absl::StatusOr<ConfinedFile> scan =
          ConfinedFile::Open(ctx.folders.DataDir(req.tenant_dir), input, "input_path");
      !scan.ok()) {
    return scan.status();
  }

  JobRecord job;
  // A keyed submit gets an id derived from its tenant and key (unique per tenant, like the
  // key): tiles record their job id, so two runs submitted with the same key (`carvemap run`
  // with 1 and with 2 workers) give byte-identical tiles, and two tenants using the same key
  // get different jobs.
  job.id =
      req.idempotency_key.empty()
          ? ctx.new_job_id()
          : absl::StrCat(
                "j-", Sha256Hex(absl::StrCat(req.tenant, "\n", req.idempotency_key)).substr(0, 16));
  job.tenant = req.tenant;
  job.tenant_dir = req.tenant_dir;
  job.input_path = input;
  job.output_name = req.output_name.empty() ? job.id : req.output_name;
  job.params_json = params->ToJson();
  job.idempotency_key = req.idempotency_key;
  job.created_unix_ms = job.updated_unix_ms = ctx.now_unix_ms;
  // The output folder must not already be a link out of the tenant's output folder (one
  // planted there would have the merge write elsewhere).
  const std::string output_root = ctx.folders.OutputRoot(job.tenant_dir);
  if (absl::Status s = CheckWritableDir(output_root, "output root"); !s.ok()) {
    if (ctx.server_note) ctx.server_note(s.ToString());
    return absl::FailedPreconditionError("the output root is not writable");
  }
  if (absl::StatusOr<std::string> out =
          ResolveConfinedPath(output_root, job.output_name, "output_name");
      !out.ok() && !absl::IsNotFound(out.status())) {
    return out.status();
  }
  std::error_code ec;
  const std::string output_dir = ctx.folders.OutputDir(job), tiles_dir = ctx.folders.TilesDir(job);
  const bool output_existed = fs::exists(output_dir, ec);
  if (absl::Status s = CheckWritableDir(output_dir, "output"); !s.ok()) {
    if (ctx.server_note) ctx.server_note(absl::StrCat("job ", job.id, ": ", s.ToString()));
    return absl::FailedPreconditionError(
        absl::StrCat("output_name '", job.output_name, "': the output folder cannot be written"));
  }
  if (absl::Status s = CheckWritableDir(tiles_dir, "tiles dir"); !s.ok()) return s;
  if (absl::Status s = store.CreateJob(job, ctx.max_jobs_per_tenant); !s.ok()) {
    if (!output_existed) {
      // A refused submit leaves nothing behind: the folders made above, if still empty
      // (fs::remove does not remove a folder with anything in it).
      fs::remove(tiles_dir, ec);
      fs::remove(output_dir, ec);
    }
    if (absl::IsAlreadyExists(s)) {
      return absl::AlreadyExistsError(
          absl::StrCat("output_name '", job.output_name, "' is used by another job"));
    }
    return s;
  }
  absl::StatusOr<JobRecord> stored = store.GetJob(job.id);
  if (!stored.ok()) return stored.status();
  return SubmitOutcome{*std::move(stored), false};
}

}  // namespace carvemap
