// Partial sums files (storage/partial_sums.h, PARTIAL_FORMAT.md) and regions files: what a
// worker reads of another worker's slices, from the shared volume. Any bytes read or give
// errors naming the file (NotFound never: the file is there); a file that reads has sections
// in order, leaves inside the chunk with finite sums, and writes back to the same bytes.
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <string>
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
    }
    if (all_read) {
      fuzz::Require((*writer)->Finish().ok(), "the copy finishes");
      std::ifstream a(path, std::ios::binary), b(copy, std::ios::binary);
      const std::string x(std::istreambuf_iterator<char>(a), {}), y(std::istreambuf_iterator<char>(b), {});
      // The writer sorts each section's leaves; a read file's are sorted already, or the
      // copy differs only there.
      fuzz::Require(x.size() == y.size(), "the copy has the file's size");
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
