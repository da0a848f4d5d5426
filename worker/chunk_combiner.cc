#include "worker/chunk_combiner.h"

#include <chrono>
#include <filesystem>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "storage/tile_store.h"
#include "worker/chunk_octree.h"

namespace carvemap {

SectionsByChunk GroupSections(const std::vector<PartialSource>& sources) {
  SectionsByChunk out;
  for (size_t i = 0; i < sources.size(); ++i) {
    const std::vector<PartialSection>& sections = sources[i].index.sections;
    for (size_t k = 0; k < sections.size(); ++k) out[sections[k].chunk].push_back({i, k});
  }
  return out;
}

absl::StatusOr<CarveChunkResult> CombineChunkToTile(const CombineChunkRequest& request) {
  const auto t0 = std::chrono::steady_clock::now();
  const ChunkKey& chunk = request.chunk;
  const std::string name = absl::StrCat(chunk.x(), ",", chunk.y(), ",", chunk.z());
  const auto prefixed = [&name](const absl::Status& s) {
    return absl::Status(s.code(), absl::StrCat("combine chunk (", name, "): ", s.message()));
  };
  if (request.grid.chunk_depth < kMinChunkDepth || request.grid.chunk_depth > kMaxChunkDepth) {
    return prefixed(absl::InvalidArgumentError(
        absl::StrCat("chunk depth ", request.grid.chunk_depth, " out of range")));
  }
  if (request.sources == nullptr) return prefixed(absl::InvalidArgumentError("no sources"));
  if (request.tiles_dir.empty()) return prefixed(absl::InvalidArgumentError("no tiles directory"));
  ChunkOctree tree(request.grid, chunk);
  std::vector<TileLeaf> leaves;
  for (const auto& [source_index, section_index] : request.sections) {
    if (source_index >= request.sources->size()) {
      return prefixed(absl::InvalidArgumentError("section of an unknown source"));
    }
    const PartialSource& source = (*request.sources)[source_index];
    if (source.index.chunk_depth != request.grid.chunk_depth) {
      return prefixed(absl::InvalidArgumentError(
          absl::StrCat(source.path, " holds chunk depth ", source.index.chunk_depth, ", not ",
                       request.grid.chunk_depth)));
    }
    if (section_index >= source.index.sections.size()) {
      return prefixed(absl::InvalidArgumentError(absl::StrCat(source.path, ": no section ",
                                                              section_index)));
    }
    const PartialSection& section = source.index.sections[section_index];
    if (section.chunk != chunk) {
      return prefixed(absl::InvalidArgumentError(absl::StrCat(
          source.path, ": section ", section_index, " is of another chunk")));
    }
    leaves.clear();
    if (absl::Status s = ReadPartialSection(source.path, source.index, section, leaves); !s.ok()) {
      return prefixed(s);
    }
    if (absl::Status s = tree.AddFinest(leaves, section.wedges); !s.ok()) return prefixed(s);
  }
  tree.DropUnobserved();
  tree.Simplify();
  std::error_code ec;
  std::filesystem::create_directories(request.tiles_dir, ec);
  if (ec) {
    return prefixed(absl::UnavailableError(
        absl::StrCat("cannot create ", request.tiles_dir, ": ", ec.message())));
  }
  const TileData tile = tree.ToTile(request.job_id);
  absl::StatusOr<std::string> path = WriteTile(request.tiles_dir, tile);
  if (!path.ok()) return prefixed(path.status());
  CarveChunkResult result;
  result.tile_path = *path;
  result.tile_bytes = std::filesystem::file_size(*path, ec);
  if (ec) result.tile_bytes = 0;
  result.wedges = tree.num_wedges();
  result.leaves = tile.leaves.size();
  result.elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace carvemap
