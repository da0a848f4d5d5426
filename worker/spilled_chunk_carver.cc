#include "worker/spilled_chunk_carver.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <thread>

#include "absl/strings/str_cat.h"
#include "worker/chunk_carver.h"

namespace carvemap {

absl::StatusOr<SpilledChunkCarveTotals> CarveSpilledChunks(
    const std::vector<SpilledChunk>& chunks, const SpilledChunkCarveOptions& options,
    const std::function<void(const SpilledChunkCarveProgress&)>& progress) {
  if (options.threads < 1) return absl::InvalidArgumentError("threads must be >= 1");
  // Biggest first, so a large chunk does not start last and leave the other threads idle.
  std::vector<size_t> order(chunks.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return chunks[a].wedge_count > chunks[b].wedge_count;
  });
  SpilledChunkCarveProgress state;
  state.chunks_total = chunks.size();
  for (const SpilledChunk& c : chunks) state.pairs_total += c.wedge_count;

  std::mutex mu;
  std::condition_variable cv;
  absl::Status first_error;        // guarded by mu
  SpilledChunkCarveTotals totals;  // guarded by mu
  totals.tile_paths.resize(chunks.size());
  std::atomic<size_t> next{0};
  std::atomic<bool> failed{false};

  auto work = [&] {
    while (!failed.load()) {
      const size_t k = next.fetch_add(1);
      if (k >= order.size()) break;
      const SpilledChunk& c = chunks[order[k]];
      absl::StatusOr<CarveChunkResult> r = absl::UnknownError("not carved");
      absl::StatusOr<ChunkSpillFile> file = ReadChunkSpillFile(c.path);
      if (!file.ok()) {
        r = file.status();
      } else {
        CarveChunkRequest req;
        req.job_id = options.job_id;
        req.chunk = c.chunk;
        req.grid = options.grid;
        req.wedge_payload = file->payload;
        req.tiles_dir = options.tiles_dir;
        req.evaluation = options.evaluation;
        if (auto it = options.regions.find(c.chunk); it != options.regions.end()) {
          req.region = &it->second;
        }
        r = CarveChunkToTile(req);
      }
      std::lock_guard<std::mutex> lock(mu);
      if (!r.ok()) {
        if (first_error.ok()) first_error = r.status();
        failed.store(true);
      } else {
        totals.tile_paths[order[k]] = r->tile_path;
        totals.tile_bytes += r->tile_bytes;
        totals.leaves += r->leaves;
        totals.leaf_updates += r->leaf_updates;
      }
      state.pairs_done += c.wedge_count;
      ++state.chunks_done;
      cv.notify_all();
    }
  };
  std::vector<std::thread> pool;
  const int n = std::max(1, std::min<int>(options.threads, static_cast<int>(chunks.size())));
  for (int i = 0; i < n; ++i) pool.emplace_back(work);
  {
    std::unique_lock<std::mutex> lock(mu);
    while (state.chunks_done < chunks.size() && !failed.load()) {
      cv.wait_for(lock, std::chrono::milliseconds(250));
      if (progress) progress(state);
    }
  }
  for (std::thread& t : pool) t.join();
  if (!first_error.ok()) return first_error;
  if (progress) progress(state);
  return totals;
}

absl::StatusOr<std::vector<SpilledChunk>> FindSpilledChunks(const std::string& spill_dir,
                                                            const std::vector<ChunkKey>& chunks) {
  std::vector<SpilledChunk> found;
  found.reserve(chunks.size());
  for (const ChunkKey& key : chunks) {
    SpilledChunk c;
    c.chunk = key;
    c.path = ChunkSpillPath(spill_dir, key);
    std::error_code ec;
    c.file_bytes = std::filesystem::file_size(c.path, ec);
    if (ec) return absl::NotFoundError(absl::StrCat(c.path, ": no spill file: ", ec.message()));
    found.push_back(std::move(c));
  }
  return found;
}

}  // namespace carvemap
