// A lease's id, "<job_id>/<x>,<y>,<z>/<generation>" (docs/RPC.md): unique, since a task's
// generation is never reused, and self-describing, so a lease granted before a restart still
// names its job and task. The one place that builds and reads the text.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "storage/job_store.h"  // ChunkCoord

namespace carvemap {

struct LeaseId {
  std::string job_id;      // not empty; may itself contain '/'
  ChunkCoord chunk;        // the task's key (a chunk, or a slice: SliceTaskKey)
  int64_t generation = 0;  // ≥ 1

  // Split from the right, so that a job id holding '/' reads back. InvalidArgument, quoting
  // the text, for anything ToString does not make.
  static absl::StatusOr<LeaseId> Parse(absl::string_view text);
  [[nodiscard]] std::string ToString() const;
  bool operator==(const LeaseId&) const = default;
};

}  // namespace carvemap
