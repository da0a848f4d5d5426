// Paths named by a client, confined to a root directory (docs/DESIGN.md §8: "a token sees only its
// own tenant's jobs and paths"). A client may name a file under its root, through symlinks that
// stay under the root; nothing it names may reach a file outside, and no answer may tell it
// whether a file outside exists.
//
// Error codes (docs/RPC.md, "Paths"):
//   INVALID_ARGUMENT   the text itself is not a confined path: empty, absolute, a ".."
//                      component, a NUL byte, longer than kMaxConfinedPathBytes. Decided from
//                      the text alone; nothing on disk is looked at.
//   PERMISSION_DENIED  a symlink under the root leads outside it. Decided from the link's own
//                      text before anything outside is looked at, so the message and code are
//                      the same whether the target exists or not.
//   NOT_FOUND          a component does not exist under the root, or is not readable.
// Messages name the path as the client gave it (`what` 'relative'), never the root or a
// symlink's target.
#ifndef CARVEMAP_STORAGE_CONFINED_PATH_H_
#define CARVEMAP_STORAGE_CONFINED_PATH_H_

#include <atomic>
#include <functional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace carvemap {

inline constexpr size_t kMaxConfinedPathBytes = 1024;

// The lexical checks above (INVALID_ARGUMENT "<what> '<relative>': ...").
absl::Status CheckConfinedPathText(absl::string_view relative, absl::string_view what);

// Resolves `relative` under `root` one component at a time, following symlinks (at most 40)
// the way the kernel would, but refusing any step that would leave the root. `root` must be
// an existing directory; it is canonicalised first (the root itself may be a symlink: the
// administrator chose it). Returns the absolute resolved path, which lies under the
// canonical root (or is the root). Does not require the final component to be a file.
absl::StatusOr<std::string> ResolveConfinedPath(const std::string& root,
                                                absl::string_view relative,
                                                absl::string_view what);

// A regular file under a root, opened and held open. `path()` is "/proc/self/fd/<n>": it
// names exactly the opened file for as long as this object lives, so code that opens files
// by name (HDF5) reads the file that was checked, even if a symlink on the way is swapped
// afterwards. A link swapped in between the resolution and the open is caught twice: the
// open itself is openat2(2) beneath the root with RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS
// where the kernel has it (Linux 5.6), so the kernel refuses any step out of the root while it
// opens; and after the open the kernel's own name of the file is checked to lie under the
// root again (the only check on older kernels).
// Move-only; closes the file on destruction. Linux only (/proc).
class ConfinedFile {
 public:
  // Errors as above; a directory or special file is NOT_FOUND ("not a regular file").
  static absl::StatusOr<ConfinedFile> Open(const std::string& root, absl::string_view relative,
                                           absl::string_view what);
  ConfinedFile(ConfinedFile&& other) noexcept;
  ConfinedFile& operator=(ConfinedFile&& other) noexcept;
  ConfinedFile(const ConfinedFile&) = delete;
  ConfinedFile& operator=(const ConfinedFile&) = delete;
  ~ConfinedFile();

  [[nodiscard]] int fd() const { return fd_; }
  [[nodiscard]] const std::string& path() const { return proc_path_; }
  [[nodiscard]] int64_t size_bytes() const { return size_bytes_; }
  // Replaces path() in `status`'s message by the name the client gave, so errors of code
  // that opened path() read as the client's own path. When the file has been removed since it
  // was opened, NOT_FOUND "... no such file (removed while it was read: <message>)", whatever
  // `status` was.
  [[nodiscard]] absl::Status Rename(const absl::Status& status) const;

 private:
  ConfinedFile(int fd, std::string what, std::string relative, int64_t size_bytes);
  int fd_ = -1;
  std::string what_;
  std::string relative_;
  std::string proc_path_;
  int64_t size_bytes_ = 0;
};

// For tests of the race between resolution and open: `between` runs after ResolveConfinedPath
// and before the open; with `no_openat2` the open is a plain open(2), as on a kernel without
// openat2; `beneath_refusals` counts the opens openat2 refused for leaving the root (atomic:
// every open in the process counts, from any thread). Set `between` and `no_openat2` only
// while no other thread opens.
struct ConfinedOpenTestHooks {
  std::function<void()> between;
  bool no_openat2 = false;
  std::atomic<int> beneath_refusals{0};
};
ConfinedOpenTestHooks& ConfinedOpenHooksForTest();

}  // namespace carvemap

#endif  // CARVEMAP_STORAGE_CONFINED_PATH_H_
