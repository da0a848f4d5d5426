// Files that appear complete or not at all (docs/DESIGN.md §5, "a failed job leaves no half-written
// output that looks complete"): data goes to "<path>.partial", renamed into place when done.
#pragma once

#include <functional>
#include <ostream>
#include <string>

#include "absl/status/status.h"

namespace carvemap {

[[nodiscard]] std::string PartialPath(const std::string& path);

// Renames PartialPath(path) to `path`. On failure removes the partial file.
absl::Status CommitPartial(const std::string& path);

// Writes through PartialPath(path) with `write`, then commits. Errors name `path`; on any
// failure no file is left at either name.
absl::Status WriteFileAtomically(const std::string& path,
                                 const std::function<void(std::ostream&)>& write);

}  // namespace carvemap
