// Per-chunk merge stages on every core: the tiles of each chunk's neighbourhood are read on the
// calling thread (HDF5 is not thread-safe, storage/tile_store.h) and decompressed on `threads`
// threads, a batch of a few chunks per thread at a time; the per-chunk work runs on `threads`
// threads; the results are handed on in chunk order, on the calling thread, so they do not
// depend on the thread count.
#pragma once

#include <algorithm>
#include <array>
#include <memory>
#include <optional>
#include <span>
#include <type_traits>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/parallel_for.h"

namespace carvemap {

// Runs `compute` on every chunk's neighbourhood (FetchNeighbourhood with `low_only`) and hands
// the results to `take` in the order of `chunks`; `take` may return an absl::Status. Stops at the
// first error, or with Cancelled naming `stage` when `progress` says so.
template <typename Result, typename Compute, typename Take>
absl::Status ForEachChunk(TileSet& tiles, std::span<const ChunkKey> chunks, bool low_only,
                          int threads, const Compute& compute, const Take& take,
                          const ChunkProgressFn& progress, const char* stage) {
  threads = std::max(1, threads);
  const size_t batch = threads == 1 ? 1 : 4 * size_t(threads);
  std::vector<std::array<std::shared_ptr<const TileData>, 27>> hold(batch);
  std::vector<ChunkNeighbourhood> hoods(batch);
  std::vector<std::optional<absl::StatusOr<Result>>> results(batch);
  for (size_t first = 0; first < chunks.size(); first += batch) {
    const size_t n = std::min(batch, chunks.size() - first);
    if (threads > 1) {
      std::vector<ChunkKey> needed;
      for (size_t k = 0; k < n; ++k) {
        for (int dz = -1; dz <= 1; ++dz) {
          for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
              if (low_only && (dx > 0 || dy > 0 || dz > 0)) continue;
              needed.push_back(chunks[first + k] + ChunkKey(dx, dy, dz));
            }
          }
        }
      }
      if (absl::Status s = tiles.Prefetch(needed, threads); !s.ok()) return s;
    }
    for (size_t k = 0; k < n; ++k) {
      absl::StatusOr<ChunkNeighbourhood> hood =
          FetchNeighbourhood(tiles, chunks[first + k], low_only, hold[k]);
      if (!hood.ok()) return hood.status();
      hoods[k] = *hood;
    }
    ParallelFor(n, threads, [&](size_t k) { results[k].emplace(compute(hoods[k])); });
    for (size_t k = 0; k < n; ++k) {
      absl::StatusOr<Result>& r = *results[k];
      if (!r.ok()) return r.status();
      if constexpr (std::is_same_v<decltype(take(*std::move(r))), absl::Status>) {
        if (absl::Status s = take(*std::move(r)); !s.ok()) return s;
      } else {
        take(*std::move(r));
      }
      results[k].reset();
      if (progress && !progress(first + k + 1, chunks.size())) {
        return absl::CancelledError(absl::StrCat(stage, ": cancelled"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace carvemap
