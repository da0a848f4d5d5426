// Files that appear complete or not at all (docs/DESIGN.md §5, "a failed job leaves no half-written
// output that looks complete"): data goes to "<path>.partial", renamed into place when done.
//
// Durable too (docs/JOB_STORE.md, "Durability"): a rename alone is ordered after the data by
// no file system; after a power loss ext4 or XFS may show the new name over missing or zeroed
// blocks. So the data is fsynced before the rename and the folder after it: once a commit
// returns, the file survives a crash whole, and a step that trusts it (the job store marking a
// task done, the user reading job.json) can only come later.
#pragma once

#include <functional>
#include <ostream>
#include <string>

#include "absl/status/status.h"

namespace carvemap {

[[nodiscard]] std::string PartialPath(const std::string& path);

// fsync(2) of a file or a folder. Errors name the path.
absl::Status SyncPath(const std::string& path);
// SyncPath of the folder holding `path` (what makes a rename or a new name durable).
absl::Status SyncFolderOf(const std::string& path);

// Renames `from` to `to` durably: syncs `from`'s data, renames, then syncs the folder holding
// `to` (the rename itself). On failure `from` is left for the caller to remove, and `to` is
// gone if the failure came after the rename.
absl::Status RenameDurably(const std::string& from, const std::string& to);

// RenameDurably(PartialPath(path), path). On failure removes the partial file.
absl::Status CommitPartial(const std::string& path);

// The error for a failed stream write to `path`: a stream keeps no error code, but errno,
// cleared before the writes, still holds the failed write(2)'s (ENOSPC, EDQUOT, EIO...), the
// reason a user can act on. DataLoss.
[[nodiscard]] absl::Status StreamWriteError(const std::string& path, int err);

// Writes through PartialPath(path) with `write`, then commits. Errors name `path`; on any
// failure no file is left at either name.
absl::Status WriteFileAtomically(const std::string& path,
                                 const std::function<void(std::ostream&)>& write);

}  // namespace carvemap
