// Streamed uploads into a tenant's folder (docs/RPC.md "Uploads"): a client sends a file in
// pieces, resumes after a broken connection from what the server holds, and the file appears
// under its final name only whole and with the SHA-256 it was announced with.
//
// Under a tenant's data folder:
//   uploads/<name>             finished uploads: what SubmitJob's input_path names
//   .uploads/<id>.partial      the bytes received so far; its size is where to resume, so a
//                              restarted server resumes too
//   .uploads/<id>.json         {name, size_bytes, sha256_hex, complete}: what was announced
// The id follows from (name, size, SHA-256): a client that lost it, or lost the connection
// before learning it, finds its upload again by starting with the same file.
#pragma once

#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/synchronization/mutex.h"

namespace carvemap {

struct UploadRequest {
  std::string name;  // [A-Za-z0-9._-]{1,128}, not starting with '.'
  int64_t size_bytes = 0;
  std::string sha256_hex;  // 64 hex digits (either case)
};

struct UploadState {
  std::string id;  // "u-" and 24 hex digits
  std::string name;
  std::string input_path;  // "uploads/<name>", relative to the tenant's data folder
  int64_t size_bytes = 0;
  std::string sha256_hex;  // lower case
  int64_t received_bytes = 0;
  bool complete = false;
};

// "u-" + the first 24 hex digits of SHA-256(name, size, sha256): the same file, the same id.
[[nodiscard]] std::string UploadId(const UploadRequest& request);

class UploadStore;

// The one writer of an upload (UploadStore::OpenWriter); another is refused while it lives.
class UploadWriter {
 public:
  ~UploadWriter();
  UploadWriter(const UploadWriter&) = delete;
  UploadWriter& operator=(const UploadWriter&) = delete;

  [[nodiscard]] const UploadState& state() const { return state_; }
  // Writes `data` at `offset`. FailedPrecondition when `offset` is not the bytes received so
  // far (the message says where to resume) or the upload is complete; InvalidArgument past
  // size_bytes; ResourceExhausted when the disk is full (the bytes before stay).
  [[nodiscard]] absl::StatusOr<UploadState> Append(int64_t offset, absl::string_view data);
  // Once every byte is in: syncs the data, checks the SHA-256 and puts the file at
  // uploads/<name> (durably, refusing to replace a file there). DataLoss on a mismatch: the
  // received bytes are removed, the upload starts again from nothing. FailedPrecondition
  // before the last byte. A complete upload returns its state.
  [[nodiscard]] absl::StatusOr<UploadState> Finish();

 private:
  friend class UploadStore;
  UploadWriter(UploadStore* store, std::string dir, std::string key, UploadState state, int fd)
      : store_(store),
        dir_(std::move(dir)),
        key_(std::move(key)),
        state_(std::move(state)),
        fd_(fd) {}
  UploadStore* store_;
  std::string dir_;  // the tenant's data folder
  std::string key_;  // in the store's set of open writers
  UploadState state_;
  int fd_ = -1;  // the partial file; -1 once complete
};

class UploadStore {
 public:
  struct Options {
    // Bytes a tenant may hold in uploads (finished files in uploads/ and what unfinished ones
    // announced); 0 = no quota.
    int64_t quota_bytes = 0;
    // An unfinished upload without data for this long is removed when the next starts.
    int64_t expire_after_ms = int64_t{24} * 3600 * 1000;
  };
  explicit UploadStore(Options options) : options_(options) {}

  // Starts an upload into `dir` (a tenant's data folder, which must exist) or finds the one
  // with the same name, size and SHA-256. InvalidArgument: a bad name, size or hash.
  // AlreadyExists: uploads/<name> exists (and is not this upload's), or another unfinished
  // upload has the name. ResourceExhausted: past the quota, or the disk has not the room.
  // FailedPrecondition: uploads/ or .uploads/ is not a plain folder (a symlink).
  [[nodiscard]] absl::StatusOr<UploadState> Start(const std::string& dir,
                                                  const UploadRequest& request, int64_t now_ms);
  // The upload `id` of `dir`. NotFound when there is none (also for a malformed id).
  [[nodiscard]] absl::StatusOr<UploadState> Find(const std::string& dir, const std::string& id);
  // The writer of upload `id`. Aborted while another writer of it is open; NotFound as Find.
  [[nodiscard]] absl::StatusOr<std::unique_ptr<UploadWriter>> OpenWriter(const std::string& dir,
                                                                         const std::string& id);

 private:
  friend class UploadWriter;
  void Release(const std::string& key);
  // The unfinished uploads of `dir`, each record read once; those without data for longer
  // than expire_after_ms (and not being written) are removed instead.
  std::vector<UploadState> UnfinishedUploads(const std::string& dir, int64_t now_ms)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const Options options_;
  absl::Mutex mu_;
  std::set<std::string> writing_ ABSL_GUARDED_BY(mu_);  // "<dir>\n<id>" of open writers
};

}  // namespace carvemap
