// Carving one time slice of a scan (coordinator/scan_slices.h) into partial sums per chunk
// (docs/DESIGN.md §5): the scan's frames ➜ rays and wedges (§4.1.1, §4.3.1;
// coordinator/wedge_builder.h) ➜ the 2 m chunks each wedge's hull touches ➜ eq 4.8 in each chunk
// (worker/chunk_octree.h), the slice's own rays voting, its context rays only shaping their wedges.
// No spill: a wedge is binned in memory and carved within the batch of frames it belongs to.
//
// Memory is bounded whatever the slice's length: frames are carved in batches of about
// batch_rays own rays (a ray votes in the batch of its frame; the wedges joining two batches
// go to both, each voting its own rays); a grid or points frame larger than batch_rays (a
// terrestrial scanner's setup) is cut into bands of about batch_rays, a grid's at whole pixel
// rows, each its own batch, carved as the wedge builder's row order moves past it. What still
// grows with such a frame is the frame itself and the wedge builder's noise model of each of
// its rays (~100 B a pixel). The chunks' sums go out as sections
// (PartialSumsWriter) whenever their hash maps, with a second pass's decoded regions, exceed
// memory_budget_bytes (checked after each chunk is carved), and at the end.
//
// Deterministic: batches, flushes and the order of every sum follow from the slice and the
// options alone, so the same slice gives the same sections on any worker.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "coordinator/scan_slices.h"
#include "coordinator/wedge_builder.h"
#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "storage/scan_reader.h"
#include "storage/tile_store.h"
#include "worker/chunk_octree.h"

namespace carvemap {

struct SliceCarveOptions {
  OctreeGrid grid;
  CarveEvaluation evaluation = CarveEvaluation::kFast;
  WedgeBuilderOptions wedges;
  // §5.6.1's second pass: only these chunks, each only inside its region, decoded when a
  // wedge first reaches the chunk (a slice reaches a small part of a building's pass). Null:
  // every chunk, whole. Must outlive the carver.
  const RecarveRegionMap* regions = nullptr;
  uint64_t batch_rays = 500'000;             // own rays per batch of frames
  // Chunks' sums held before they are flushed: ChunkOctree::memory_bytes(), the maps' real size,
  // and the regions of the pass decoded since the last flush (ChunkRegion::memory_bytes()).
  size_t memory_budget_bytes = 256u << 20;
  [[nodiscard]] absl::Status Validate() const;
};

struct SliceCarveStats {
  uint64_t frames = 0, rays = 0, returns = 0;  // the slice's own frames
  uint64_t wedges = 0;                         // wedges holding a ray of the slice
  uint64_t wedge_chunk_pairs = 0;              // (wedge, chunk) carved, a wedge once per batch
  uint64_t leaf_updates = 0;                   // eq 4.8 votes
  uint64_t batches = 0, flushes = 0, sections = 0;
  bool default_covariance = false;             // the scan had no /path_cov
  Eigen::AlignedBox3d bounds;                  // of the own rays' sensor and point means
};

// The carve of one slice as plain data in, sections out. Not thread-safe.
class SliceCarver {
 public:
  // Receives a chunk's finest sums (worker/chunk_octree.h FinestLeaves) and the wedges carved
  // into them. A chunk may come several times (one per flush), always in ChunkKeyLess order
  // within a flush. Valid only during the call.
  using SectionSink =
      std::function<absl::Status(const ChunkKey&, uint64_t wedges, std::span<const TileLeaf>)>;

  // `sensors` as the scan's (ScanReader::sensors()), the slice as planned over its frames.
  static absl::StatusOr<std::unique_ptr<SliceCarver>> Create(std::vector<SensorInfo> sensors,
                                                             const ScanSlice& slice,
                                                             const SliceCarveOptions& options,
                                                             SectionSink sink);
  ~SliceCarver();

  // The frames of slice.read in the scan's order (ScanReader::StreamFrames over slice.read),
  // each with its FrameContextAt. InvalidArgument for a frame outside slice.read or out of
  // order; a wedge that is not finite or reaches beyond ±1000 km names its sensor and frame.
  absl::Status AddFrame(const ScanFrame& frame, const FrameContext& context);
  // Carves what is left and flushes every chunk. Call once, after the last frame.
  absl::StatusOr<SliceCarveStats> Finish();
  // `progress` gets the slice's own rays carved so far, after every chunk a batch carves: a
  // batch's own rays count in proportion to its (wedge, chunk) pairs carved, so the count
  // moves while a batch is carved (seconds at the rig's rate), not when its frames are read.
  // Finish ends it at SliceCarveStats::rays.
  void SetProgress(std::function<void(uint64_t own_rays_carved)> progress);

 private:
  struct Impl;
  explicit SliceCarver(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// How to open the scan for `slice`: only the poses around its frames (a worker's memory does
// not grow with the survey's path).
[[nodiscard]] ScanReader::OpenOptions SliceOpenOptions(const ScanSlice& slice);

// The I/O around it: streams slice.read from `reader` (opened with SliceOpenOptions, or with
// the whole path), writes the sections to `partial_path`
// (storage/partial_sums.h, atomically: nothing under that name unless complete). `progress`,
// if set, gets the own rays carved so far (SliceCarver::SetProgress). REQUIRES: HDF5 calls serialized
// (scan_reader.h): the reader is used from this thread only.
absl::StatusOr<SliceCarveStats> CarveSliceToFile(
    ScanReader& reader, const ScanSlice& slice, const SliceCarveOptions& options,
    const std::string& partial_path, const std::function<void(uint64_t rays)>& progress = {});

}  // namespace carvemap
