#include "services/merge/segment_tiles.h"

#include <filesystem>

#include "absl/strings/str_cat.h"

namespace carvemap {

absl::StatusOr<SegmentTilesResult> SegmentTiles(TileSet& tiles, const PlanVolume& plan,
                                                const SegmentOptions& options,
                                                const std::string& building_dir,
                                                const std::string& objects_dir,
                                                const ChunkProgressFn& progress,
                                                const ChunkRegionMap* only_in) {
  for (const std::string& dir : {building_dir, objects_dir}) {
    if (dir.empty()) continue;
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return absl::UnavailableError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  SegmentTilesResult result;
  const uint64_t total = tiles.chunks().size();
  std::array<std::shared_ptr<const TileData>, 27> hold;
  for (const ChunkKey& chunk : tiles.chunks()) {
    absl::StatusOr<ChunkNeighbourhood> hood =
        FetchNeighbourhood(tiles, chunk, /*low_only=*/false, hold);
    if (!hood.ok()) return hood.status();
    const ChunkRegion none;
    const ChunkRegion* region = nullptr;
    if (only_in != nullptr) {
      auto it = only_in->find(chunk);
      region = it != only_in->end() ? &it->second : &none;
    }
    absl::StatusOr<SegmentedChunk> seg = SegmentChunk(*hood, plan, options, region);
    if (!seg.ok()) return seg.status();
    if (!building_dir.empty()) {
      if (absl::StatusOr<std::string> w = WriteTile(building_dir, seg->building); !w.ok()) {
        return w.status();
      }
      ++result.building_tiles;
    }
    if (seg->object_cells > 0) {
      if (absl::StatusOr<std::string> w = WriteTile(objects_dir, seg->objects); !w.ok()) {
        return w.status();
      }
      ++result.object_tiles;
      result.object_chunks.push_back(chunk);
    }
    result.object_cells += seg->object_cells;
    result.unobserved_object_cells += seg->unobserved_object_cells;
    result.trimmed_cells += seg->trimmed_cells;
    ++result.chunks;
    if (progress && !progress(result.chunks, total)) {
      return absl::CancelledError("merge cancelled");
    }
  }
  return result;
}

}  // namespace carvemap
