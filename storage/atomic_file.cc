#include "storage/atomic_file.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "absl/strings/str_cat.h"

namespace carvemap {

std::string PartialPath(const std::string& path) { return path + ".partial"; }

absl::Status CommitPartial(const std::string& path) {
  std::error_code ec;
  std::filesystem::rename(PartialPath(path), path, ec);
  if (!ec) return absl::OkStatus();
  std::filesystem::remove(PartialPath(path), ec);
  return absl::InternalError(absl::StrCat(path, ": rename into place failed: ", ec.message()));
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
      // The stream keeps no error code; errno still holds the failed write(2)'s (ENOSPC,
      // EDQUOT, EIO...), which is the reason a user can act on.
      const int err = errno;
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      return absl::DataLossError(absl::StrCat(
          path, ": write failed: ", err != 0 ? std::strerror(err) : "unknown error (disk full?)"));
    }
  }
  return CommitPartial(path);
}

}  // namespace carvemap
