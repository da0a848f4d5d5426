#include "services/merge/segment_tiles.h"

#include <filesystem>
#include <optional>

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
  // The tiles are compressed on the per-chunk threads; only their files are written in order.
  struct Encoded {
    SegmentedChunk counts;  // its tiles' leaves moved out
    std::optional<EncodedTile> building, objects;
  };
  const auto encode = [&](absl::StatusOr<SegmentedChunk> seg) -> absl::StatusOr<Encoded> {
    if (!seg.ok()) return seg.status();
    Encoded e;
    if (!building_dir.empty()) {
      absl::StatusOr<EncodedTile> b = EncodeTile(building_dir, seg->building);
      if (!b.ok()) return b.status();
      e.building = *std::move(b);
    }
    if (seg->object_cells > 0) {
      absl::StatusOr<EncodedTile> o = EncodeTile(objects_dir, seg->objects);
      if (!o.ok()) return o.status();
      e.objects = *std::move(o);
    }
    e.counts = *std::move(seg);
    e.counts.building.leaves = {};
    e.counts.objects.leaves = {};
    return e;
  };
  absl::Status s = ForEachChunk<Encoded>(
      tiles, tiles.chunks(), /*low_only=*/false, threads,
      [&](const ChunkNeighbourhood& hood) -> absl::StatusOr<Encoded> {
        if (only_in == nullptr) return encode(SegmentChunk(hood, plan, options, nullptr));
        auto it = only_in->find(hood.chunk);
        if (it == only_in->end()) return encode(SegmentChunk(hood, plan, options, &none));
        absl::StatusOr<ChunkRegion> region = it->second.Decode();
        if (!region.ok()) return region.status();
        return encode(SegmentChunk(hood, plan, options, &*region));
      },
      [&](Encoded&& e) -> absl::Status {
        const SegmentedChunk& seg = e.counts;
        if (e.building) {
          if (absl::StatusOr<std::string> w = WriteEncodedTile(*e.building); !w.ok()) {
            return w.status();
          }
          ++result.building_tiles;
        }
        if (e.objects) {
          if (absl::StatusOr<std::string> w = WriteEncodedTile(*e.objects); !w.ok()) {
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
