#include "services/merge/pocket_tiles.h"

#include <filesystem>
#include <optional>

#include "absl/strings/str_cat.h"
#include "services/merge/for_each_chunk.h"

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
  PocketTilesResult result;
  // The tiles are compressed on the per-chunk threads; only their files are written in order.
  struct Filled {
    ChunkKey chunk = ChunkKey::Zero();
    uint64_t cells = 0;
    std::optional<EncodedTile> tile;  // when cells > 0
  };
  absl::Status s = ForEachChunk<Filled>(
      tiles, tiles.chunks(), /*low_only=*/false, threads,
      [&](const ChunkNeighbourhood& hood) -> absl::StatusOr<Filled> {
        absl::StatusOr<FilledChunk> filled = FillPockets(hood, options);
        if (!filled.ok()) return filled.status();
        Filled f;
        f.chunk = hood.chunk;
        f.cells = filled->filled_cells;
        if (f.cells > 0) {
          absl::StatusOr<EncodedTile> e = EncodeTile(out_dir, filled->tile);
          if (!e.ok()) return e.status();
          f.tile = *std::move(e);
        }
        return f;
      },
      [&](Filled&& f) -> absl::Status {
        ++result.chunks;
        if (f.tile) {
          if (absl::StatusOr<std::string> w = WriteEncodedTile(*f.tile); !w.ok()) {
            return w.status();
          }
          ++result.filled_tiles;
          result.filled_cells += f.cells;
          return absl::OkStatus();
        }
        const fs::path from = fs::path(tiles_dir) / TileFileName(f.chunk);
        const fs::path to = fs::path(out_dir) / TileFileName(f.chunk);
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
        return absl::OkStatus();
      },
      progress, "pocket_fill");
  if (!s.ok()) return s;
  return result;
}

}  // namespace carvemap
