#include "storage/atomic_file.h"

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
    write(out);
    out.flush();
    if (!out) {
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      return absl::DataLossError(absl::StrCat(path, ": write failed (disk full?)"));
    }
  }
  return CommitPartial(path);
}

}  // namespace carvemap
