#include "services/merge/segment_tiles.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "services/merge/for_each_chunk.h"

namespace carvemap {

absl::StatusOr<SegmentTilesResult> SegmentTiles(TileSet& tiles, const PlanVolume& plan,
                                                const SegmentOptions& options,
                                                const std::string& building_dir,
                                                const std::string& objects_dir,
                                                const ChunkProgressFn& progress, int threads,
                                                const RecarveRegionMap* only_in) {
  for (const std::string& dir : {building_dir, objects_dir}) {
    if (dir.empty()) continue;
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return absl::UnavailableError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  SegmentTilesResult result;
  const ChunkRegion none;
  absl::Status s = ForEachChunk<SegmentedChunk>(
      tiles, tiles.chunks(), /*low_only=*/false, threads,
      [&](const ChunkNeighbourhood& hood) -> absl::StatusOr<SegmentedChunk> {
        if (only_in == nullptr) return SegmentChunk(hood, plan, options, nullptr);
        auto it = only_in->find(hood.chunk);
        if (it == only_in->end()) return SegmentChunk(hood, plan, options, &none);
        absl::StatusOr<ChunkRegion> region = it->second.Decode();
        if (!region.ok()) return region.status();
        return SegmentChunk(hood, plan, options, &*region);
      },
      [&](SegmentedChunk&& seg) -> absl::Status {
        if (!building_dir.empty()) {
          if (absl::StatusOr<std::string> w = WriteTile(building_dir, seg.building); !w.ok()) {
            return w.status();
          }
          ++result.building_tiles;
        }
        if (seg.object_cells > 0) {
          if (absl::StatusOr<std::string> w = WriteTile(objects_dir, seg.objects); !w.ok()) {
            return w.status();
          }
          ++result.object_tiles;
          result.object_chunks.push_back(seg.objects.chunk);
        }
        result.object_cells += seg.object_cells;
        result.unobserved_object_cells += seg.unobserved_object_cells;
        result.trimmed_cells += seg.trimmed_cells;
        ++result.chunks;
        return absl::OkStatus();
      },
      progress, "segmentation");
  if (!s.ok()) return s;
  return result;
}

}  // namespace carvemap
