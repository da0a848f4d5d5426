#include "services/merge/pocket_tiles.h"

#include <algorithm>
#include <filesystem>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "services/merge/for_each_chunk.h"
#include "services/merge/parallel_for.h"

namespace carvemap {

namespace fs = std::filesystem;

absl::StatusOr<PocketTilesResult> FillPocketTiles(TileSet& tiles, const std::string& tiles_dir,
                                                  const std::string& out_dir,
                                                  const PocketFillOptions& options,
                                                  const ChunkProgressFn& progress, int threads) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(out_dir, ": cannot create: ", ec.message()));
  threads = std::max(1, threads);
  PocketTilesResult result;

  // 1. Every chunk's candidates (its neighbours decoded with it), each chunk's list at its
  //    size, then the whole pockets, kept in those lists.
  std::vector<std::pair<ChunkKey, std::vector<PocketCell>>> by_chunk;
  absl::Status s = ForEachChunk<std::pair<ChunkKey, std::vector<PocketCell>>>(
      tiles, tiles.chunks(), /*low_only=*/false, threads,
      [&](const ChunkNeighbourhood& hood)
          -> absl::StatusOr<std::pair<ChunkKey, std::vector<PocketCell>>> {
        absl::StatusOr<std::vector<PocketCell>> cells = PocketCandidates(hood, options);
        if (!cells.ok()) return cells.status();
        DropInnerTaintedPockets(*cells, hood.chunk, hood.grid);
        cells->shrink_to_fit();
        return std::make_pair(hood.chunk, *std::move(cells));
      },
      [&](std::pair<ChunkKey, std::vector<PocketCell>>&& cells) {
        if (!cells.second.empty()) by_chunk.push_back(std::move(cells));
      },
      progress, "pocket_fill");
  if (!s.ok()) return s;
  by_chunk.shrink_to_fit();
  if (s = KeepFillablePocketCells(by_chunk, tiles.grid()); !s.ok()) return s;
  std::erase_if(by_chunk, [](const auto& c) { return c.second.empty(); });
  const auto cells_of = [&by_chunk](const ChunkKey& chunk) -> const std::vector<PocketCell>* {
    auto it = std::lower_bound(
        by_chunk.begin(), by_chunk.end(), chunk,
        [](const auto& e, const ChunkKey& k) { return ChunkKeyLess{}(e.first, k); });
    return it != by_chunk.end() && it->first == chunk ? &it->second : nullptr;
  };

  // 2. Each chunk with filled cells as a new tile (built and compressed on `threads` threads,
  //    written in order), any other as a link to its tile.
  std::vector<ChunkKey> filled;
  for (const ChunkKey& chunk : tiles.chunks()) {
    if (cells_of(chunk) != nullptr) {
      filled.push_back(chunk);
      continue;
    }
    const fs::path from = fs::path(tiles_dir) / TileFileName(chunk);
    const fs::path to = fs::path(out_dir) / TileFileName(chunk);
    std::error_code link_ec;
    fs::remove(to, link_ec);
    fs::create_hard_link(from, to, link_ec);
    if (link_ec) {
      std::error_code copy_ec;
      fs::copy_file(from, to, fs::copy_options::overwrite_existing, copy_ec);
      if (copy_ec) {
        return absl::UnavailableError(absl::StrCat(to.string(), ": cannot link or copy ",
                                                   from.string(), ": ", copy_ec.message()));
      }
    }
  }
  const size_t batch = 4 * size_t(threads);
  for (size_t first = 0; first < filled.size(); first += batch) {
    const size_t n = std::min(batch, filled.size() - first);
    std::vector<std::shared_ptr<const TileData>> in(n);
    for (size_t i = 0; i < n; ++i) {
      absl::StatusOr<std::shared_ptr<const TileData>> tile = tiles.Get(filled[first + i]);
      if (!tile.ok()) return tile.status();
      in[i] = *std::move(tile);
    }
    std::vector<std::optional<absl::StatusOr<EncodedTile>>> encoded(n);
    ParallelFor(n, threads, [&](size_t i) {
      absl::StatusOr<TileData> tile = WithFilledCells(*in[i], *cells_of(filled[first + i]));
      encoded[i].emplace(tile.ok() ? EncodeTile(out_dir, *tile)
                                   : absl::StatusOr<EncodedTile>(tile.status()));
    });
    for (size_t i = 0; i < n; ++i) {
      if (!encoded[i]->ok()) return encoded[i]->status();
      if (absl::StatusOr<std::string> w = WriteEncodedTile(**encoded[i]); !w.ok()) {
        return w.status();
      }
      result.filled_cells += cells_of(filled[first + i])->size();
    }
  }
  result.chunks = tiles.chunks().size();
  result.filled_tiles = filled.size();
  return result;
}

}  // namespace carvemap
