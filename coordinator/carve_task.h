// What a worker is given with a lease (docs/RPC.md "Slices"; carve.proto Lease): the task's
// key and lease, the carve's parameters, and either a slice to carve (the scan's rows to read
// and to vote with, where to write its partial sums, a re-carve's regions) or a chunk to
// combine (every partial-sums file of the pass, in slice order). Plain data, made from a
// granted lease and the job's runtime; the service turns it into the Lease message.
#pragma once

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include "absl/status/statusor.h"
#include "coordinator/job_runtime.h"
#include "coordinator/lease_table.h"
#include "storage/scan_reader.h"

namespace carvemap {

struct SliceWork {
  uint32_t index = 0;
  int pass = 0;  // 0: the job's carve; 1, 2, …: §5.6.1's re-carves of object chunks
  // The scan, opened confined to the tenant's folder: `scan_root` (absolute) and `scan_path`
  // (as the job names it).
  std::string scan_root, scan_path;
  std::vector<ScanReader::RowRange> own, read;
  uint64_t own_rays = 0;
  std::string partial_path;  // where the slice's sums go
  std::string regions_path;  // a re-carve's regions; "" in the job's carve
};

struct CombineWork {
  std::vector<std::string> partial_paths;  // every slice of the pass, in slice order
};

struct CarveTask {
  LeaseTable::Grant grant;
  double resolution_m = 0;
  CarveMethod method = CarveMethod::kProbabilistic;
  int leaf_depth = 0;  // the chunk's depth at resolution_m; 0 when the resolution is not 2 m / 2^k
  std::string tile_dir;
  CarveEvaluation evaluation = CarveEvaluation::kFast;
  double world_yaw_rad = 0;  // §2.3's turn to north
  std::variant<SliceWork, CombineWork> work;
};

// The task of `grant` in the job whose runtime is `rt` (its pass, folders and plan);
// `scan_root`: the tenant's data folder, absolute. Internal when a slice task names a slice
// the plan does not have.
[[nodiscard]] absl::StatusOr<CarveTask> CarveTaskOf(const LeaseTable::Grant& grant,
                                                    const JobRuntime& rt,
                                                    const std::string& scan_root);

}  // namespace carvemap
