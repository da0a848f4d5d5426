// Partial sums files (storage/partial_sums.h, PARTIAL_FORMAT.md) and regions files: what a
// worker reads of another worker's slices, from the shared volume. Any bytes read or give
// errors naming the file (NotFound never: the file is there); a file that reads has sections
// in order, leaves inside the chunk with finite sums, and writes back to a file that reads the
// same.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <tuple>
#include <vector>

#include "storage/partial_sums.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("slice.part", data, size);
  absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(path);
  if (!index.ok()) {
    fuzz::Require(index.status().code() == absl::StatusCode::kDataLoss, "errors are DataLoss");
    fuzz::RequireNamesFile(index.status(), path);
  } else {
    fuzz::Trace(absl::OkStatus());
    const std::string copy = (fuzz::ScratchDir() / "copy.part").string();
    absl::StatusOr<std::unique_ptr<PartialSumsWriter>> writer =
        PartialSumsWriter::Create(copy, index->chunk_depth, index->slice);
    fuzz::Require(writer.ok(), "a read file's depth is writable");
    bool all_read = true;
    std::vector<std::vector<TileLeaf>> written;
    for (const PartialSection& s : index->sections) {
      std::vector<TileLeaf> leaves;
      const absl::Status st = ReadPartialSection(path, *index, s, leaves);
      if (!st.ok()) {
        fuzz::Require(st.code() == absl::StatusCode::kDataLoss, "section errors are DataLoss");
        fuzz::RequireNamesFile(st, path);
        all_read = false;
        continue;
      }
      fuzz::Require(leaves.size() == s.leaves, "a section holds its count of leaves");
      for (const TileLeaf& l : leaves) {
        fuzz::Require(l.node.depth == index->chunk_depth, "leaves are finest");
        fuzz::Require(std::isfinite(l.stats.sum_w) && l.stats.sum_w >= 0, "finite sums");
      }
      fuzz::Require((*writer)->AddSection(s.chunk, s.wedges, leaves).ok(), "leaves write back");
      written.push_back(std::move(leaves));
    }
    if (all_read) {
      fuzz::Require((*writer)->Finish().ok(), "the copy finishes");
      // The copy (this build's version, its own compression) reads back to the same sections
      // and, each sorted by place as the writer sorts them, the same leaves.
      absl::StatusOr<PartialSumsIndex> again = ReadPartialIndex(copy);
      fuzz::Require(again.ok() && again->sections.size() == index->sections.size(),
                    "the copy reads");
      const auto by_place = [](const TileLeaf& a, const TileLeaf& b) {
        return std::tuple(a.node.local.z(), a.node.local.y(), a.node.local.x()) <
               std::tuple(b.node.local.z(), b.node.local.y(), b.node.local.x());
      };
      for (size_t k = 0; k < written.size(); ++k) {
        const PartialSection& s = again->sections[k];
        fuzz::Require(s.chunk == index->sections[k].chunk &&
                          s.wedges == index->sections[k].wedges && s.leaves == written[k].size(),
                      "the copy's sections are the file's");
        std::vector<TileLeaf> back;
        fuzz::Require(ReadPartialSection(copy, *again, s, back).ok(), "the copy's sections read");
        std::stable_sort(written[k].begin(), written[k].end(), by_place);
        for (size_t i = 0; i < back.size(); ++i) {
          const TileLeaf &a = back[i], &b = written[k][i];
          fuzz::Require(a.node.local == b.node.local && a.stats.count == b.stats.count &&
                            a.stats.points == b.stats.points &&
                            std::memcmp(&a.stats.sum_w, &b.stats.sum_w, 8) == 0 &&
                            std::memcmp(&a.stats.sum_wp, &b.stats.sum_wp, 8) == 0 &&
                            std::memcmp(&a.stats.sum_wp2, &b.stats.sum_wp2, 8) == 0,
                        "the copy's leaves are the file's");
        }
      }
    }
  }
  const std::string regions_path = fuzz::WriteInput("regions.bin", data, size);
  absl::StatusOr<RecarveRegionMap> regions = ReadRegionsFile(regions_path);
  if (!regions.ok()) {
    fuzz::Require(regions.status().code() == absl::StatusCode::kDataLoss, "errors are DataLoss");
    fuzz::RequireNamesFile(regions.status(), regions_path);
  } else {
    // What the reader accepts, a slice can decode.
    for (const auto& [chunk, encoded] : *regions) {
      fuzz::Require(encoded.chunk == chunk, "each region under its own chunk");
      absl::StatusOr<ChunkRegion> region = encoded.Decode();
      fuzz::Require(region.ok(), "accepted regions decode");
      fuzz::Require(region->depth() >= 0 && region->depth() <= ChunkRegion::kMaxDepth, "depths");
    }
  }
  return 0;
}
