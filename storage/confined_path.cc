#include "storage/confined_path.h"

#include <fcntl.h>
#include <limits.h>
#include <linux/openat2.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"

namespace carvemap {
namespace {

// Linux's own limit on symlinks followed in one lookup (MAXSYMLINKS); a loop ends here.
constexpr int kMaxSymlinks = 40;

std::vector<std::string> Components(absl::string_view path) {
  std::vector<std::string> out;
  for (absl::string_view part : absl::StrSplit(path, '/', absl::SkipEmpty())) {
    if (part != ".") out.emplace_back(part);
  }
  return out;
}

std::string Quoted(absl::string_view what, absl::string_view relative) {
  return absl::StrCat(what, " '", relative, "'");
}

absl::Status NotFound(absl::string_view what, absl::string_view relative) {
  return absl::NotFoundError(absl::StrCat(Quoted(what, relative), ": no such file"));
}

// One message for every escape, whatever lies outside.
absl::Status Escapes(absl::string_view what, absl::string_view relative) {
  return absl::PermissionDeniedError(
      absl::StrCat(Quoted(what, relative), ": a symlink on the way leads outside the allowed "
                                           "directory"));
}

absl::StatusOr<std::string> CanonicalRoot(const std::string& root, absl::string_view what,
                                          absl::string_view relative) {
  char buf[PATH_MAX];
  if (root.empty() || ::realpath(root.c_str(), buf) == nullptr) return NotFound(what, relative);
  struct stat st {};
  if (::stat(buf, &st) != 0 || !S_ISDIR(st.st_mode)) return NotFound(what, relative);
  return std::string(buf);
}

bool UnderRoot(const std::string& path, const std::string& root) {
  if (root == "/") return !path.empty() && path.front() == '/';
  return path == root || (path.size() > root.size() && path.compare(0, root.size(), root) == 0 &&
                          path[root.size()] == '/');
}

}  // namespace

absl::Status CheckConfinedPathText(absl::string_view relative, absl::string_view what) {
  if (relative.size() > kMaxConfinedPathBytes) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": longer than ",
                                                   kMaxConfinedPathBytes, " bytes"));
  }
  if (relative.find('\0') != absl::string_view::npos) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": contains a NUL byte"));
  }
  if (relative.empty()) return absl::InvalidArgumentError(absl::StrCat(what, ": empty"));
  if (relative.front() == '/') {
    return absl::InvalidArgumentError(
        absl::StrCat(Quoted(what, relative), ": must be relative, not absolute"));
  }
  for (absl::string_view part : absl::StrSplit(relative, '/')) {
    if (part == "..") {
      return absl::InvalidArgumentError(
          absl::StrCat(Quoted(what, relative), ": must not contain '..'"));
    }
  }
  return absl::OkStatus();
}

namespace {

// The walk of ResolveConfinedPath, under `base`, the root already made canonical.
absl::StatusOr<std::string> ResolveUnder(const std::string& base, absl::string_view relative,
                                         absl::string_view what) {
  const std::vector<std::string> base_parts = Components(base);

  // `resolved`: components under the root reached so far (never a symlink); `pending`: what
  // is left to walk, next component last.
  std::vector<std::string> resolved;
  std::vector<std::string> pending = Components(relative);
  std::reverse(pending.begin(), pending.end());
  int links = 0;
  auto current = [&](const std::string& next) {
    std::string p = base == "/" ? "" : base;
    for (const std::string& c : resolved) absl::StrAppend(&p, "/", c);
    return absl::StrCat(p, "/", next);
  };
  while (!pending.empty()) {
    std::string part = std::move(pending.back());
    pending.pop_back();
    if (part == "..") {  // only from a symlink's text: one level up, never above the root
      if (resolved.empty()) return Escapes(what, relative);
      resolved.pop_back();
      continue;
    }
    // Everything looked at here lies under the root: `resolved` is, and `part` is a plain name.
    const std::string candidate = current(part);
    struct stat st {};
    if (::lstat(candidate.c_str(), &st) != 0) return NotFound(what, relative);
    if (S_ISLNK(st.st_mode)) {
      if (++links > kMaxSymlinks) {
        return absl::InvalidArgumentError(
            absl::StrCat(Quoted(what, relative), ": too many levels of symbolic links"));
      }
      char target[PATH_MAX];
      const ssize_t n = ::readlink(candidate.c_str(), target, sizeof(target) - 1);
      if (n <= 0) return NotFound(what, relative);
      const absl::string_view text(target, static_cast<size_t>(n));
      std::vector<std::string> parts = Components(text);
      if (text.front() == '/') {
        // An absolute target must spell the canonical root (checked on its text: nothing
        // outside is looked at); what follows is walked under the root like the rest.
        if (parts.size() < base_parts.size() ||
            !std::equal(base_parts.begin(), base_parts.end(), parts.begin())) {
          return Escapes(what, relative);
        }
        parts.erase(parts.begin(), parts.begin() + static_cast<ptrdiff_t>(base_parts.size()));
        resolved.clear();
      }
      pending.insert(pending.end(), parts.rbegin(), parts.rend());
      continue;
    }
    if (!pending.empty() && !S_ISDIR(st.st_mode)) return NotFound(what, relative);
    resolved.push_back(std::move(part));
  }
  std::string out = base;
  for (const std::string& c : resolved) {
    if (out != "/") out.push_back('/');
    out += c;
  }
  return out;
}

}  // namespace

absl::StatusOr<std::string> ResolveConfinedPath(const std::string& root,
                                                absl::string_view relative,
                                                absl::string_view what) {
  if (absl::Status s = CheckConfinedPathText(relative, what); !s.ok()) return s;
  absl::StatusOr<std::string> base = CanonicalRoot(root, what, relative);
  if (!base.ok()) return base.status();
  return ResolveUnder(*base, relative, what);
}

// ---- ConfinedFile

ConfinedFile::ConfinedFile(int fd, std::string what, std::string relative, int64_t size_bytes)
    : fd_(fd),
      what_(std::move(what)),
      relative_(std::move(relative)),
      proc_path_(absl::StrCat("/proc/self/fd/", fd)),
      size_bytes_(size_bytes) {}

ConfinedFile::ConfinedFile(ConfinedFile&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      what_(std::move(other.what_)),
      relative_(std::move(other.relative_)),
      proc_path_(std::move(other.proc_path_)),
      size_bytes_(other.size_bytes_) {}

ConfinedFile& ConfinedFile::operator=(ConfinedFile&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
    what_ = std::move(other.what_);
    relative_ = std::move(other.relative_);
    proc_path_ = std::move(other.proc_path_);
    size_bytes_ = other.size_bytes_;
  }
  return *this;
}

ConfinedFile::~ConfinedFile() {
  if (fd_ >= 0) ::close(fd_);
}

absl::Status ConfinedFile::Rename(const absl::Status& status) const {
  if (status.ok() || proc_path_.empty()) return status;
  std::string message = absl::StrReplaceAll(status.message(), {{proc_path_, relative_}});
  // Removed since it was opened: code that reopens path() by name (HDF5 resolves the link to
  // the file's real name, which is gone) reports errors about the contents; the cause is that
  // the file no longer exists.
  struct stat st;
  if (fd_ >= 0 && ::fstat(fd_, &st) == 0 && st.st_nlink == 0) {
    return absl::NotFoundError(absl::StrCat(Quoted(what_, relative_),
                                            ": no such file (removed while it was read: ",
                                            message, ")"));
  }
  return absl::Status(status.code(), std::move(message));
}

ConfinedOpenTestHooks& ConfinedOpenHooksForTest() {
  static ConfinedOpenTestHooks hooks;
  return hooks;
}

namespace {

// openat2(2) of `path` (under `base`, the canonical root) relative to the root, the kernel
// refusing to leave it (EXDEV) or to follow /proc's magic links. glibc 2.36 has no wrapper.
// -1 with errno ENOSYS where the kernel lacks the call (or a seccomp filter hides it).
int OpenBeneath(const std::string& base, const std::string& path, int flags) {
  if (ConfinedOpenHooksForTest().no_openat2) {
    errno = ENOSYS;
    return -1;
  }
  const int root_fd = ::open(base.c_str(), O_PATH | O_DIRECTORY | O_CLOEXEC);
  if (root_fd < 0) return -1;
  std::string rel = path.size() > base.size() ? path.substr(base.size()) : std::string(".");
  if (base != "/" && !rel.empty() && rel.front() == '/') rel.erase(0, 1);
  open_how how{};
  how.flags = uint64_t(flags);
  how.resolve = RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS;
  const int fd = int(::syscall(SYS_openat2, root_fd, rel.c_str(), &how, sizeof(how)));
  const int err = errno;
  ::close(root_fd);
  errno = err;
  return fd;
}

}  // namespace

absl::StatusOr<ConfinedFile> ConfinedFile::Open(const std::string& root,
                                                absl::string_view relative,
                                                absl::string_view what) {
  if (absl::Status s = CheckConfinedPathText(relative, what); !s.ok()) return s;
  absl::StatusOr<std::string> base = CanonicalRoot(root, what, relative);
  if (!base.ok()) return base.status();
  absl::StatusOr<std::string> path = ResolveUnder(*base, relative, what);
  if (!path.ok()) return path.status();
  if (ConfinedOpenHooksForTest().between) ConfinedOpenHooksForTest().between();
  // O_NOFOLLOW: the last component was not a link when resolved and must not be one now;
  // O_NONBLOCK: a FIFO planted under the root does not hang the open.
  const int flags = O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK;
  int fd = OpenBeneath(*base, *path, flags);
  if (fd < 0 && errno == EXDEV) {
    ConfinedOpenHooksForTest().beneath_refusals.fetch_add(1, std::memory_order_relaxed);
    return Escapes(what, relative);  // a link swapped in meanwhile leads out
  }
  if (fd < 0 && (errno == ENOSYS || errno == EPERM)) fd = ::open(path->c_str(), flags);
  if (fd < 0) {
    if (errno == ELOOP) return Escapes(what, relative);  // swapped for a link meanwhile
    return NotFound(what, relative);
  }
  ConfinedFile file(fd, std::string(what), std::string(relative), 0);
  // What the kernel says the open file is: it must still be under the root (with openat2 a
  // second check; without it the only one).
  char real[PATH_MAX];
  const ssize_t n = ::readlink(file.proc_path_.c_str(), real, sizeof(real) - 1);
  if (n <= 0 ||
      !UnderRoot(std::string(real, static_cast<size_t>(n)), *base)) {
    return Escapes(what, relative);
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    return absl::NotFoundError(absl::StrCat(Quoted(what, relative), ": not a regular file"));
  }
  const int status_flags = ::fcntl(fd, F_GETFL);
  if (status_flags >= 0) ::fcntl(fd, F_SETFL, status_flags & ~O_NONBLOCK);
  file.size_bytes_ = static_cast<int64_t>(st.st_size);
  return file;
}

}  // namespace carvemap
