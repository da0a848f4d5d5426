// The merge step of a job as the coordinator sees it (docs/DESIGN.md §6, §8): what it hands over
// (MergeJobRequest) and the function that runs it (MergeFunction). Two implementations:
// LocalMerge() runs RunMerge (services/merge/merge_job.h) in the calling process — what a
// `carvemap merger` runs for each call, and what the in-process tests give the coordinator —
// and RemoteMerge() (services/rpc/merge_client.h) calls a merge service over MergeService
// (proto/carvemap/v1/merge.proto), which is what `carvemap coordinator` uses.
// Plain header: no gRPC.
#ifndef CARVEMAP_SERVICES_RPC_MERGE_REQUEST_H_
#define CARVEMAP_SERVICES_RPC_MERGE_REQUEST_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/chunk_region.h"
#include "services/merge/merge_params.h"

namespace carvemap {

// What the merge step gets: the job's tiles and where the outputs go.
struct MergeJobRequest {
  std::string job_id;
  std::string tiles_dir;   // the committed tiles of every chunk
  std::string output_dir;  // octree.bt, level_0/, job.json go here
  // The job's input scan.h5 (the merge reads its /path): `scan_input` as the tenant named it,
  // resolved under `scan_root` (the tenant's data folder) by the merge, confined as at submit
  // (storage/confined_path.h), so that a symlink swapped since cannot redirect the read and
  // errors name the tenant's path. Both empty: no scan (no floor plans).
  std::string scan_root;
  std::string scan_input;
  // What the merge makes (resolutions, floor-plan method, points.ply, specks, the turn to
  // north). Its object_resolution_m is carved by `recarve`: the coordinator leases the object
  // chunks to its workers once more, each limited to its region, and returns the directory of
  // their tiles. No `recarve`: no re-carving.
  MergeParams params;
  std::function<absl::StatusOr<std::string>(const std::vector<RecarveChunk>& chunks,
                                            double resolution_m)>
      recarve;
  std::string job_json;  // the job document (id, input, parameters, counts) as JSON text
  // Called by the merge as it goes (stage name, done, total); false = stop (job cancelled or
  // coordinator stopping): the merge then returns Cancelled. May be empty. RemoteMerge also
  // calls it every 250 ms between the service's reports (and while it waits for a service),
  // so a cancelled job stops promptly; calls never overlap.
  std::function<bool(const std::string& stage, uint64_t done, uint64_t total)> progress;
  // 1-based try of this job's merge (RemoteMerge counts the services lost); for logs.
  int attempt = 1;
};

// OK: every output written, job.json last. Cancelled: `progress` said stop. Any other error
// fails the job with its message.
using MergeFunction = std::function<absl::Status(const MergeJobRequest&)>;

// RunMerge in this process. Not thread-safe with other HDF5 use in the process: callers
// serialize (the coordinator with its HDF5 lock, the merge service one merge at a time).
// memory_budget_bytes: MergeOptions::memory_budget_bytes (0: none).
MergeFunction LocalMerge(uint64_t memory_budget_bytes = 0);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_MERGE_REQUEST_H_
