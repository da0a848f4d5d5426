#include "worker/chunk_octree.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <bit>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <utility>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_cat.h"
#include "geometry/carve_map.h"
#include "geometry/carve_map_float.h"
#include "geometry/wedge_geometry.h"
#include "worker/hull_raster.h"

namespace carvemap {
namespace {

bool Finite(const RayModel& ray) {
  if (!ray.sensor_mean.allFinite() || !ray.point_mean.allFinite()) return false;
  for (int i = 0; i < 6; ++i) {
    if (!std::isfinite(ray.sensor_cov[i]) || !std::isfinite(ray.point_cov[i])) return false;
  }
  return true;
}

// A ray's bits: copies of one ray in several wedge records compare equal.
struct RayBits {
  std::array<uint32_t, 18> v;
  explicit RayBits(const RayModel& r) {
    static_assert(sizeof(RayModel) == sizeof(v));
    std::memcpy(v.data(), &r, sizeof(v));
  }
  bool operator==(const RayBits& o) const { return v == o.v; }
  template <typename H>
  friend H AbslHashValue(H h, const RayBits& r) {
    return H::combine_contiguous(std::move(h), r.v.data(), r.v.size());
  }
};

// The fused sums of one call over the chunk's finest leaves: one dense array up to k = 6
// (262 144 leaves, 8 MiB), else 8³ bricks allocated on first touch (a dense array would be
// 537 MB at k = 8).
class LeafScratch {
 public:
  explicit LeafScratch(int k)
      : k_(k), shift_(k <= kDenseDepth ? k : 3), per_side_(1 << (k - shift_)),
        bricks_(size_t(per_side_) * per_side_ * per_side_) {}

  LeafStats& At(const Eigen::Vector3i& l) {
    const int m = (1 << shift_) - 1;
    const size_t b = size_t(l.x() >> shift_) +
                     size_t(per_side_) * (size_t(l.y() >> shift_) +
                                          size_t(per_side_) * size_t(l.z() >> shift_));
    std::unique_ptr<LeafStats[]>& brick = bricks_[b];
    if (!brick) {
      brick = std::make_unique<LeafStats[]>(size_t{1} << (3 * shift_));
      used_.push_back(uint32_t(b));
    }
    return brick[size_t(l.x() & m) | size_t(l.y() & m) << shift_ |
                 size_t(l.z() & m) << (2 * shift_)];
  }

  // Every leaf with votes, as (local, stats).
  template <typename F>
  void ForEach(F&& f) const {
    const int side = 1 << shift_;
    for (uint32_t b : used_) {
      const Eigen::Vector3i base(int(b % per_side_), int((b / per_side_) % per_side_),
                                 int(b / (size_t(per_side_) * per_side_)));
      const LeafStats* brick = bricks_[b].get();
      for (int z = 0; z < side; ++z)
        for (int y = 0; y < side; ++y)
          for (int x = 0; x < side; ++x) {
            const LeafStats& c =
                brick[size_t(x) | size_t(y) << shift_ | size_t(z) << (2 * shift_)];
            if (c.count > 0) f(Eigen::Vector3i(base * side + Eigen::Vector3i(x, y, z)), c);
          }
    }
  }

 private:
  static constexpr int kDenseDepth = 6;
  int k_;
  int shift_;  // a brick holds (2^shift)³ leaves; one brick when k ≤ kDenseDepth
  int per_side_;
  std::vector<std::unique_ptr<LeafStats[]>> bricks_;
  std::vector<uint32_t> used_;
};

// The fast path's sums over the chunk's finest leaves, for chunk depths up to kMaxDepth: one
// dense array (64³ leaves, 8 MiB at 3.125 cm), reused by every call on this thread so that a
// chunk costs no fresh pages, and a run of leaves is a pointer and a stride. The 8³ bricks
// that got votes are listed, so draining and clearing cost the voted volume, not the chunk's.
class DenseScratch {
 public:
  static constexpr int kMaxDepth = 6;

  // Empties the array for a chunk of depth k ≤ kMaxDepth (it is empty after Drain already).
  void Reset(int k) {
    assert(k <= kMaxDepth);
    if (k == k_) return;
    k_ = k;
    n_ = 1 << k;
    brick_shift_ = std::min(k, 3);
    bricks_per_side_ = n_ >> brick_shift_;
    cells_.assign(size_t(n_) * n_ * n_, LeafStats{});
    touched_.assign(size_t(bricks_per_side_) * bricks_per_side_ * bricks_per_side_, 0);
    used_.clear();
  }
  [[nodiscard]] ptrdiff_t Stride(int axis) const { return ptrdiff_t{1} << (k_ * axis); }
  [[nodiscard]] LeafStats* At(const Eigen::Vector3i& l) {
    return &cells_[size_t(l.x()) | size_t(l.y()) << k_ | size_t(l.z()) << (2 * k_)];
  }
  // Marks the bricks of leaves lo … hi along `axis` of the row through `l`.
  void Touch(const Eigen::Vector3i& l, int axis, int lo, int hi) {
    Eigen::Vector3i b(l.x() >> brick_shift_, l.y() >> brick_shift_, l.z() >> brick_shift_);
    for (int t = lo >> brick_shift_; t <= hi >> brick_shift_; ++t) {
      b[axis] = t;
      const uint32_t i = uint32_t(b.x() + bricks_per_side_ * (b.y() + bricks_per_side_ * b.z()));
      if (!touched_[i]) {
        touched_[i] = 1;
        used_.push_back(i);
      }
    }
  }
  // Calls f(local, stats) for every leaf with votes, then clears the array.
  template <typename F>
  void Drain(F&& f) {
    const int side = 1 << brick_shift_;
    for (uint32_t i : used_) {
      const Eigen::Vector3i base =
          Eigen::Vector3i(int(i % bricks_per_side_), int((i / bricks_per_side_) % bricks_per_side_),
                          int(i / (bricks_per_side_ * bricks_per_side_))) *
          side;
      for (int z = 0; z < side; ++z)
        for (int y = 0; y < side; ++y)
          for (int x = 0; x < side; ++x) {
            const Eigen::Vector3i l = base + Eigen::Vector3i(x, y, z);
            LeafStats& c = *At(l);
            if (c.count > 0) {
              f(l, c);
              c = LeafStats{};
            }
          }
      touched_[i] = 0;
    }
    used_.clear();
  }

 private:
  int k_ = -1, n_ = 0, brick_shift_ = 0, bricks_per_side_ = 0;
  std::vector<LeafStats> cells_;
  std::vector<uint8_t> touched_;
  std::vector<uint32_t> used_;
};

// The axis a ray runs most along: its rasters are listed in runs along it, so a run is a
// stretch of the ray (few, long runs) and eq 4.7 is stepped along it.
int RunAxis(const Eigen::Vector3d& direction) {
  const Eigen::Vector3d d = direction.cwiseAbs();
  return d.x() >= d.y() && d.x() >= d.z() ? 0 : (d.y() >= d.z() ? 1 : 2);
}

// Compressed rows: for each of n keys the values [begin[k], begin[k + 1]).
struct Csr {
  std::vector<uint32_t> begin, values, fill;
  template <typename Each>  // Each(emit) calls emit(key, value) for every pair, twice alike
  void Build(size_t n, Each&& each) {
    begin.assign(n + 1, 0);
    each([&](size_t key, uint32_t) { ++begin[key + 1]; });
    for (size_t k = 0; k < n; ++k) begin[k + 1] += begin[k];
    values.resize(begin[n]);
    fill.assign(begin.begin(), begin.end() - 1);
    each([&](size_t key, uint32_t value) { values[fill[key]++] = value; });
  }
  [[nodiscard]] std::span<const uint32_t> Row(size_t k) const {
    return {values.data() + begin[k], begin[k + 1] - begin[k]};
  }
};

// CarveIndexed's working memory, kept by each thread from one call to the next: a chunk's
// bookkeeping is a few hundred bytes per ray and per wedge, and allocated afresh for every
// chunk its pages cost more (faults and clearing) than the fast path's arithmetic. Holds the
// largest chunk's worth between calls.
struct CarveBuffers {
  std::vector<int8_t> axis;
  std::vector<Eigen::Vector3d> sensor_means, far_ends;
  Csr ray_wedges, voters, freed;
  std::vector<uint32_t> last_wedge, free_after;
  std::vector<uint8_t> axes_needed;
  std::vector<std::array<std::vector<LeafRun>, 3>> runs;
  std::vector<std::vector<LeafRun>> pool;
  std::vector<LeafRun> merged, merging;
  std::vector<double> par, lat_a, lat_b, vote_p, vote_w;
  std::vector<LeafStats*> cells;
  std::vector<float> row_w, row_p;
};

// out = the merge of sorted a and b, with no branch per element: which list's head is smaller
// is a coin toss that a branch predictor loses (a ray's wedges' runs interleave row by row).
void MergeSortedRuns(std::span<const LeafRun> a, std::span<const LeafRun> b,
                     std::vector<LeafRun>& out) {
  out.resize(a.size() + b.size());
  const LeafRun *x = a.data(), *x_end = x + a.size(), *y = b.data(), *y_end = y + b.size();
  LeafRun* o = out.data();
  while (x != x_end && y != y_end) {
    const bool from_b = *y < *x;
    *o++ = from_b ? *y : *x;
    y += from_b;
    x += !from_b;
  }
  o = std::copy(x, x_end, o);
  std::copy(y, y_end, o);
}

// Whether a multi-ray wedge's hull may reach a cell of `region`: the box WedgePointsBox puts
// around its hull meets one. A leaf the hull touches lies in that box, so a wedge this rejects
// would give no runs in the region: skipping it changes no bit of the carve, and saves building
// its hull (most wedges of a re-carved chunk pass far from its objects).
bool MayTouchRegion(const ChunkRegion& region, const Eigen::Vector3d& chunk_origin,
                    std::pair<const Eigen::Vector3d*, const Eigen::Vector3d*> points,
                    const WedgeRef& ref) {
  std::array<Eigen::Vector3d, 4> s, e;
  for (int r = 0; r < ref.num_rays; ++r) {
    s[r] = points.first[ref.ray[r]];
    e[r] = points.second[ref.ray[r]];
  }
  const Eigen::AlignedBox3d box =
      WedgePointsBox({s.data(), ref.num_rays}, {e.data(), ref.num_rays});
  return region.IntersectsBox(box.min() - chunk_origin, box.max() - chunk_origin);
}

// The fast path's votes of one ray in the leaves of its merged runs (sorted, along `axis`):
// eq 4.7 by FloatRay row by row (by the double path, rounded to float, for a ray FloatRay
// refuses) as w and p − 0.5, summed in double into the dense array (or the sparse bricks past
// its depth) in run order. Returns the votes with weight ≥ kMinRayWeight.
uint64_t VoteFast(const PreparedRay& ray, const FloatRay* float_ray, int axis,
                  std::span<const LeafRun> merged, const Eigen::Vector3d& chunk_origin,
                  double leaf_size, DenseScratch* dense, LeafScratch* sparse,
                  std::vector<float>& w, std::vector<float>& d) {
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const Eigen::Vector3d step = Eigen::Vector3d::Unit(axis) * leaf_size;
  uint64_t votes = 0;
  for (size_t i = 0; i < merged.size();) {
    // Overlapping or adjacent runs of one row are one stretch.
    const LeafRun first = merged[i];
    int hi = RunHi(first);
    size_t j = i + 1;
    for (; j < merged.size() && RunRow(merged[j]) == RunRow(first) && RunLo(merged[j]) <= hi + 1;
         ++j) {
      hi = std::max(hi, RunHi(merged[j]));
    }
    i = j;
    const int lo = RunLo(first);
    Eigen::Vector3i local;
    local[axis] = 0;
    local[u] = RunU(first);
    local[v] = RunV(first);
    // The centre of the row's leaf 0, as NodeBox computes centres.
    const Eigen::Vector3d box_lo = chunk_origin + local.cast<double>() * leaf_size;
    const Eigen::Vector3d row_origin = (box_lo + (box_lo + Eigen::Vector3d::Constant(leaf_size))) / 2.0;
    const size_t n = size_t(hi - lo + 1);
    w.resize(std::max(w.size(), n));
    d.resize(std::max(d.size(), n));
    if (float_ray != nullptr) {
      float_ray->EvaluateRow(local[u], local[v], lo, hi, w.data(), d.data());
    } else {
      for (int t = lo; t <= hi; ++t) {
        const CarveSample s = ray.Evaluate(row_origin + t * step);
        w[size_t(t - lo)] = float(s.w);
        d[size_t(t - lo)] = float(s.p - 0.5);
      }
    }
    if (dense != nullptr) {
      local[axis] = lo;
      dense->Touch(local, axis, lo, hi);
      LeafStats* cell = dense->At(local);
      const ptrdiff_t stride = dense->Stride(axis);
      for (size_t k = 0; k < n; ++k, cell += stride) {
        if (!(w[k] >= float(kMinRayWeight))) continue;
        cell->Add(0.5 + double(d[k]), w[k]);
        ++votes;
      }
    } else {
      for (size_t k = 0; k < n; ++k) {
        if (!(w[k] >= float(kMinRayWeight))) continue;
        local[axis] = lo + int(k);
        sparse->At(local).Add(0.5 + double(d[k]), w[k]);
        ++votes;
      }
    }
  }
  return votes;
}

}  // namespace

ChunkOctree::ChunkOctree(const OctreeGrid& grid, const ChunkKey& chunk)
    : grid_(grid), chunk_(chunk), levels_(static_cast<size_t>(grid.chunk_depth) + 1) {
  assert(grid.chunk_depth >= kMinChunkDepth && grid.chunk_depth <= kMaxChunkDepth);
}

absl::Status ChunkOctree::CarveWedges(std::span<const Wedge> wedges) {
  IndexedWedges indexed;
  indexed.wedges.reserve(wedges.size());
  absl::flat_hash_map<RayBits, uint32_t> ray_ids;
  for (size_t w = 0; w < wedges.size(); ++w) {
    const Wedge& wedge = wedges[w];
    if (wedge.num_rays < 1 || wedge.num_rays > 4) {
      return absl::InvalidArgumentError(absl::StrCat("chunk_octree: wedge ", w, " with ",
                                                     wedge.num_rays, " rays (expected 1 to 4)"));
    }
    WedgeRef ref;
    ref.num_rays = wedge.num_rays;
    for (int r = 0; r < wedge.num_rays; ++r) {
      if (!Finite(wedge.rays[r])) {
        return absl::InvalidArgumentError(absl::StrCat(
            "chunk_octree: wedge ", w, " ray ", r, " has a non-finite mean or covariance"));
      }
      auto [it, inserted] =
          ray_ids.try_emplace(RayBits(wedge.rays[r]), uint32_t(indexed.rays.size()));
      if (inserted) indexed.rays.push_back(wedge.rays[r]);
      ref.ray[r] = it->second;
    }
    indexed.wedges.push_back(ref);
  }
  return CarveIndexed(indexed);
}

absl::Status ChunkOctree::CarveIndexed(const IndexedWedges& in) {
  if (simplified_) {
    return absl::FailedPreconditionError("chunk_octree: CarveWedge after Simplify");
  }
  const size_t num_rays = in.rays.size(), num_wedges = in.wedges.size();
  for (size_t w = 0; w < num_wedges; ++w) {
    const WedgeRef& wedge = in.wedges[w];
    if (wedge.num_rays < 1 || wedge.num_rays > 4) {
      return absl::InvalidArgumentError(absl::StrCat("chunk_octree: wedge ", w, " with ",
                                                     wedge.num_rays, " rays (expected 1 to 4)"));
    }
    for (int r = 0; r < wedge.num_rays; ++r) {
      if (wedge.ray[r] >= num_rays) {
        return absl::InvalidArgumentError(absl::StrCat("chunk_octree: wedge ", w, " ray ", r,
                                                       " has index ", wedge.ray[r], " of ",
                                                       num_rays, " rays"));
      }
    }
  }
  for (size_t r = 0; r < num_rays; ++r) {
    if (!Finite(in.rays[r])) {
      return absl::InvalidArgumentError(
          absl::StrCat("chunk_octree: ray ", r, " has a non-finite mean or covariance"));
    }
  }
  if (!in.far_ends.empty() && in.far_ends.size() != num_rays) {
    return absl::InvalidArgumentError(absl::StrCat("chunk_octree: ", in.far_ends.size(),
                                                   " far ends for ", num_rays, " rays"));
  }
  if (!in.votes.empty() && in.votes.size() != num_rays) {
    return absl::InvalidArgumentError(absl::StrCat("chunk_octree: ", in.votes.size(),
                                                   " vote flags for ", num_rays, " rays"));
  }
  const auto votes = [&in](size_t r) { return in.votes.empty() || in.votes[r] != 0; };
  num_wedges_ += num_wedges;

  // 1. Every ray's run axis and its wedges' hull points; a ray shorter than 1 µm (the only way
  //    PreparedRay::Make fails on finite input) has no direction and no vote. Eq 4.7's
  //    constants are prepared when the ray votes (once), not held for the whole chunk.
  const bool fast = evaluation_ == CarveEvaluation::kFast;
  const double leaf_size = grid_.resolution_m();
  thread_local CarveBuffers buffers;
  CarveBuffers& buf = buffers;
  auto& axis = buf.axis;
  axis.assign(num_rays, -1);
  // The wedge hulls' points, once per ray rather than once per wedge.
  auto& sensor_means = buf.sensor_means;
  auto& far_ends = buf.far_ends;
  sensor_means.resize(num_rays);
  far_ends.resize(num_rays);
  for (size_t r = 0; r < num_rays; ++r) {
    sensor_means[r] = in.rays[r].sensor_mean.cast<double>();
    far_ends[r] =
        in.far_ends.empty() ? ExtendedPointMean(in.rays[r], kWedgeHullSigmas) : in.far_ends[r];
    const std::optional<Eigen::Vector3d> direction = PreparedRay::Direction(in.rays[r]);
    if (direction && votes(r)) axis[r] = int8_t(RunAxis(*direction));
  }

  // 2. Each ray's wedges, and the last of them: the ray votes once that wedge is listed, and a
  //    wedge's runs are dropped once all its rays have voted, so the runs held follow the span
  //    of a ray's wedges in the payload (two frames of a line sensor), not the chunk's size
  //    (what grows with the chunk is ~100 bytes of bookkeeping per wedge and per ray).
  Csr& ray_wedges = buf.ray_wedges;
  ray_wedges.Build(num_rays, [&](auto&& emit) {
    for (size_t w = 0; w < num_wedges; ++w)
      for (int r = 0; r < in.wedges[w].num_rays; ++r) emit(in.wedges[w].ray[r], uint32_t(w));
  });
  auto& last_wedge = buf.last_wedge;
  last_wedge.assign(num_rays, 0);
  for (size_t r = 0; r < num_rays; ++r) {
    const auto row = ray_wedges.Row(r);
    if (!row.empty()) last_wedge[r] = row.back();
  }
  Csr& voters = buf.voters;  // rays by the wedge after which they vote
  voters.Build(num_wedges, [&](auto&& emit) {
    for (size_t r = 0; r < num_rays; ++r)
      if (!ray_wedges.Row(r).empty()) emit(last_wedge[r], uint32_t(r));
  });
  auto& free_after = buf.free_after;
  free_after.assign(num_wedges, 0);
  auto& axes_needed = buf.axes_needed;
  axes_needed.assign(num_wedges, 0);
  for (size_t w = 0; w < num_wedges; ++w) {
    for (int r = 0; r < in.wedges[w].num_rays; ++r) {
      const uint32_t id = in.wedges[w].ray[r];
      free_after[w] = std::max(free_after[w], last_wedge[id]);
      if (axis[id] >= 0) axes_needed[w] |= uint8_t(1 << axis[id]);
    }
  }
  Csr& freed = buf.freed;  // wedges by the wedge after which their runs are no longer needed
  freed.Build(num_wedges, [&](auto&& emit) {
    for (size_t w = 0; w < num_wedges; ++w) emit(free_after[w], uint32_t(w));
  });

  // 3. Wedge by wedge: list its leaves as runs along the axes its rays need; then every ray
  //    whose wedges are all listed votes once in each leaf of the union of their runs (eq 4.8
  //    with S(L) a set), in a fixed order, so the sums depend only on the input.
  const Eigen::Vector3d chunk_origin = chunk_.cast<double>() * kChunkSizeM;
  const ChunkRegion* region = region_.get();
  auto& runs = buf.runs;  // emptied as their wedges are done: assign only resizes
  runs.resize(num_wedges);
  auto& pool = buf.pool;  // emptied run lists, reused
  auto& merged = buf.merged;
  auto& merging = buf.merging;
  // One ray's leaves: their projections on the ray, their sums, and its votes.
  auto& par = buf.par;
  auto& lat_a = buf.lat_a;
  auto& lat_b = buf.lat_b;
  auto& vote_p = buf.vote_p;
  auto& vote_w = buf.vote_w;
  auto& cells = buf.cells;
  // Sums: the reference path's sparse bricks, or the fast path's dense array where it fits.
  const bool dense = fast && grid_.chunk_depth <= DenseScratch::kMaxDepth;
  std::optional<LeafScratch> sparse;
  if (!dense) sparse.emplace(grid_.chunk_depth);
  thread_local DenseScratch dense_scratch;
  if (dense) dense_scratch.Reset(grid_.chunk_depth);
  auto& row_w = buf.row_w;
  auto& row_p = buf.row_p;
  Wedge wedge;
  uint64_t updates = 0, touches = 0;
  for (size_t w = 0; w < num_wedges; ++w) {
    const WedgeRef& ref = in.wedges[w];
    if (axes_needed[w] != 0 && region != nullptr && ref.num_rays > 1 &&
        !MayTouchRegion(*region, chunk_origin, {sensor_means.data(), far_ends.data()}, ref)) {
      // §5.6.1's pass: the wedge's hull lies in no cell of the region, so it has no runs there.
      axes_needed[w] = 0;
    }
    if (axes_needed[w] != 0) {
      WedgeHull hull;
      if (ref.num_rays == 1) {
        wedge.num_rays = 1;
        wedge.rays[0] = in.rays[ref.ray[0]];
        hull = MakeWedgeHull(wedge, kWedgeHullSigmas);
      } else {
        std::array<Eigen::Vector3d, 4> s, e;
        for (int r = 0; r < ref.num_rays; ++r) {
          s[r] = sensor_means[ref.ray[r]];
          e[r] = far_ends[ref.ray[r]];
        }
        uint64_t facets = ref.facets;  // the binning's: no search for facets
        hull = HullOfWedgePoints({s.data(), ref.num_rays}, {e.data(), ref.num_rays}, &facets);
      }
      bool counted = false;
      for (int a = 0; a < 3; ++a) {
        if (!(axes_needed[w] & (1 << a))) continue;
        std::vector<LeafRun>& list = runs[w][a];
        if (!pool.empty()) {
          list.swap(pool.back());
          pool.pop_back();
        }
        const size_t n = RasterizeHull(hull, grid_, chunk_, a, region, list);
        if (!counted) touches += n;
        counted = true;
      }
    }
    for (uint32_t r : voters.Row(w)) {
      if (axis[r] < 0) continue;
      const int a = axis[r], u = (a + 1) % 3, v = (a + 2) % 3;
      // The union of the ray's wedges' runs, sorted: a merge of their sorted lists.
      merged.clear();
      for (uint32_t rw : ray_wedges.Row(r)) {
        const std::vector<LeafRun>& list = runs[rw][a];
        if (list.empty()) continue;
        if (merged.empty()) {
          merged.assign(list.begin(), list.end());
          continue;
        }
        MergeSortedRuns(merged, list, merging);
        merged.swap(merging);
      }
      if (merged.empty()) continue;  // no leaf of the chunk (or of the region)
      const absl::StatusOr<PreparedRay> prepared = PreparedRay::Make(in.rays[r]);
      if (!prepared.ok()) continue;  // cannot happen: axis[r] ≥ 0 means Make succeeds
      const PreparedRay& ray = *prepared;
      if (fast) {
        const std::optional<FloatRay> float_ray = FloatRay::Make(
            ray, chunk_origin + Eigen::Vector3d::Constant(leaf_size / 2), leaf_size, a);
        updates += VoteFast(ray, float_ray ? &*float_ray : nullptr, a, merged, chunk_origin,
                            leaf_size, dense ? &dense_scratch : nullptr,
                            sparse ? &*sparse : nullptr, row_w, row_p);
        continue;
      }
      Eigen::Vector3d step = Eigen::Vector3d::Zero();
      step[a] = leaf_size;
      const PreparedRay::Projection dp = ray.ProjectStep(step);
      // The leaves of the union: overlapping or adjacent runs of one row are one stretch.
      // Leaf centres as NodeBox(...).center() computes them, stepped from the row's first
      // leaf, so a leaf's value does not depend on how the runs around it were cut.
      par.clear();
      lat_a.clear();
      lat_b.clear();
      cells.clear();
      for (size_t i = 0; i < merged.size();) {
        const LeafRun first = merged[i];
        int hi = RunHi(first);
        size_t j = i + 1;
        for (; j < merged.size() && RunRow(merged[j]) == RunRow(first) &&
               RunLo(merged[j]) <= hi + 1;
             ++j) {
          hi = std::max(hi, RunHi(merged[j]));
        }
        Eigen::Vector3i local;
        local[a] = 0;
        local[u] = RunU(first);
        local[v] = RunV(first);
        const Eigen::Vector3d lo = chunk_origin + local.cast<double>() * leaf_size;
        const PreparedRay::Projection p0 =
            ray.Project((lo + (lo + Eigen::Vector3d::Constant(leaf_size))) / 2.0);
        for (int t = RunLo(first); t <= hi; ++t) {
          par.push_back(p0.par + t * dp.par);
          lat_a.push_back(p0.a + t * dp.a);
          lat_b.push_back(p0.b + t * dp.b);
          local[a] = t;
          cells.push_back(&sparse->At(local));
        }
        i = j;
      }
      vote_p.resize(par.size());
      vote_w.resize(par.size());
      ray.EvaluateMany(par.data(), lat_a.data(), lat_b.data(), par.size(), vote_p.data(),
                       vote_w.data());
      for (size_t i = 0; i < par.size(); ++i) {
        // w = f_⊥ ∈ [0, 1] is how much the ray speaks about x_L. Tiny weights still count:
        // a leaf in the middle of a wide wedge (sparse beams, far from the sensor) lies many
        // σ_⊥ from all four rays, yet §4.2.1/§4.3.1 mean the wedge's interpolated volume to
        // be carved, and every vote there is p = 0.5 + f_⊥/2 > 0.5, so the leaf is interior
        // whatever the magnitude. With the cut at 1e-6 (x_L beyond ~5.3 σ_⊥) such leaves
        // stayed unobserved, i.e. exterior pockets inside rooms; at 1e-15 (~8.3 σ_⊥) the
        // office accuracy test observes 46 % more leaves at the same 98.5 % accuracy. The
        // cut itself keeps sum_w clear of denormals.
        if (vote_w[i] < kMinRayWeight) continue;
        cells[i]->Add(vote_p[i], vote_w[i]);
        ++updates;
      }
    }
    for (uint32_t fw : freed.Row(w)) {
      for (std::vector<LeafRun>& list : runs[fw]) {
        if (list.capacity() == 0) continue;
        list.clear();
        pool.push_back(std::move(list));
        list = {};
      }
    }
  }
  num_leaf_touches_ += touches;
  num_leaf_updates_ += updates;
  Level& finest = levels_[grid_.chunk_depth];
  const auto keep = [&](const Eigen::Vector3i& local, const LeafStats& stats) {
    finest[MortonCode(local)].Merge(stats);
  };
  if (dense) {
    dense_scratch.Drain(keep);
  } else {
    sparse->ForEach(keep);
  }
  CountPoints(in);
  return absl::OkStatus();
}

void ChunkOctree::CountPoints(const IndexedWedges& in) {
  // §4.2.3's point voxel set, of the rays that vote here. A ray written twice into one payload
  // (WedgePayloadWriter repeats rays of old frames) is one point: count each bit-identical ray
  // once. Points in a leaf that no ray observed (the carve skipped every vote there) are not
  // kept: an unobserved leaf stores nothing; a part of the carve (SetPartial) keeps them until
  // DropUnobserved, as another part may observe the leaf.
  absl::flat_hash_set<RayBits> seen;
  Level& finest = levels_[grid_.chunk_depth];
  const Eigen::Vector3i base = chunk_ * grid_.leaves_per_side();
  const int n = grid_.leaves_per_side();
  for (size_t r = 0; r < in.rays.size(); ++r) {
    if (!in.votes.empty() && !in.votes[r]) continue;
    const RayModel& ray = in.rays[r];
    const Eigen::Vector3i local = LeafOf(grid_, ray.point_mean.cast<double>()) - base;
    if ((local.array() < 0).any() || (local.array() >= n).any()) continue;
    if (region_ && !region_->Intersects(ChunkNode{local, grid_.chunk_depth})) continue;
    auto it = partial_ ? finest.try_emplace(MortonCode(local)).first : finest.find(MortonCode(local));
    if (it == finest.end() || !seen.insert(RayBits(ray)).second) continue;
    ++it->second.points;
  }
}

absl::Status ChunkOctree::AddFinest(std::span<const TileLeaf> leaves, uint64_t wedges) {
  if (simplified_) return absl::FailedPreconditionError("chunk_octree: AddFinest after Simplify");
  const int k = grid_.chunk_depth, n = grid_.leaves_per_side();
  for (const TileLeaf& l : leaves) {
    if (l.node.depth != k || (l.node.local.array() < 0).any() || (l.node.local.array() >= n).any()) {
      return absl::InvalidArgumentError(
          absl::StrCat("chunk_octree: a leaf of depth ", l.node.depth, " at (", l.node.local.x(),
                       ",", l.node.local.y(), ",", l.node.local.z(), ") is not a finest leaf"));
    }
  }
  Level& finest = levels_[k];
  for (const TileLeaf& l : leaves) finest[MortonCode(l.node.local)].Merge(l.stats);
  num_wedges_ += wedges;
  return absl::OkStatus();
}

void ChunkOctree::DropUnobserved() {
  absl::erase_if(levels_[grid_.chunk_depth],
                 [](const auto& entry) { return entry.second.count == 0; });
}

std::vector<TileLeaf> ChunkOctree::FinestLeaves() const {
  std::vector<TileLeaf> leaves;
  const int k = grid_.chunk_depth;
  leaves.reserve(levels_[k].size());
  for (const auto& [code, stats] : levels_[k]) {
    TileLeaf leaf;
    leaf.node.local = MortonDecode(code);
    leaf.node.depth = k;
    leaf.stats = stats;
    leaves.push_back(leaf);
  }
  SortTileLeaves(grid_, leaves);
  return leaves;
}

void ChunkOctree::Simplify() {
  // Bottom-up (§4.3.2): a parent can only become a leaf once its children's levels are final,
  // so depth k is processed first and merged parents are considered again one level up.
  for (int d = grid_.chunk_depth; d >= 1; --d) {
    Level& level = levels_[d];
    if (level.size() < 8) continue;
    // Sorted, so siblings are adjacent (Morton: siblings share code >> 3) and merge sums run in
    // a fixed order: the result never depends on the hash map's iteration order.
    std::vector<std::pair<uint64_t, LeafStats>> sorted(level.begin(), level.end());
    std::sort(sorted.begin(), sorted.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    Level& parents = levels_[d - 1];
    for (size_t i = 0; i + 8 <= sorted.size();) {
      const uint64_t parent = sorted[i].first >> 3;
      if ((sorted[i + 7].first >> 3) != parent) {
        // Fewer than 8 observed siblings: the others are unobserved, so the children are
        // neither all observed nor all unobserved; no merge.
        ++i;
        while (i < sorted.size() && (sorted[i].first >> 3) == parent) ++i;
        continue;
      }
      const bool interior = sorted[i].second.interior();
      bool same_label = true, points = false;
      for (size_t j = i; j < i + 8; ++j) {
        same_label &= sorted[j].second.interior() == interior;
        points |= sorted[j].second.points > 0;
      }
      // Leaves holding scan points stay finest, so segmentation knows where the points are.
      if (same_label && !points) {
        // Sums: the parent's p is the weight-averaged p of its children, which keeps the label
        // (a weighted mean of values all > 0.5, or all ≤ 0.5, stays on the same side).
        LeafStats merged;
        for (size_t j = i; j < i + 8; ++j) {
          merged.Merge(sorted[j].second);
          level.erase(sorted[j].first);
        }
        parents.emplace(parent, merged);
      }
      i += 8;
    }
  }
  simplified_ = true;
}

std::vector<TileLeaf> ChunkOctree::Leaves() const {
  std::vector<TileLeaf> leaves;
  leaves.reserve(num_leaves());
  for (int d = 0; d <= grid_.chunk_depth; ++d) {
    for (const auto& [code, stats] : levels_[d]) {
      TileLeaf leaf;
      leaf.node.local = MortonDecode(code);
      leaf.node.depth = d;
      leaf.stats = stats;
      leaves.push_back(leaf);
    }
  }
  // Hash-map order is arbitrary; the canonical order (distinct keys) makes the output depend
  // only on the contents.
  SortTileLeaves(grid_, leaves);
  return leaves;
}

LeafStats ChunkOctree::StatsAt(const Eigen::Vector3d& x_world, int* depth) const {
  if (depth != nullptr) *depth = -1;
  const int k = grid_.chunk_depth;
  const Eigen::Vector3i local = LeafOf(grid_, x_world) - chunk_ * grid_.leaves_per_side();
  if ((local.array() < 0).any() || (local.array() >= grid_.leaves_per_side()).any()) {
    return LeafStats{};
  }
  for (int d = k; d >= 0; --d) {
    const Level& level = levels_[d];
    if (level.empty()) continue;
    const Eigen::Vector3i ancestor(local.x() >> (k - d), local.y() >> (k - d), local.z() >> (k - d));
    auto it = level.find(MortonCode(ancestor));
    if (it != level.end()) {
      if (depth != nullptr) *depth = d;
      return it->second;
    }
  }
  return LeafStats{};
}

TileData ChunkOctree::ToTile(const std::string& job_id) const {
  TileData tile;
  tile.chunk = chunk_;
  tile.grid = grid_;
  tile.params.job_id = job_id;
  tile.params.num_wedges = num_wedges_;
  tile.params.hull_sigmas = kWedgeHullSigmas;
  tile.params.min_weight = kMinRayWeight;
  tile.params.simplified = simplified_;
  tile.leaves = Leaves();
  return tile;
}

size_t ChunkOctree::num_leaves() const {
  size_t n = 0;
  for (const Level& level : levels_) n += level.size();
  return n;
}

size_t ChunkOctree::memory_bytes() const {
  size_t n = 0;
  for (const Level& level : levels_) n += level.capacity() * (sizeof(Level::value_type) + 1);
  return n;
}

}  // namespace carvemap
