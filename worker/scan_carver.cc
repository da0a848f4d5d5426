#include "worker/scan_carver.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <thread>

#include "absl/strings/str_cat.h"
#include "storage/hdf5_lock.h"
#include "storage/partial_sums.h"
#include "storage/scan_reader.h"
#include "worker/chunk_combiner.h"
#include "worker/slice_carver.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Runs work(i) for i in `order` on `threads` threads until one fails; calls tick() from this
// thread every 250 ms and once at the end. Returns the first error.
absl::Status RunPool(const std::vector<size_t>& order, int threads,
                     const std::function<absl::Status(size_t)>& work,
                     const std::function<void()>& tick) {
  std::mutex mu;
  std::condition_variable cv;
  absl::Status first_error;
  size_t finished = 0;
  std::atomic<size_t> next{0};
  std::atomic<bool> failed{false};
  auto run = [&] {
    while (!failed.load()) {
      const size_t k = next.fetch_add(1);
      if (k >= order.size()) break;
      absl::Status s = work(order[k]);
      std::lock_guard<std::mutex> lock(mu);
      if (!s.ok() && first_error.ok()) {
        first_error = s;
        failed.store(true);
      }
      ++finished;
      cv.notify_all();
    }
  };
  std::vector<std::thread> pool;
  const int n = std::max(1, std::min<int>(threads, int(order.size())));
  for (int i = 0; i < n && !order.empty(); ++i) pool.emplace_back(run);
  {
    std::unique_lock<std::mutex> lock(mu);
    while (finished < order.size() && !failed.load()) {
      cv.wait_for(lock, std::chrono::milliseconds(250));
      lock.unlock();
      if (tick) tick();
      lock.lock();
    }
  }
  for (std::thread& t : pool) t.join();
  if (tick) tick();
  return first_error;
}

}  // namespace

absl::StatusOr<ScanCarveTotals> CarveScan(
    const std::string& scan_path, const ScanCarveOptions& options,
    const std::function<void(const ScanCarveProgress&)>& progress) {
  if (options.threads < 1) return absl::InvalidArgumentError("carve: threads must be >= 1");
  if (options.partials_dir.empty() || options.tiles_dir.empty()) {
    return absl::InvalidArgumentError("carve: no partials or tiles directory");
  }
  const Clock::time_point t0 = Clock::now();
  ScanCarveTotals totals;
  totals.bounds.setEmpty();

  // The plan: every sensor's frame rows, cut by time.
  absl::StatusOr<ScanSlicePlan> plan;
  {
    std::lock_guard<std::mutex> lock(Hdf5Lock());
    ScanReader::OpenOptions open;
    open.path_rows = ScanReader::PathRows::kNone;  // the frame tables only
    absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path, open);
    if (!reader.ok()) return reader.status();
    plan = PlanScanSlices(**reader, options.slices);
  }
  if (!plan.ok()) return plan.status();
  totals.slice_s = plan->slice_s;
  std::vector<ScanSlice>& slices = plan->slices;
  totals.slices = slices.size();

  std::error_code ec;
  fs::create_directories(options.partials_dir, ec);
  if (!ec) fs::create_directories(options.tiles_dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat("carve: cannot create directories: ",
                                                     ec.message()));

  // The slices, biggest first (they are independent).
  SliceCarveOptions so;
  so.grid = options.grid;
  so.evaluation = options.evaluation;
  so.wedges = options.wedges;
  so.regions = options.regions;
  so.memory_budget_bytes = options.memory_budget_bytes;
  std::vector<std::string> partials(slices.size());
  std::vector<SliceCarveStats> stats(slices.size());
  std::vector<std::atomic<uint64_t>> slice_rays(slices.size());
  const uint64_t rays_total = plan->rays;  // the slices' own rows partition every frame
  std::vector<size_t> order(slices.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return slices[a].own_rays > slices[b].own_rays; });
  std::atomic<uint64_t> slices_done{0};
  const auto tick_slices = [&] {
    if (!progress) return;
    ScanCarveProgress p;
    p.stage = "slices";
    p.done = slices_done.load();
    p.total = slices.size();
    for (const auto& r : slice_rays) p.rays_done += r.load();
    p.rays_total = rays_total;
    progress(p);
  };
  absl::Status carved = RunPool(
      order, options.threads,
      [&](size_t i) -> absl::Status {
        const ScanSlice& s = slices[i];
        partials[i] = (fs::path(options.partials_dir) / absl::StrCat("slice_", s.index, ".part"))
                          .string();
        std::unique_ptr<ScanReader> reader;
        {
          std::lock_guard<std::mutex> lock(Hdf5Lock());
          ScanReader::OpenOptions open = SliceOpenOptions(s);
          open.world_yaw_rad = options.world_yaw_rad;
          absl::StatusOr<std::unique_ptr<ScanReader>> r = ScanReader::Open(scan_path, open);
          if (!r.ok()) return r.status();
          reader = *std::move(r);
        }
        absl::StatusOr<SliceCarveStats> st = CarveSliceToFile(
            *reader, s, so, partials[i], [&slice_rays, i](uint64_t r) { slice_rays[i] = r; });
        {
          std::lock_guard<std::mutex> lock(Hdf5Lock());
          reader.reset();  // closing the file is HDF5 too
        }
        if (!st.ok()) return st.status();
        stats[i] = *st;
        ++slices_done;
        return absl::OkStatus();
      },
      tick_slices);
  if (!carved.ok()) return carved;
  for (const SliceCarveStats& st : stats) {
    totals.frames += st.frames;
    totals.rays += st.rays;
    totals.returns += st.returns;
    totals.wedges += st.wedges;
    totals.wedge_chunk_pairs += st.wedge_chunk_pairs;
    totals.leaf_updates += st.leaf_updates;
    totals.default_covariance |= st.default_covariance;
    totals.bounds.extend(st.bounds);
  }
  totals.slices_elapsed_s = SecondsSince(t0);

  // Combine: every chunk's sections in slice order.
  const Clock::time_point t1 = Clock::now();
  std::vector<PartialSource> sources;
  for (const std::string& p : partials) {
    absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(p);
    if (!index.ok()) return index.status();
    totals.partial_bytes += fs::file_size(p, ec);
    sources.push_back({p, *std::move(index)});
  }
  const SectionsByChunk sections = GroupSections(sources);
  std::vector<std::pair<ChunkKey, const std::vector<std::pair<size_t, size_t>>*>> chunks;
  for (const auto& [chunk, list] : sections) chunks.push_back({chunk, &list});
  totals.chunks.reserve(chunks.size());
  for (const auto& c : chunks) totals.chunks.push_back(c.first);
  totals.tile_paths.resize(chunks.size());
  std::vector<CarveChunkResult> results(chunks.size());
  std::vector<size_t> chunk_order(chunks.size());
  for (size_t i = 0; i < chunk_order.size(); ++i) chunk_order[i] = i;
  std::atomic<uint64_t> chunks_done{0};
  absl::Status combined = RunPool(
      chunk_order, options.threads,
      [&](size_t i) -> absl::Status {
        CombineChunkRequest req;
        req.job_id = options.job_id;
        req.chunk = chunks[i].first;
        req.grid = options.grid;
        req.sources = &sources;
        req.sections = *chunks[i].second;
        req.tiles_dir = options.tiles_dir;
        absl::StatusOr<CarveChunkResult> r = CombineChunkToTile(req);
        if (!r.ok()) return r.status();
        results[i] = *std::move(r);
        ++chunks_done;
        return absl::OkStatus();
      },
      [&] {
        if (!progress) return;
        ScanCarveProgress p;
        p.stage = "combine";
        p.done = chunks_done.load();
        p.total = chunks.size();
        p.rays_done = p.rays_total = rays_total;
        progress(p);
      });
  if (!combined.ok()) return combined;
  for (size_t i = 0; i < results.size(); ++i) {
    totals.tile_paths[i] = results[i].tile_path;
    totals.tile_bytes += results[i].tile_bytes;
    totals.leaves += results[i].leaves;
  }
  totals.combine_elapsed_s = SecondsSince(t1);
  if (!options.keep_partials) fs::remove_all(options.partials_dir, ec);
  return totals;
}

}  // namespace carvemap
