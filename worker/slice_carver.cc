#include "worker/slice_carver.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "coordinator/chunk_binning.h"
#include "geometry/wedge_geometry.h"
#include "storage/hdf5_lock.h"
#include "storage/partial_sums.h"

namespace carvemap {
namespace {

// A frame of one sensor: its rays are RayId::index within it.
struct FrameKey {
  uint32_t sensor;
  uint64_t frame;
  bool operator==(const FrameKey&) const = default;
  template <typename H>
  friend H AbslHashValue(H h, const FrameKey& k) {
    return H::combine(std::move(h), k.sensor, k.frame);
  }
};

constexpr uint32_t kNoRay = std::numeric_limits<uint32_t>::max();
// A batch's vectors are reserved for at most this many rays (72 MiB of RayModel).
constexpr uint64_t kMaxReservedRays = uint64_t{1} << 20;

// One batch's wedges, each ray stored once for the whole batch (a ray's wedges reach ~2 chunks
// on average): chunks list their wedges by batch ray ids, and each chunk's IndexedWedges (its
// rays once, eq 4.8's S(L) a set) is made when the chunk is carved. Rays are found by frame and
// index, not hashed one by one: a wedge's rays lie in one or two frames.
struct Batch {
  int64_t index = 0;
  std::vector<RayModel> rays;  // by batch ray id, in order of first use
  std::vector<uint8_t> votes;  // by batch ray id: whether the ray votes in this batch
  std::vector<Eigen::Vector3d> far_ends;  // by batch ray id: ExtendedPointMean, for the hulls
  absl::flat_hash_map<FrameKey, uint32_t> frame_slot;   // frame → its entry in frame_ids
  std::vector<std::vector<uint32_t>> frame_ids;         // a frame's batch ray id by ray index
  FrameKey last_frame[2] = {{kNoRay, 0}, {kNoRay, 0}};  // the frames looked up last, and
  uint32_t last_slot[2] = {0, 0};                       // their entries
  std::vector<WedgeRef> wedges;  // WedgeRef::ray: batch ray ids
  // Each chunk's wedges (indices into `wedges`: a wedge reaches ~2 chunks).
  std::map<ChunkKey, std::vector<uint32_t>, ChunkKeyLess> chunks;

  // The batch ray id of frame `key`'s ray `index` (kNoRay the first time).
  uint32_t& RayOf(const FrameKey& key, uint32_t index) {
    int hit = key == last_frame[0] ? 0 : (key == last_frame[1] ? 1 : -1);
    if (hit < 0) {
      auto [it, inserted] = frame_slot.try_emplace(key, uint32_t(frame_ids.size()));
      if (inserted) frame_ids.emplace_back();
      last_frame[1] = last_frame[0];
      last_slot[1] = last_slot[0];
      last_frame[0] = key;
      last_slot[0] = it->second;
      hit = 0;
    }
    std::vector<uint32_t>& ids = frame_ids[last_slot[hit]];
    if (index >= ids.size()) ids.resize(size_t(index) + 1, kNoRay);
    return ids[index];
  }
};

}  // namespace

absl::Status SliceCarveOptions::Validate() const {
  if (grid.chunk_depth < kMinChunkDepth || grid.chunk_depth > kMaxChunkDepth) {
    return absl::InvalidArgumentError(absl::StrCat("slice carve: chunk depth ", grid.chunk_depth,
                                                   " outside [", kMinChunkDepth, ", ",
                                                   kMaxChunkDepth, "]"));
  }
  if (batch_rays == 0) return absl::InvalidArgumentError("slice carve: batch_rays is 0");
  if (memory_budget_bytes == 0) {
    return absl::InvalidArgumentError("slice carve: memory_budget_bytes is 0");
  }
  return wedges.Validate();
}

struct SliceCarver::Impl {
  std::vector<SensorInfo> sensors;
  ScanSlice slice;
  SliceCarveOptions options;
  SectionSink sink;
  std::optional<WedgeBuilder> builder;
  SliceCarveStats stats;

  // Per sensor: the batch of each own frame (by row − own.begin), the batch of the last frame
  // fed (kAfter past the own rows), and whether its last frame to read has come (a line
  // sensor's last frame has wedges pending until Finish even then).
  static constexpr int64_t kAfter = std::numeric_limits<int64_t>::max();
  std::vector<std::vector<int64_t>> frame_batch;
  // Per sensor, by own row: the rays of each band of a frame larger than batch_rays (0: the
  // frame is one batch's). Only grid and points frames are cut (their wedges lie within the
  // frame), a grid's at whole pixel rows; band k is batch frame_batch + k.
  std::vector<std::vector<uint64_t>> frame_band;
  // While a banded frame's wedges come: the lowest batch they can still reach (the wedge
  // builder's row order), below which its bands are complete.
  int64_t emitting_from = kAfter;
  std::vector<int64_t> last_batch_fed;
  std::vector<bool> finished;
  std::vector<uint64_t> next_row;
  int64_t batch = 0;           // the batch own frames go to now
  uint64_t batch_own_rays = 0;  // own rays in it so far
  std::vector<uint64_t> own_rays_of_batch;  // by batch index
  uint64_t own_rays_carved = 0;             // of the batches carved whole
  std::function<void(uint64_t)> progress;

  std::deque<Batch> open;  // oldest first
  int64_t carved_up_to = -1;  // batches up to this one are carved
  std::map<ChunkKey, ChunkOctree, ChunkKeyLess> trees;
  // The pass's regions (options.regions) decoded since the last flush: those of chunks a wedge
  // reached, shared with their trees. A longer slice reaches more of a building's object
  // chunks, so they count in the budget with the sums and go with them at a flush.
  std::map<ChunkKey, std::shared_ptr<const ChunkRegion>, ChunkKeyLess> decoded;
  size_t tree_bytes = 0;    // Σ ChunkOctree::memory_bytes() of `trees`
  size_t region_bytes = 0;  // Σ ChunkRegion::memory_bytes() of `decoded`
  // CarveBatch's working memory, kept from one chunk and batch to the next.
  IndexedWedges chunk_wedges;
  std::vector<uint32_t> local_of;    // batch ray id → the chunk's ray index (kNoRay: none yet)
  std::vector<uint32_t> chunk_rays;  // the chunk's rays' batch ids
  uint64_t flushed_updates = 0;

  [[nodiscard]] bool Owned(uint32_t sensor, uint64_t row) const {
    const ScanReader::RowRange& own = slice.own[sensor];
    return row >= own.begin && row < own.end;
  }
  [[nodiscard]] int64_t BatchOf(uint32_t sensor, uint64_t row, uint32_t index) const {
    const uint64_t own = row - slice.own[sensor].begin;
    const uint64_t band = frame_band[sensor][own];
    return frame_batch[sensor][own] + (band == 0 ? 0 : int64_t(index / band));
  }
  absl::StatusOr<Batch*> OpenBatch(int64_t b) {
    // A batch is carved only once no sensor can add to it (CarveCompleteBatches).
    if (b <= carved_up_to) {
      return absl::InternalError(absl::StrCat("slice carve: a wedge for batch ", b,
                                              ", carved already"));
    }
    for (Batch& x : open) {
      if (x.index == b) return &x;
    }
    auto at = std::find_if(open.begin(), open.end(), [b](const Batch& x) { return x.index > b; });
    at = open.insert(at, Batch{});
    at->index = b;
    // About what the batch will hold (its own rays, few of its neighbours'): growing the
    // vector by copies cost more than the wedges' binning. Pages are only taken when written;
    // a batch_rays meaning "one batch" is not reserved whole.
    const size_t expected = std::min<uint64_t>(options.batch_rays, kMaxReservedRays);
    at->rays.reserve(expected);
    at->votes.reserve(expected);
    at->far_ends.reserve(expected);
    at->wedges.reserve(expected);
    return &*at;
  }

  // The pass's region of `chunk`, decoded the first time it is asked for; null when the chunk
  // is not in the pass.
  absl::StatusOr<const ChunkRegion*> RegionOf(const ChunkKey& chunk) {
    auto it = decoded.find(chunk);
    if (it != decoded.end()) return it->second.get();
    auto encoded = options.regions->find(chunk);
    if (encoded == options.regions->end()) return nullptr;
    absl::StatusOr<ChunkRegion> region = encoded->second.Decode();
    if (!region.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("slice carve: the region of chunk ",
                                                     chunk.x(), ",", chunk.y(), ",", chunk.z(),
                                                     ": ", region.status().message()));
    }
    region_bytes += region->memory_bytes();
    return decoded.emplace(chunk, std::make_shared<const ChunkRegion>(*std::move(region)))
        .first->second.get();
  }
  // Whether `box` meets the region of a chunk of the pass (regions set). A box across more
  // chunks than kMaxBoxChunks is taken to: looking them all up would cost more than the hull.
  absl::StatusOr<bool> MayReachRegions(const Eigen::AlignedBox3d& box) {
    constexpr int kMaxBoxChunks = 8;
    const ChunkKey lo = ChunkOf(box.min()), hi = ChunkOf(box.max());
    // In 64 bits: world coordinates reach ±1e6 m (kMaxWorldCoordinateM), 1e6 chunks a side.
    if ((hi - lo + Eigen::Vector3i::Ones()).cast<int64_t>().prod() > kMaxBoxChunks) return true;
    for (int z = lo.z(); z <= hi.z(); ++z) {
      for (int y = lo.y(); y <= hi.y(); ++y) {
        for (int x = lo.x(); x <= hi.x(); ++x) {
          const ChunkKey c(x, y, z);
          absl::StatusOr<const ChunkRegion*> region = RegionOf(c);
          if (!region.ok()) return region.status();
          const Eigen::Vector3d origin = c.cast<double>() * kChunkSizeM;
          if (*region != nullptr &&
              (*region)->IntersectsBox(box.min() - origin, box.max() - origin)) {
            return true;
          }
        }
      }
    }
    return false;
  }
  absl::Status OnWedge(const Wedge& wedge, std::span<const RayId> ids);
  absl::Status CarveBatch(Batch& batch);
  absl::Status Flush();
  absl::Status CarveCompleteBatches(bool all);
};

absl::Status SliceCarver::Impl::OnWedge(const Wedge& wedge, std::span<const RayId> ids) {
  // The batches this wedge serves: those of its own rays.
  int64_t batches[4];
  int nb = 0;
  for (int r = 0; r < wedge.num_rays; ++r) {
    if (!Owned(ids[r].sensor, ids[r].frame)) continue;
    const int64_t b = BatchOf(ids[r].sensor, ids[r].frame, ids[r].index);
    if (std::find(batches, batches + nb, b) == batches + nb) batches[nb++] = b;
  }
  if (nb == 0) return absl::OkStatus();  // context alone: another slice's
  if (const int64_t lowest = *std::min_element(batches, batches + nb); lowest > emitting_from) {
    // A banded frame has moved past its earlier bands: carve them now.
    emitting_from = lowest;
    if (absl::Status s = CarveCompleteBatches(false); !s.ok()) return s;
  }
  if (absl::Status s = ValidateWedge(wedge); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("slice carve: sensor ",
                                                   sensors[ids[0].sensor].name, " frame ",
                                                   ids[0].frame, ": ", s.message()));
  }
  for (int r = 0; r < wedge.num_rays; ++r) {
    for (const Eigen::Vector3f& v : {wedge.rays[r].sensor_mean, wedge.rays[r].point_mean}) {
      if ((v.array().abs() >= float(kMaxWorldCoordinateM)).any()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "slice carve: sensor ", sensors[ids[r].sensor].name, " frame ", ids[r].frame,
            ": a ray reaches beyond ±", kMaxWorldCoordinateM, " m (a broken pose?)"));
      }
    }
  }
  ++stats.wedges;
  // The wedge's rays in each batch it serves, with their far ends computed once per batch ray
  // (a 3×3 inverse each, and a ray belongs to up to four wedges): this hull and the chunks'
  // (CarveIndexed) are built from the same points.
  std::array<std::array<uint32_t, 4>, 4> batch_ids;
  std::array<Eigen::Vector3d, 4> sensor_means, far_ends;
  for (int i = 0; i < nb; ++i) {
    absl::StatusOr<Batch*> opened = OpenBatch(batches[i]);
    if (!opened.ok()) return opened.status();
    Batch& batch = **opened;
    for (int r = 0; r < wedge.num_rays; ++r) {
      uint32_t& id = batch.RayOf({ids[r].sensor, ids[r].frame}, ids[r].index);
      if (id == kNoRay) {
        id = uint32_t(batch.rays.size());
        batch.rays.push_back(wedge.rays[r]);
        const bool votes = Owned(ids[r].sensor, ids[r].frame) &&
                           BatchOf(ids[r].sensor, ids[r].frame, ids[r].index) == batches[i];
        batch.votes.push_back(votes ? 1 : 0);
        batch.far_ends.push_back(i == 0 ? ExtendedPointMean(wedge.rays[r], kWedgeHullSigmas)
                                        : far_ends[r]);
      }
      batch_ids[i][r] = id;
      if (i == 0) far_ends[r] = batch.far_ends[id];
    }
  }
  auto extend_bounds = [&] {
    for (int r = 0; r < wedge.num_rays; ++r) {
      if (!Owned(ids[r].sensor, ids[r].frame)) continue;
      stats.bounds.extend(wedge.rays[r].sensor_mean.cast<double>());
      stats.bounds.extend(wedge.rays[r].point_mean.cast<double>());
    }
  };
  for (int r = 0; r < wedge.num_rays; ++r) {
    sensor_means[r] = wedge.rays[r].sensor_mean.cast<double>();
  }
  if (options.regions != nullptr && wedge.num_rays > 1) {
    absl::StatusOr<bool> may = MayReachRegions(WedgePointsBox(
        {sensor_means.data(), size_t(wedge.num_rays)}, {far_ends.data(), size_t(wedge.num_rays)}));
    if (!may.ok()) return may.status();
    if (!*may) {  // in no region of the pass: no chunk to carve, so no hull to build
      extend_bounds();
      return absl::OkStatus();
    }
  }
  uint64_t facets = 0;  // the hull's facets: the carve rebuilds it from them, without a search
  WedgeHull hull;
  if (wedge.num_rays == 1) {
    hull = MakeWedgeHull(wedge, kWedgeHullSigmas, &facets);
  } else {
    // As MakeWedgeHull, from the same points.
    hull = HullOfWedgePoints({sensor_means.data(), size_t(wedge.num_rays)},
                             {far_ends.data(), size_t(wedge.num_rays)}, &facets);
  }
  std::vector<ChunkKey> chunks = ChunksOfWedge(hull);
  if (options.regions != nullptr) {
    // §5.6.1: only chunks of the pass, and only where the hull's box meets their region.
    size_t kept = 0;
    for (const ChunkKey& c : chunks) {
      absl::StatusOr<const ChunkRegion*> region = RegionOf(c);
      if (!region.ok()) return region.status();
      const Eigen::Vector3d origin = c.cast<double>() * kChunkSizeM;
      if (*region != nullptr &&
          (*region)->IntersectsBox(hull.box.min() - origin, hull.box.max() - origin)) {
        chunks[kept++] = c;
      }
    }
    chunks.resize(kept);
  }
  extend_bounds();
  if (chunks.empty()) return absl::OkStatus();
  for (int i = 0; i < nb; ++i) {
    absl::StatusOr<Batch*> opened = OpenBatch(batches[i]);
    if (!opened.ok()) return opened.status();
    Batch& batch = **opened;
    WedgeRef ref;
    ref.num_rays = wedge.num_rays;
    ref.facets = facets;
    for (int r = 0; r < wedge.num_rays; ++r) ref.ray[r] = batch_ids[i][r];
    const uint32_t w = uint32_t(batch.wedges.size());
    batch.wedges.push_back(ref);
    for (const ChunkKey& c : chunks) {
      batch.chunks[c].push_back(w);
      ++stats.wedge_chunk_pairs;
    }
  }
  return absl::OkStatus();
}

absl::Status SliceCarver::Impl::CarveBatch(Batch& batch) {
  ++stats.batches;
  carved_up_to = batch.index;
  const uint64_t own =
      size_t(batch.index) < own_rays_of_batch.size() ? own_rays_of_batch[batch.index] : 0;
  uint64_t pairs = 0, pairs_done = 0;
  for (const auto& [chunk, wedges] : batch.chunks) pairs += wedges.size();
  // A chunk's rays are numbered in the order its wedges first name them, each once.
  local_of.assign(batch.rays.size(), kNoRay);
  for (auto& [chunk, wedges] : batch.chunks) {
    pairs_done += wedges.size();
    auto [it, inserted] = trees.try_emplace(chunk, options.grid, chunk);
    ChunkOctree& tree = it->second;
    if (inserted) {
      tree.SetPartial(true);
      tree.SetEvaluation(options.evaluation);
      if (options.regions != nullptr) {
        // Decoded when the chunk was binned, unless a flush since then let it go.
        if (absl::StatusOr<const ChunkRegion*> r = RegionOf(chunk); !r.ok()) return r.status();
        tree.RestrictTo(decoded.at(chunk));
      }
    }
    IndexedWedges& in = chunk_wedges;
    in.rays.clear();
    in.votes.clear();
    in.wedges.clear();
    in.far_ends.clear();
    chunk_rays.clear();
    for (uint32_t w : wedges) {
      WedgeRef ref = batch.wedges[w];
      for (int r = 0; r < ref.num_rays; ++r) {
        uint32_t& local = local_of[ref.ray[r]];
        if (local == kNoRay) {
          local = uint32_t(in.rays.size());
          in.rays.push_back(batch.rays[ref.ray[r]]);
          in.votes.push_back(batch.votes[ref.ray[r]]);
          in.far_ends.push_back(batch.far_ends[ref.ray[r]]);
          chunk_rays.push_back(ref.ray[r]);
        }
        ref.ray[r] = local;
      }
      in.wedges.push_back(ref);
    }
    for (uint32_t id : chunk_rays) local_of[id] = kNoRay;
    const size_t before = tree.memory_bytes();
    if (absl::Status s = tree.CarveIndexed(in); !s.ok()) return s;
    tree_bytes += tree.memory_bytes() - before;
    // The chunk's wedges are done with: give the memory back now, not at the batch's end.
    wedges = std::vector<uint32_t>();
    // Checked after every chunk, not once per batch: a batch's chunks can add more sums than
    // the whole budget. Each chunk is carved once per batch, so a flush here splits no chunk.
    if (tree_bytes + region_bytes > options.memory_budget_bytes) {
      if (absl::Status s = Flush(); !s.ok()) return s;
    }
    if (progress) {
      progress(own_rays_carved + uint64_t(double(own) * double(pairs_done) / double(pairs)));
    }
  }
  own_rays_carved += own;
  if (progress) progress(own_rays_carved);
  return absl::OkStatus();
}

absl::Status SliceCarver::Impl::Flush() {
  ++stats.flushes;
  for (auto& [chunk, tree] : trees) {
    const std::vector<TileLeaf> leaves = tree.FinestLeaves();
    if (absl::Status s = sink(chunk, tree.num_wedges(), leaves); !s.ok()) return s;
    ++stats.sections;
  }
  // The votes counted so far stay in the stats: the trees go.
  for (const auto& [chunk, tree] : trees) flushed_updates += tree.num_leaf_updates();
  trees.clear();
  tree_bytes = 0;
  decoded.clear();
  region_bytes = 0;
  return absl::OkStatus();
}

absl::Status SliceCarver::Impl::CarveCompleteBatches(bool all) {
  while (!open.empty()) {
    const int64_t b = open.front().index;
    // Complete when no sensor can still emit a wedge with a ray of batch b. No own frame joins
    // b any more once a later batch has begun, or b holds batch_rays own rays (the next own
    // frame begins a new one), or no frame is left to read. Then only a line sensor whose
    // last frame fed is in b can add to it: that frame still joins its next one, or, the last,
    // still has its single-ray wedges to come (WedgeBuilder::Finish). A grid's or a points
    // sensor's wedges lie within one frame, so a batch of a few large frames is carved as soon
    // as its last frame is in, before the next one is read.
    bool complete = all;
    if (!complete) {
      complete = b < emitting_from &&
                 (b < batch || batch_own_rays >= options.batch_rays ||
                  std::all_of(finished.begin(), finished.end(), [](bool f) { return f; }));
      for (size_t s = 0; s < sensors.size() && complete; ++s) {
        complete = sensors[s].kind != SensorKind::kLine || last_batch_fed[s] != b;
      }
    }
    if (!complete) break;
    Batch batch = std::move(open.front());
    open.pop_front();
    if (absl::Status s = CarveBatch(batch); !s.ok()) return s;
  }
  return absl::OkStatus();
}

SliceCarver::SliceCarver(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SliceCarver::~SliceCarver() = default;

absl::StatusOr<std::unique_ptr<SliceCarver>> SliceCarver::Create(std::vector<SensorInfo> sensors,
                                                                 const ScanSlice& slice,
                                                                 const SliceCarveOptions& options,
                                                                 SectionSink sink) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (!sink) return absl::InvalidArgumentError("slice carve: no section sink");
  if (slice.own.size() != sensors.size() || slice.read.size() != sensors.size()) {
    return absl::InvalidArgumentError(absl::StrCat("slice carve: slice ", slice.index, " has ",
                                                   slice.own.size(), " row ranges for ",
                                                   sensors.size(), " sensors"));
  }
  auto impl = std::make_unique<Impl>();
  impl->sensors = sensors;
  impl->slice = slice;
  impl->options = options;
  impl->sink = std::move(sink);
  impl->stats.bounds.setEmpty();
  const size_t n = sensors.size();
  impl->frame_batch.resize(n);
  impl->frame_band.resize(n);
  impl->last_batch_fed.assign(n, -1);
  impl->finished.assign(n, false);
  impl->next_row.resize(n);
  for (size_t s = 0; s < n; ++s) {
    const ScanReader::RowRange& own = slice.own[s];
    const ScanReader::RowRange& read = slice.read[s];
    if (own.begin > own.end || read.begin > own.begin || read.end < own.end) {
      return absl::InvalidArgumentError(absl::StrCat("slice carve: slice ", slice.index,
                                                     " sensor ", s, ": own rows outside its "
                                                     "read rows"));
    }
    impl->frame_batch[s].assign(own.end - own.begin, -1);
    impl->frame_band[s].assign(own.end - own.begin, 0);
    impl->finished[s] = read.begin == read.end;
    impl->next_row[s] = read.begin;
  }
  Impl* m = impl.get();
  absl::StatusOr<WedgeBuilder> builder = WedgeBuilder::Create(
      std::move(sensors), options.wedges,
      [m](const Wedge& w, std::span<const RayId> ids) { return m->OnWedge(w, ids); });
  if (!builder.ok()) return builder.status();
  impl->builder.emplace(*std::move(builder));
  return std::unique_ptr<SliceCarver>(new SliceCarver(std::move(impl)));
}

absl::Status SliceCarver::AddFrame(const ScanFrame& frame, const FrameContext& context) {
  Impl& m = *impl_;
  if (frame.sensor < 0 || size_t(frame.sensor) >= m.sensors.size()) {
    return absl::InvalidArgumentError(absl::StrCat("slice carve: frame of unknown sensor ",
                                                   frame.sensor));
  }
  const uint32_t s = uint32_t(frame.sensor);
  if (m.finished[s] || frame.row != m.next_row[s]) {
    return absl::InvalidArgumentError(absl::StrCat(
        "slice carve: sensor ", m.sensors[s].name, " row ", frame.row, " where row ",
        m.next_row[s], " of slice ", m.slice.index, "'s rows [", m.slice.read[s].begin, ", ",
        m.slice.read[s].end, ") was due"));
  }
  ++m.next_row[s];
  if (m.Owned(s, frame.row)) {
    // A new batch once the current one holds batch_rays own rays: at a frame, so the batches
    // follow from the slice's frames alone; a large grid or points frame in bands (frame_band).
    const uint64_t n = frame.points_sensor.size();
    const SensorInfo& info = m.sensors[s];
    uint64_t band = 0;
    if (info.kind != SensorKind::kLine && n > m.options.batch_rays) {
      band = info.kind == SensorKind::kGrid
                 ? std::max<uint64_t>(1, m.options.batch_rays / info.cols) * info.cols
                 : m.options.batch_rays;
    }
    if (m.batch_own_rays >= m.options.batch_rays || (band > 0 && m.batch_own_rays > 0)) {
      ++m.batch;
      m.batch_own_rays = 0;
    }
    const uint64_t own = frame.row - m.slice.own[s].begin;
    m.frame_batch[s][own] = m.batch;
    m.frame_band[s][own] = band;
    const uint64_t bands = band == 0 ? 1 : (n + band - 1) / band;
    if (band > 0) m.emitting_from = m.batch;
    m.own_rays_of_batch.resize(std::max<size_t>(m.own_rays_of_batch.size(), m.batch + bands), 0);
    for (uint64_t k = 0; k + 1 < bands; ++k) m.own_rays_of_batch[m.batch + k] += band;
    m.batch += int64_t(bands - 1);
    const uint64_t last = n - (bands - 1) * band;  // the last band's rays, or the whole frame's
    m.own_rays_of_batch[m.batch] += last;
    m.batch_own_rays += last;
    m.last_batch_fed[s] = m.batch;
    ++m.stats.frames;
    m.stats.rays += frame.points_sensor.size();
    for (const Eigen::Vector3f& p : frame.points_sensor) m.stats.returns += p.allFinite();
  } else if (frame.row >= m.slice.own[s].end) {
    m.last_batch_fed[s] = Impl::kAfter;
  }
  if (absl::Status st = m.builder->AddFrame(frame, context); !st.ok()) return st;
  m.emitting_from = Impl::kAfter;
  if (m.next_row[s] == m.slice.read[s].end) m.finished[s] = true;
  return m.CarveCompleteBatches(false);
}

absl::StatusOr<SliceCarveStats> SliceCarver::Finish() {
  Impl& m = *impl_;
  if (absl::Status s = m.builder->Finish(); !s.ok()) return s;
  if (absl::Status s = m.CarveCompleteBatches(true); !s.ok()) return s;
  if (absl::Status s = m.Flush(); !s.ok()) return s;
  m.stats.leaf_updates = m.flushed_updates;
  // Own rays of batches no wedge reached were never carved, but are done.
  m.own_rays_carved = m.stats.rays;
  if (m.progress) m.progress(m.own_rays_carved);
  return m.stats;
}

void SliceCarver::SetProgress(std::function<void(uint64_t)> progress) {
  impl_->progress = std::move(progress);
}

ScanReader::OpenOptions SliceOpenOptions(const ScanSlice& slice) {
  ScanReader::OpenOptions options;
  options.path_rows = ScanReader::PathRows::kFrames;
  options.frame_rows = slice.read;
  return options;
}

absl::StatusOr<SliceCarveStats> CarveSliceToFile(ScanReader& reader, const ScanSlice& slice,
                                                 const SliceCarveOptions& options,
                                                 const std::string& partial_path,
                                                 const std::function<void(uint64_t)>& progress) {
  absl::StatusOr<std::unique_ptr<PartialSumsWriter>> writer =
      PartialSumsWriter::Create(partial_path, options.grid.chunk_depth, slice.index);
  if (!writer.ok()) return writer.status();
  absl::StatusOr<std::unique_ptr<SliceCarver>> carver = SliceCarver::Create(
      reader.sensors(), slice, options,
      [&writer](const ChunkKey& chunk, uint64_t wedges, std::span<const TileLeaf> leaves) {
        return (*writer)->AddSection(chunk, wedges, leaves);
      });
  if (!carver.ok()) return carver.status();
  const std::vector<TimedPose>& path = reader.timed_path();
  std::span<const PathCovariance> cov;
  if (reader.path_covariance().has_value()) cov = *reader.path_covariance();
  std::unique_ptr<ScanReader::FrameStream> stream;
  {
    std::lock_guard<std::mutex> lock(Hdf5Lock());
    absl::StatusOr<std::unique_ptr<ScanReader::FrameStream>> s = reader.StreamFrames(slice.read);
    if (!s.ok()) return s.status();
    stream = *std::move(s);
  }
  if (progress) (*carver)->SetProgress(progress);
  ScanFrame frame;
  while (true) {
    absl::StatusOr<bool> more;
    {
      std::lock_guard<std::mutex> lock(Hdf5Lock());
      more = stream->Next(frame);
    }
    if (!more.ok()) return more.status();
    if (!*more) break;
    absl::StatusOr<FrameContext> ctx = FrameContextAt(path, cov, frame.t, options.wedges.noise);
    if (!ctx.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat(reader.file(), ": frame at t=", frame.t, ": ", ctx.status().message()));
    }
    if (absl::Status s = (*carver)->AddFrame(frame, *ctx); !s.ok()) {
      return absl::Status(s.code(), absl::StrCat(reader.file(), ": ", s.message()));
    }
  }
  absl::StatusOr<SliceCarveStats> stats = (*carver)->Finish();
  if (!stats.ok()) return stats.status();
  stats->default_covariance = cov.empty();
  if (absl::StatusOr<uint64_t> bytes = (*writer)->Finish(); !bytes.ok()) return bytes.status();
  return stats;
}

}  // namespace carvemap
