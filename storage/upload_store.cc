#include "storage/upload_store.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"
#include "storage/file_hash.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

constexpr char kFinalDir[] = "uploads";
constexpr char kWorkDir[] = ".uploads";

bool ValidName(const std::string& name) {
  if (name.empty() || name.size() > 128 || name[0] == '.') return false;
  for (char c : name) {
    if (!absl::ascii_isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '_' && c != '-') {
      return false;
    }
  }
  return true;
}

bool IsHex(absl::string_view s, size_t digits) {
  if (s.size() != digits) return false;
  for (char c : s) {
    if (!absl::ascii_isxdigit(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

bool ValidId(const std::string& id) {
  return absl::StartsWith(id, "u-") && IsHex(absl::string_view(id).substr(2), 24) &&
         absl::AsciiStrToLower(id) == id;
}

std::string WorkPath(const std::string& dir, const std::string& id, const char* suffix) {
  return (fs::path(dir) / kWorkDir / (id + suffix)).string();
}

std::string FinalPath(const std::string& dir, const std::string& name) {
  return (fs::path(dir) / kFinalDir / name).string();
}

// uploads/ and .uploads/ must be folders of their own: a symlink planted there would have the
// coordinator write outside the tenant's folder.
absl::Status EnsurePlainFolder(const std::string& dir, const char* sub) {
  const std::string path = (fs::path(dir) / sub).string();
  struct stat st;
  if (::lstat(path.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) return absl::OkStatus();
    return absl::FailedPreconditionError(
        absl::StrCat(sub, "/ in the tenant's folder is not a folder (a link or a file)"));
  }
  if (errno != ENOENT) {
    return absl::InternalError(absl::StrCat(sub, "/: ", std::strerror(errno)));
  }
  if (::mkdir(path.c_str(), 0750) != 0 && errno != EEXIST) {
    return absl::InternalError(
        absl::StrCat("cannot create ", sub, "/ in the tenant's folder: ", std::strerror(errno)));
  }
  return SyncFolderOf(path);
}

absl::Status WriteRecord(const std::string& dir, const UploadState& s) {
  const nlohmann::json j = {{"name", s.name},
                            {"size_bytes", s.size_bytes},
                            {"sha256_hex", s.sha256_hex},
                            {"complete", s.complete}};
  return WriteFileAtomically(WorkPath(dir, s.id, ".json"),
                             [&](std::ostream& out) { out << j.dump() << '\n'; });
}

absl::StatusOr<UploadState> ReadRecord(const std::string& dir, const std::string& id) {
  const std::string path = WorkPath(dir, id, ".json");
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("no upload ", id));
  nlohmann::json j = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  UploadState s;
  s.id = id;
  if (j.is_object() && j.contains("name") && j["name"].is_string() && j.contains("size_bytes") &&
      j["size_bytes"].is_number_integer() && j.contains("sha256_hex") &&
      j["sha256_hex"].is_string() && j.contains("complete") && j["complete"].is_boolean()) {
    s.name = j["name"].get<std::string>();
    s.size_bytes = j["size_bytes"].get<int64_t>();
    s.sha256_hex = j["sha256_hex"].get<std::string>();
    s.complete = j["complete"].get<bool>();
  }
  if (!ValidName(s.name) || s.size_bytes <= 0 || !IsHex(s.sha256_hex, 64)) {
    return absl::DataLossError(absl::StrCat("upload ", id, ": its record ", path, " is corrupt"));
  }
  s.input_path = absl::StrCat(kFinalDir, "/", s.name);
  return s;
}

// -1 when `path` does not exist.
int64_t FileSize(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 ? int64_t{st.st_size} : -1;
}

int64_t MtimeMs(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return -1;
  return int64_t{st.st_mtim.tv_sec} * 1000 + st.st_mtim.tv_nsec / 1000000;
}

}  // namespace

std::string UploadId(const UploadRequest& r) {
  return "u-" + Sha256Hex(absl::StrCat(r.name, "\n", r.size_bytes, "\n",
                                       absl::AsciiStrToLower(r.sha256_hex)))
                    .substr(0, 24);
}

absl::StatusOr<UploadState> UploadStore::Find(const std::string& dir, const std::string& id) {
  if (!ValidId(id)) return absl::NotFoundError(absl::StrCat("no upload ", id));
  absl::StatusOr<UploadState> s = ReadRecord(dir, id);
  if (!s.ok()) return s.status();
  const int64_t final_size = FileSize(FinalPath(dir, s->name));
  if (s->complete) {
    if (final_size != s->size_bytes) {
      return absl::NotFoundError(
          absl::StrCat("upload ", id, ": its file ", s->input_path, " is gone or changed"));
    }
    s->received_bytes = s->size_bytes;
    return s;
  }
  const int64_t partial = FileSize(WorkPath(dir, id, ".partial"));
  if (partial < 0 && final_size == s->size_bytes) {
    // A crash after Finish put the file in place and before it marked the record complete.
    absl::StatusOr<std::string> sha = Sha256HexOfFile(FinalPath(dir, s->name));
    if (sha.ok() && *sha == s->sha256_hex) {
      s->complete = true;
      s->received_bytes = s->size_bytes;
      if (absl::Status w = WriteRecord(dir, *s); !w.ok()) return w;
      return s;
    }
  }
  s->received_bytes = std::max<int64_t>(partial, 0);
  return s;
}

std::vector<UploadState> UploadStore::UnfinishedUploads(const std::string& dir, int64_t now_ms) {
  std::vector<UploadState> kept;
  std::error_code ec;
  for (fs::directory_iterator it(fs::path(dir) / kWorkDir, ec), end; !ec && it != end;
       it.increment(ec)) {
    const std::string file = it->path().filename().string();
    if (!absl::EndsWith(file, ".json")) continue;
    absl::StatusOr<UploadState> s = ReadRecord(dir, file.substr(0, file.size() - 5));
    if (!s.ok() || s->complete) continue;
    const std::string partial = WorkPath(dir, s->id, ".partial");
    const int64_t last_ms = std::max(MtimeMs(partial), MtimeMs(it->path().string()));
    if (last_ms >= 0 && now_ms - last_ms > options_.expire_after_ms &&
        writing_.count(absl::StrCat(dir, "\n", s->id)) == 0) {
      std::error_code rm;
      fs::remove(partial, rm);
      fs::remove(it->path(), rm);
      continue;
    }
    kept.push_back(*std::move(s));
  }
  return kept;
}

absl::StatusOr<UploadState> UploadStore::Start(const std::string& dir, const UploadRequest& r,
                                               int64_t now_ms) {
  if (!ValidName(r.name)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "upload name '", r.name, "': must match [A-Za-z0-9._-]{1,128} and not start with '.'"));
  }
  if (r.size_bytes <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("upload '", r.name, "': size_bytes ", r.size_bytes, " is not positive"));
  }
  if (!IsHex(r.sha256_hex, 64)) {
    return absl::InvalidArgumentError(
        absl::StrCat("upload '", r.name, "': sha256_hex must be 64 hex digits"));
  }
  absl::MutexLock lock(&mu_);
  for (const char* sub : {kFinalDir, kWorkDir}) {
    if (absl::Status s = EnsurePlainFolder(dir, sub); !s.ok()) return s;
  }
  const std::vector<UploadState> unfinished = UnfinishedUploads(dir, now_ms);
  const std::string id = UploadId(r);
  std::error_code ec;
  if (FileSize(WorkPath(dir, id, ".json")) >= 0) {
    absl::StatusOr<UploadState> found = Find(dir, id);
    if (!absl::IsNotFound(found.status())) return found;
    // Finished once, and its file removed since: start it again.
    fs::remove(WorkPath(dir, id, ".partial"), ec);
    fs::remove(WorkPath(dir, id, ".json"), ec);
  }

  struct stat st;
  if (::lstat(FinalPath(dir, r.name).c_str(), &st) == 0) {
    return absl::AlreadyExistsError(absl::StrCat(
        kFinalDir, "/", r.name, " already exists (another file): choose another name"));
  }
  // What the tenant holds: finished files, and what the unfinished uploads announced.
  int64_t used = 0;
  for (fs::directory_iterator it(fs::path(dir) / kFinalDir, ec), end; !ec && it != end;
       it.increment(ec)) {
    if (it->is_regular_file(ec)) used += std::max<int64_t>(FileSize(it->path().string()), 0);
  }
  for (const UploadState& other : unfinished) {
    if (other.name == r.name) {
      return absl::AlreadyExistsError(
          absl::StrCat("an upload of ", r.name, " with another size or SHA-256 is unfinished (",
                       other.id, "); it expires after ", options_.expire_after_ms / 3600000,
                       " h without data, or choose another name"));
    }
    used += other.size_bytes;
  }
  if (options_.quota_bytes > 0 && used + r.size_bytes > options_.quota_bytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "upload '", r.name, "' of ", r.size_bytes, " bytes: the tenant's uploads hold ", used,
        " bytes of a quota of ", options_.quota_bytes, " (remove finished uploads to make room)"));
  }
  struct statvfs vfs;
  const std::string work = (fs::path(dir) / kWorkDir).string();
  if (::statvfs(work.c_str(), &vfs) == 0 &&
      static_cast<double>(vfs.f_bavail) * static_cast<double>(vfs.f_frsize) <
          static_cast<double>(r.size_bytes)) {
    return absl::ResourceExhaustedError(
        absl::StrCat("upload '", r.name, "' of ", r.size_bytes, " bytes: the server's disk has ",
                     uint64_t{vfs.f_bavail} * vfs.f_frsize, " bytes free"));
  }

  UploadState s;
  s.id = id;
  s.name = r.name;
  s.input_path = absl::StrCat(kFinalDir, "/", r.name);
  s.size_bytes = r.size_bytes;
  s.sha256_hex = absl::AsciiStrToLower(r.sha256_hex);
  // The partial first: a record always has its data file (or its finished file).
  const std::string partial = WorkPath(dir, id, ".partial");
  const int fd = ::open(partial.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
  if (fd < 0) {
    return absl::InternalError(
        absl::StrCat("upload ", id, ": cannot create its data file: ", std::strerror(errno)));
  }
  ::close(fd);
  if (absl::Status w = WriteRecord(dir, s); !w.ok()) {
    fs::remove(partial, ec);
    return w;
  }
  return s;
}

absl::StatusOr<std::unique_ptr<UploadWriter>> UploadStore::OpenWriter(const std::string& dir,
                                                                      const std::string& id) {
  absl::MutexLock lock(&mu_);
  absl::StatusOr<UploadState> s = Find(dir, id);
  if (!s.ok()) return s.status();
  const std::string key = absl::StrCat(dir, "\n", id);
  if (!writing_.insert(key).second) {
    return absl::AbortedError(
        absl::StrCat("upload ", id, " is being written by another stream; retry when it ends"));
  }
  int fd = -1;
  if (!s->complete) {
    fd = ::open(WorkPath(dir, id, ".partial").c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0640);
    if (fd < 0) {
      writing_.erase(key);
      return absl::InternalError(
          absl::StrCat("upload ", id, ": cannot open its data file: ", std::strerror(errno)));
    }
  }
  return std::unique_ptr<UploadWriter>(new UploadWriter(this, dir, key, *std::move(s), fd));
}

void UploadStore::Release(const std::string& key) {
  absl::MutexLock lock(&mu_);
  writing_.erase(key);
}

UploadWriter::~UploadWriter() {
  if (fd_ >= 0) ::close(fd_);
  store_->Release(key_);
}

absl::StatusOr<UploadState> UploadWriter::Append(int64_t offset, absl::string_view data) {
  UploadState& s = state_;
  if (s.complete) {
    return absl::FailedPreconditionError(absl::StrCat("upload ", s.id, " is complete"));
  }
  if (offset != s.received_bytes) {
    return absl::FailedPreconditionError(absl::StrCat("upload ", s.id, ": data for offset ", offset,
                                                      ", but the server holds ", s.received_bytes,
                                                      " bytes: resume from ", s.received_bytes));
  }
  if (static_cast<int64_t>(data.size()) > s.size_bytes - s.received_bytes) {
    return absl::InvalidArgumentError(
        absl::StrCat("upload ", s.id, ": ", data.size(), " bytes at offset ", offset,
                     " go past its announced size of ", s.size_bytes, " bytes"));
  }
  size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::pwrite(fd_, data.data() + done, data.size() - done,
                               static_cast<off_t>(offset + static_cast<int64_t>(done)));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      // The file's size is where a resume starts: cut back what this piece half wrote.
      if (::ftruncate(fd_, static_cast<off_t>(s.received_bytes)) != 0) {
        // Nothing better to do: the size then says more than arrived, and the SHA-256 at
        // the end refuses the file.
      }
      const std::string why = absl::StrCat("upload ", s.id, ": cannot write at offset ", offset,
                                           ": ", std::strerror(err));
      return (err == ENOSPC || err == EDQUOT) ? absl::ResourceExhaustedError(why)
                                              : absl::InternalError(why);
    }
    done += static_cast<size_t>(n);
  }
  s.received_bytes += static_cast<int64_t>(data.size());
  return s;
}

absl::StatusOr<UploadState> UploadWriter::Finish() {
  UploadState& s = state_;
  if (s.complete) return s;
  if (s.received_bytes != s.size_bytes) {
    return absl::FailedPreconditionError(
        absl::StrCat("upload ", s.id, " holds ", s.received_bytes, " of ", s.size_bytes, " bytes"));
  }
  const std::string partial = WorkPath(dir_, s.id, ".partial");
  const std::string final_path = FinalPath(dir_, s.name);
  if (::fsync(fd_) != 0) {
    return absl::InternalError(
        absl::StrCat("upload ", s.id, ": cannot sync its data: ", std::strerror(errno)));
  }
  ::close(fd_);
  fd_ = -1;
  absl::StatusOr<std::string> sha = Sha256HexOfFile(partial);
  if (!sha.ok()) return sha.status();
  std::error_code ec;
  if (*sha != s.sha256_hex) {
    fs::remove(partial, ec);
    fs::remove(WorkPath(dir_, s.id, ".json"), ec);
    return absl::DataLossError(absl::StrCat(
        "upload ", s.id, ": the ", s.size_bytes, " bytes received have SHA-256 ", *sha,
        ", not the announced ", s.sha256_hex, "; they were dropped: upload the file again"));
  }
  // link(2) fails rather than replace a file that appeared at the final name meanwhile.
  if (::link(partial.c_str(), final_path.c_str()) != 0) {
    const int err = errno;
    if (err == EEXIST) {
      return absl::AlreadyExistsError(absl::StrCat(s.input_path, " appeared while ", s.id,
                                                   " was uploading: choose another "
                                                   "name, or remove it and resume"));
    }
    return absl::InternalError(
        absl::StrCat("upload ", s.id, ": cannot create ", s.input_path, ": ", std::strerror(err)));
  }
  if (absl::Status sync = SyncFolderOf(final_path); !sync.ok()) return sync;
  fs::remove(partial, ec);
  s.complete = true;
  // The record last: until it says complete, Find recognizes the finished file by its hash.
  if (absl::Status w = WriteRecord(dir_, s); !w.ok()) return w;
  return s;
}

}  // namespace carvemap
