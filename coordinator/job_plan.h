// A job's plan (docs/RPC.md "Slices"): its time slices and §2.3's turn to north, made from the
// scan's frame tables when the job is ingested (and made again, the same, after a restart);
// the slices as tasks; and the chunks a pass's partial sums name, which become its combine
// tasks. Plain functions over the scan and the partial-sums files.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "coordinator/job_params.h"
#include "coordinator/scan_north.h"
#include "coordinator/scan_slices.h"
#include "storage/job_store.h"

namespace carvemap {

struct JobPlan {
  ScanSlicePlan slices;
  ScanNorth north;
};

// Reads the frame tables of the scan at `scan_path` (the path is validated in blocks and not
// held: the workers read the poses their slices need), plans its slices and decides the turn
// to north by `params` (north mode, location and survey date). Not thread-safe with other
// HDF5 calls (storage/hdf5_lock.h). Errors: the reader's, PlanScanSlices' and NorthOfScan's,
// naming the file as opened.
[[nodiscard]] absl::StatusOr<JobPlan> PlanJob(const std::string& scan_path,
                                              const JobParams& params);

// The tasks of pass `pass`'s slices: keys SliceTaskKey(index, pass), each slice's own rays as
// its size (the store's listing shows it).
[[nodiscard]] std::vector<ChunkRecord> SliceTasks(const std::string& job_id,
                                                  std::span<const ScanSlice> slices, int pass);

// "<dir>/slice_<index>.part": where a pass's slice writes its partial sums.
[[nodiscard]] std::string SlicePartialPath(const std::string& dir, uint32_t index);

// The chunks that the partial-sums files at `paths` hold sections of (storage/
// PARTIAL_FORMAT.md), sorted and each once. Errors: ReadPartialIndex's, naming the file.
[[nodiscard]] absl::StatusOr<std::vector<ChunkCoord>> ChunksOfPartials(
    std::span<const std::string> paths);

}  // namespace carvemap
