// Tiles (storage/tile_store.h ReadTile). Any file gives a tile or DataLoss naming the file; a
// tile that reads writes back with WriteTile and reads again equal.
// Two targets from this source: tile_reader builds the file from an h5_script.h script,
// tile_reader_raw takes the input as the file's bytes (as scan_reader_fuzzer.cc).
#include <cstddef>
#include <cstdint>

#include "storage/tile_store.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/fuzz/h5_script.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  fuzz::KeepHdf5FreeLists();
#ifdef CARVEMAP_FUZZ_RAW_BYTES
  const std::string path = fuzz::WriteInput("tile.h5", data, size);
#else
  const std::string path = (fuzz::ScratchDir() / "tile.h5").string();
  fuzz::BuildH5FromScript({data, size}, path);
#endif
  absl::StatusOr<TileData> tile = ReadTile(path);
  if (!tile.ok()) {
    fuzz::RequireNamesFile(tile.status(), path);
    fuzz::Require(tile.status().code() == absl::StatusCode::kDataLoss,
                  "a bad tile is DataLoss: " + tile.status().ToString());
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  const std::string dir = (fuzz::ScratchDir() / "rewritten").string();
  std::filesystem::create_directories(dir);
  absl::StatusOr<std::string> written = WriteTile(dir, *tile);
  fuzz::Require(written.ok(), "a tile that reads writes back: " + written.status().ToString());
  absl::StatusOr<TileData> again = ReadTile(*written);
  fuzz::Require(again.ok(), "a rewritten tile reads: " + again.status().ToString());
  fuzz::Require(again->chunk == tile->chunk && again->grid.chunk_depth == tile->grid.chunk_depth &&
                    again->leaves.size() == tile->leaves.size(),
                "a rewritten tile reads equal");
  for (size_t i = 0; i < tile->leaves.size(); ++i) {
    const TileLeaf& a = tile->leaves[i];
    const TileLeaf& b = again->leaves[i];
    fuzz::Require(a.node.depth == b.node.depth && a.node.local == b.node.local &&
                      a.stats.sum_w == b.stats.sum_w && a.stats.sum_wp == b.stats.sum_wp &&
                      a.stats.sum_wp2 == b.stats.sum_wp2 && a.stats.count == b.stats.count,
                  "a rewritten tile's leaves read equal");
  }
  return 0;
}
