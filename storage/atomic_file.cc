#include "storage/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "absl/strings/str_cat.h"

namespace carvemap {

std::string PartialPath(const std::string& path) { return path + ".partial"; }

absl::Status SyncPath(const std::string& path) {
  // O_RDONLY works for folders and files alike; fsync needs no write access on Linux.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    return absl::InternalError(absl::StrCat(path, ": cannot open to sync: ", std::strerror(err)));
  }
  int rc;
  do {
    rc = ::fsync(fd);
  } while (rc != 0 && errno == EINTR);
  const int err = errno;
  ::close(fd);
  if (rc != 0) {
    // EIO here means the data did not reach the disk: the file must not be trusted.
    return absl::DataLossError(absl::StrCat(path, ": fsync failed: ", std::strerror(err)));
  }
  return absl::OkStatus();
}

absl::Status SyncFolderOf(const std::string& path) {
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  return SyncPath(dir.empty() ? std::string(".") : dir.string());
}

absl::Status RenameDurably(const std::string& from, const std::string& to) {
  if (absl::Status s = SyncPath(from); !s.ok()) return s;
  std::error_code ec;
  std::filesystem::rename(from, to, ec);
  if (ec) {
    return absl::InternalError(
        absl::StrCat(from, ": cannot rename to ", to, ": ", ec.message()));
  }
  absl::Status s = SyncFolderOf(to);
  if (!s.ok()) std::filesystem::remove(to, ec);  // not known to be durable: not complete
  return s;
}

absl::Status CommitPartial(const std::string& path) {
  absl::Status s = RenameDurably(PartialPath(path), path);
  if (s.ok()) return s;
  std::error_code ec;
  std::filesystem::remove(PartialPath(path), ec);
  return absl::Status(s.code(), absl::StrCat(path, ": commit failed: ", s.message()));
}

absl::Status StreamWriteError(const std::string& path, int err) {
  return absl::DataLossError(absl::StrCat(
      path, ": write failed: ", err != 0 ? std::strerror(err) : "unknown error (disk full?)"));
}

absl::Status WriteFileAtomically(const std::string& path,
                                 const std::function<void(std::ostream&)>& write) {
  const std::string tmp = PartialPath(path);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for writing"));
    errno = 0;
    write(out);
    out.flush();
    if (!out) {
      const int err = errno;
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      return StreamWriteError(path, err);
    }
  }
  return CommitPartial(path);
}

}  // namespace carvemap
