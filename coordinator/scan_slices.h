// Time slices of a scan: the carve's units of work (docs/DESIGN.md §5, docs/RPC.md "Slices"). Any
// worker carves a slice's rays into partial sums per chunk (worker/slice_carver.h); every chunk's
// partial sums are then added in slice order and simplified into its tile
// (worker/chunk_combiner.h). Eq 4.8's sums are additive over disjoint sets of rays, so this is
// the whole scan's carve up to floating-point rounding, whatever the slice length, and the same
// bytes whatever the number of workers.
//
// A slice owns the frames whose time lies in its interval: their rays vote. It reads a few
// frames more of each line sensor, whose rays vote in the neighbouring slice, because its own
// rays' wedges need them: one frame after its last (wedges join frames i and i+1, §4.2.1) and
// two before its first (a frame's sampling spread reads its previous frame's points, and the
// wedge to the previous frame has that frame's far ends, which need its own spread).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "storage/scan_reader.h"
#include "storage/scan_types.h"

namespace carvemap {

struct ScanSlice {
  uint32_t index = 0;
  // The slice's own frames: t in [t_begin, t_end).
  double t_begin = 0, t_end = 0;
  std::vector<ScanReader::RowRange> own;   // per sensor: the rows whose rays vote here
  std::vector<ScanReader::RowRange> read;  // per sensor: `own` and the context around it
  uint64_t own_rays = 0;                   // rays of the own rows (for progress)
};

// Context frames a line sensor's slice reads around its own rows (see above).
inline constexpr uint64_t kSliceFramesBefore = 2;
inline constexpr uint64_t kSliceFramesAfter = 1;

struct SlicePlanOptions {
  // Length of a slice in scan time, s; 0: the scan's duration split so that a slice holds about
  // target_rays rays (~30 s of the full-rate backpack), but at least min_slice_s; and a short
  // scan still in min_slices slices (so that several workers share it), down to
  // shortest_slice_s. A slice costs its context frames and a section per chunk it touches.
  double slice_s = 0;
  uint64_t target_rays = 4'000'000;
  double min_slice_s = 10;
  int min_slices = 8;
  double shortest_slice_s = 2;
};

// The slice length `options` give for a scan of `rays` rays over `duration_s` seconds.
[[nodiscard]] double SliceSeconds(const SlicePlanOptions& options, uint64_t rays,
                                  double duration_s);

// Slices [t0 + k·slice_s, t0 + (k + 1)·slice_s) over the frames, t0 the earliest frame's time;
// slices without frames are left out (a pause), the others numbered from 0. frames[s] are
// sensor s's /frames rows (ascending time, as ScanReader::FrameRecords gives them).
// InvalidArgument for sizes that disagree, a slice_s ≤ 0 or not finite, or frame times that
// are not finite.
[[nodiscard]] absl::StatusOr<std::vector<ScanSlice>> PlanSlices(
    std::span<const std::vector<FrameRecord>> frames, std::span<const SensorKind> kinds,
    double slice_s);

// A scan's slices as the carve plans them (SliceSeconds, PlanSlices), from `reader`'s frame
// tables, after Validate() has checked every row: a bad row found by a worker half-way through
// would cost the job its carve so far. `reader` may hold no path (PathRows::kNone); memory is
// the frame tables', 24 bytes per frame. Errors name the file.
struct ScanSlicePlan {
  std::vector<ScanSlice> slices;
  double slice_s = 0;
  uint64_t rays = 0;
};
[[nodiscard]] absl::StatusOr<ScanSlicePlan> PlanScanSlices(ScanReader& reader,
                                                           const SlicePlanOptions& options);

}  // namespace carvemap
