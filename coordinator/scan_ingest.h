// Ingest (DESIGN §5): stream a scan.h5's frames (never the whole scan in memory), build the
// wedges of every sensor (§4.1.1, §4.3.1), and spill them into per-chunk files that workers
// carve. The coordinator service runs this once per job; `carvemap carve` runs it in-process.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "coordinator/chunk_spill.h"
#include "coordinator/wedge_builder.h"

namespace carvemap {

struct IngestOptions {
  std::string scan_path;                     // scan.h5 (DESIGN §3); validated before use
  std::string spill_dir;                     // receives one wedge file per chunk
  WedgeBuilderOptions wedges;                // noise model and wedge rules
  size_t memory_budget_bytes = 256u << 20;   // spill buffers (bounded whatever the scan size)
  double sigmas = 3.0;                       // §4.3.1: wedges extend 3σ past their points
  [[nodiscard]] absl::Status Validate() const;
};

struct IngestProgress {
  uint64_t frames_done = 0, frames_total = 0;
  uint64_t rays = 0, wedges = 0;
  double elapsed_s = 0;
};
using IngestProgressCallback = std::function<void(const IngestProgress&)>;

struct IngestResult {
  std::vector<SpilledChunk> chunks;  // sorted by chunk key (ChunkKeyLess)
  uint64_t frames = 0, rays = 0, returns = 0;
  uint64_t wedges = 0, single_ray_wedges = 0, wedge_chunk_pairs = 0;
  bool default_covariance = false;   // the scan had no /path_cov: defaults were used
  Eigen::AlignedBox3d bounds;        // of all sensor and point means
  double elapsed_s = 0;
};

// Errors name the scan file (and dataset/row for bad content). On error the spill directory
// may hold partial files: callers discard it.
absl::StatusOr<IngestResult> IngestScan(const IngestOptions& options,
                                        const IngestProgressCallback& progress = {});

}  // namespace carvemap
