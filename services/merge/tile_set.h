// A tiles directory seen as one octree (docs/DESIGN.md §6): the index of its chunks (from the file
// names alone) and a bounded LRU cache of decoded tiles, so merge stages run out of core.
#pragma once

#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"
#include "storage/tile_store.h"

namespace carvemap {

// Parses "c_<x>_<y>_<z>.h5" (TileFileName); false for any other name (".partial" included).
[[nodiscard]] bool ParseTileFileName(const std::string& name, ChunkKey& chunk);

// The leaf of the merged octree that covers a point.
struct LeafQuery {
  ChunkKey chunk = ChunkKey::Zero();
  bool stored = false;  // false: no tile row covers the point (unobserved, p = 0.5, exterior)
  ChunkNode node;       // valid when stored
  LeafStats stats;      // count 0 when not stored
};

// Not thread-safe: one user at a time (and no concurrent HDF5 use, storage/tile_store.h).
class TileSet {
 public:
  // Lists `tiles_dir` (NotFound if missing, InvalidArgument if not a directory). The grid is
  // `resolution_m` when > 0, else the first tile's (read once to learn it; an empty directory
  // then gets the default grid). Tiles whose grid differs are rejected when read.
  static absl::StatusOr<std::unique_ptr<TileSet>> Open(const std::string& tiles_dir,
                                                       double resolution_m,
                                                       uint64_t cache_budget_bytes);

  TileSet(const TileSet&) = delete;
  TileSet& operator=(const TileSet&) = delete;

  [[nodiscard]] const std::string& dir() const { return dir_; }
  [[nodiscard]] const OctreeGrid& grid() const { return grid_; }
  // Chunks with a tile, in ChunkKeyLess order.
  [[nodiscard]] const std::vector<ChunkKey>& chunks() const { return chunks_; }
  [[nodiscard]] bool Contains(const ChunkKey& chunk) const;
  [[nodiscard]] std::string PathOf(const ChunkKey& chunk) const;

  // The decoded tile through the cache. NotFound for a chunk without a tile; DataLoss naming
  // the file for a corrupt tile or one whose chunk key disagrees with its name;
  // InvalidArgument naming the file for a tile of another resolution. The pointer stays valid
  // after eviction.
  absl::StatusOr<std::shared_ptr<const TileData>> Get(const ChunkKey& chunk);

  // Reads into the cache the tiles of `chunks` that have one and are not cached, as Get
  // would one at a time, but decompressing them on `threads` threads (the files are read on
  // this one: HDF5 is not thread-safe). The per-chunk stages call it for each batch, so that
  // decompressing tiles does not hold up their other cores.
  absl::Status Prefetch(std::span<const ChunkKey> chunks, int threads);
  // The stored leaf covering `x_world`; chunks without a tile answer `stored = false`.
  absl::StatusOr<LeafQuery> Query(const Eigen::Vector3d& x_world);

  // Drops every cached tile (pointers handed out stay valid): for a stage that is done with
  // this set while later stages still hold it open.
  void ReleaseCache();

  [[nodiscard]] uint64_t tile_reads() const { return tile_reads_; }  // cache misses
  [[nodiscard]] uint64_t cached_bytes() const { return cached_bytes_; }

 private:
  TileSet(std::string dir, OctreeGrid grid, std::vector<ChunkKey> chunks, uint64_t budget)
      : dir_(std::move(dir)), grid_(grid), chunks_(std::move(chunks)), budget_(budget) {}

  // Checks `tile` against its name and the grid, then caches it (evicting LRU tiles).
  absl::Status Insert(const ChunkKey& chunk, TileData tile);

  struct Entry {
    std::shared_ptr<const TileData> tile;
    uint64_t bytes = 0;
    std::list<ChunkKey>::iterator lru_it;
  };

  std::string dir_;
  OctreeGrid grid_;
  std::vector<ChunkKey> chunks_;
  uint64_t budget_;
  std::list<ChunkKey> lru_;  // front = most recently used
  std::map<ChunkKey, Entry, ChunkKeyLess> cache_;
  uint64_t cached_bytes_ = 0;
  uint64_t tile_reads_ = 0;
};

// Index of the row of `tile` covering finest-depth local cell `local` (in [0, 2^k)^3), or -1.
[[nodiscard]] int64_t FindLeaf(const TileData& tile, const Eigen::Vector3i& local);

}  // namespace carvemap
