// Tiles (docs/DESIGN.md §5): one HDF5 file per carved 2 m chunk holding the leaves of its
// simplified octree (§4.3.2) as columns. Layout: storage/TILE_FORMAT.md (format "carvemap-tile",
// version 2). Equal TileData gives byte-identical files, so a retried carve task is harmless.
//
// Thread safety: Debian 12's libhdf5 is built without --enable-threadsafe. WriteTile/ReadTile
// serialize among themselves (one mutex inside tile_store.cc), but every other HDF5 use in the
// process (ScanReader, ScanWriter, ...) must not run concurrently with them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"

namespace carvemap {

inline constexpr char kTileFormat[] = "carvemap-tile";
// 2 adds /leaves/points; version 1 tiles still read, with no points.
inline constexpr int kTileVersion = 2;

// One leaf of a chunk octree: a node of the chunk (depth ≤ chunk_depth) and its fused
// statistics (eq 4.8). Tiles keep the sums (sum_w, sum_wp, sum_wp2, count), so leaves of
// tiles merge exactly; p and variance are stored too, derived, for readers that want them.
struct TileLeaf {
  ChunkNode node;
  LeafStats stats;
};

// How the chunk was carved; stored as attributes so a tile says what produced it.
struct TileCarveParams {
  std::string job_id;         // may be empty
  uint64_t num_wedges = 0;    // wedges carved into the chunk
  double hull_sigmas = 3.0;   // §4.3.1: rays extended this many σ past their points
  double min_weight = 1e-6;   // ray contributions with w below this were skipped
  bool simplified = true;     // §4.3.2 simplification applied
};

struct TileData {
  ChunkKey chunk = ChunkKey::Zero();
  OctreeGrid grid;
  TileCarveParams params;
  // Leaves in any order; WriteTile stores them in canonical order (below). They must not
  // overlap. Space no leaf covers is unobserved (p = 0.5, count 0; §4.3.2).
  std::vector<TileLeaf> leaves;
};

// Canonical leaf order: by the Morton code of each leaf's first finest-depth cell
// (code << 3·(chunk_depth − depth)), then by depth. Non-overlapping leaves are thereby in
// Z-curve order. ReadTile returns leaves in this order.
void SortTileLeaves(const OctreeGrid& grid, std::vector<TileLeaf>& leaves);

// "c_<x>_<y>_<z>.h5" with the chunk key in decimal (negative keys keep their '-').
[[nodiscard]] std::string TileFileName(const ChunkKey& chunk);

// Writes `tile` to `dir`/TileFileName(tile.chunk) via "<name>.partial" and a rename, so a
// reader never sees a half-written tile; replaces an existing tile. Returns the final path.
// InvalidArgument for bad content (depth > chunk_depth, code outside 8^depth, overlapping
// leaves, non-finite sums, negative weights); the error names the file and leaf index.
absl::StatusOr<std::string> WriteTile(const std::string& dir, const TileData& tile);

// Reads and validates a tile: format/version attributes, all columns present, rank 1, equal
// lengths, depth ≤ chunk_depth, codes inside 8^depth, finite values, p in [0, 1] and
// consistent with the sums, leaves sorted and non-overlapping. NotFound for a missing file;
// DataLoss (naming the file and the dataset or attribute) for a truncated/corrupt or invalid
// tile.
absl::StatusOr<TileData> ReadTile(const std::string& path);

// The same in two steps, for callers that handle many tiles on several threads: the
// compression is most of a tile's cost, and here it runs outside the process's HDF5 lock.
// WriteTile is EncodeTile (sorts, validates and compresses each column's stored chunks, on any
// thread) then WriteEncodedTile (the file, under the lock); ReadTile is ReadRawTile (the
// attributes and the stored chunks, under the lock) then DecodeTile (decompresses and
// validates, on any thread). Each step's errors are those of WriteTile or ReadTile.
struct EncodedTile {
  std::string path;  // where WriteEncodedTile puts it
  TileData header;   // chunk, grid and params; no leaves
  uint64_t num_leaves = 0;
  uint64_t chunk_rows = 0;
  // Per column (TILE_FORMAT.md's order), each stored chunk's bytes as HDF5's filters make them.
  std::vector<std::vector<std::string>> columns;
};
absl::StatusOr<EncodedTile> EncodeTile(const std::string& dir, const TileData& tile);
absl::StatusOr<std::string> WriteEncodedTile(const EncodedTile& tile);

struct RawTile {
  std::string path;
  TileData header;  // chunk, grid and params; no leaves
  uint64_t rows = 0;
  struct Column {
    uint64_t chunk_rows = 0;
    std::vector<std::string> chunks;  // stored bytes, still filtered
    std::vector<uint32_t> masks;      // HDF5's filter mask of each: bit i = filter i skipped
    // A column another writer stored with other filters or layout: read whole through HDF5.
    std::vector<unsigned char> decoded;
  };
  std::vector<Column> columns;  // TILE_FORMAT.md's order; version 1 tiles have no points
};
absl::StatusOr<RawTile> ReadRawTile(const std::string& path);
absl::StatusOr<TileData> DecodeTile(RawTile raw);

}  // namespace carvemap
