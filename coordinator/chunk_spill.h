// Out-of-core chunk bins (DESIGN §5): the coordinator streams wedges in, each is binned into
// the 2 m chunks it touches and its records (storage/wedge_codec.h: the wedge, and its rays and
// frame the first time the chunk needs them) appended to a per-chunk buffer; buffers go to one
// spill file per chunk whenever the memory budget is exceeded, so memory stays bounded
// whatever the scan size. File layout: storage/WEDGE_FORMAT.md.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/geometry/carving_types.h"
#include "services/geometry/octree_keys.h"
#include "storage/crc32c.h"  // the spill files' checksum (storage/WEDGE_FORMAT.md)

namespace carvemap {

struct ChunkSpillOptions {
  std::string dir;                          // created if missing; should hold only this job's spill
  size_t memory_budget_bytes = 64u << 20;   // wedge records buffered before flushing
  double sigmas = 3.0;                      // extension of the wedges past their points (§4.3.1)

  [[nodiscard]] absl::Status Validate() const;
};

struct SpilledChunk {
  ChunkKey chunk;
  uint64_t wedge_count = 0;
  uint64_t file_bytes = 0;  // header included
  std::string path;
};

// Not thread-safe (one ingest thread owns it). Per chunk it keeps ~200 bytes of bookkeeping
// besides the budgeted records, plus the ids of the rays it holds of its sensors' last two
// frames (8 bytes each); files are opened, appended and closed per flush, so at most one is
// open at a time.
class ChunkSpiller {
 public:
  static absl::StatusOr<std::unique_ptr<ChunkSpiller>> Create(const ChunkSpillOptions& options);
  ~ChunkSpiller();
  ChunkSpiller(const ChunkSpiller&) = delete;
  ChunkSpiller& operator=(const ChunkSpiller&) = delete;

  // Bins the wedge and buffers its records for each chunk it touches (in insertion order per
  // chunk), flushing the largest buffers first when over budget. `ids` name its rays as the
  // wedge builder does (WedgeSink): a ray shared by several wedges of a chunk is stored once.
  // InvalidArgument for a wedge that fails ValidateWedge or reaches beyond
  // ±kMaxWorldCoordinateM, or too few ids; I/O errors name the file. A wedge touching no chunk
  // cannot happen for a valid wedge.
  absl::Status Add(const Wedge& wedge, std::span<const RayId> ids);
  // The same for a wedge without ids: each of its rays is stored as a ray of its own.
  absl::Status Add(const Wedge& wedge);

  // Flushes everything, writes the headers, fsyncs and renames each file into place; returns
  // the chunks sorted by ChunkKeyLess. FailedPrecondition when called twice; Add after Finish
  // is FailedPrecondition too.
  absl::StatusOr<std::vector<SpilledChunk>> Finish();

  [[nodiscard]] size_t buffered_bytes() const { return buffered_bytes_; }
  [[nodiscard]] uint64_t wedges_added() const { return wedges_added_; }
  [[nodiscard]] uint64_t records_written() const { return records_; }
  [[nodiscard]] uint64_t flushes() const { return flushes_; }  // buffer → file appends

 private:
  struct ChunkState;
  explicit ChunkSpiller(const ChunkSpillOptions& options);
  absl::Status FlushChunk(const std::array<int, 3>& key, ChunkState& state);
  absl::Status FlushOverBudget();

  ChunkSpillOptions options_;
  std::map<std::array<int, 3>, ChunkState> chunks_;  // (x, y, z): ChunkKeyLess order
  size_t buffered_bytes_ = 0;
  uint64_t wedges_added_ = 0;
  uint64_t records_ = 0;
  uint64_t flushes_ = 0;
  uint64_t anonymous_rays_ = 0;  // ids given to rays added without one
  bool finished_ = false;
};

// <dir>/chunk_<x>_<y>_<z>.wedges (the temporary name while spilling adds ".tmp").
[[nodiscard]] std::string ChunkSpillPath(std::string_view dir, const ChunkKey& chunk);

struct ChunkSpillFile {
  ChunkKey chunk;
  uint64_t wedge_count = 0;
  std::string payload;  // the wedge payload: what is sent to the worker
};

// The spill file format version this build writes and reads (storage/WEDGE_FORMAT.md).
inline constexpr uint32_t kChunkSpillVersion = 2;

// Reads and checks a spill file (magic, version, checksums, sizes, the payload's structure and
// wedge count). NotFound for a missing file, DataLoss naming the file for a corrupt or
// truncated one, or one of another version (an older ingest's: the job must be ingested again).
[[nodiscard]] absl::StatusOr<ChunkSpillFile> ReadChunkSpillFile(const std::string& path);
// The wedges of `chunk` under `dir`, in insertion order; also checks the header's chunk key.
[[nodiscard]] absl::StatusOr<std::vector<Wedge>> ReadChunkWedges(std::string_view dir,
                                                                 const ChunkKey& chunk);

}  // namespace carvemap
