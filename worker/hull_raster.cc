#include "worker/hull_raster.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <span>

#include "absl/container/inlined_vector.h"

namespace carvemap {
namespace {

// Below this margin (m) to a plane the analytic interval does not decide a run end: rounding
// in HullIntersectsBox's arithmetic (~1e−16 relative; world coordinates ≤ 1e6 m) might.
constexpr double kAmbiguousM = 1e-9;

// One hull plane in leaf indices: a·t + b·u + c·v ≤ g holds exactly for the leaves whose
// boxes the plane's half-space (widened by the box's support, as HullIntersectsBox does)
// reaches; s·(g − a·t − b·u − c·v) is the margin in metres.
struct IndexPlane {
  double a, b, c, g;
  double inv_a;  // 1/a (0 when a = 0)
};

// cu·u + cv·v ≤ c0: a bound on the rows that hold any leaf.
struct RowBound {
  double cu, cv, c0;
  double inv_cu;  // 1/cu (0 when cu = 0)
};

class Rasterizer {
 public:
  Rasterizer(const WedgeHull& hull, const OctreeGrid& grid, const ChunkKey& chunk, int axis,
             const ChunkRegion* region, std::vector<LeafRun>& out)
      : hull_(hull), a_(axis), u_((axis + 1) % 3), v_((axis + 2) % 3),
        s_(grid.resolution_m()), origin_(chunk.cast<double>() * kChunkSizeM),
        depth_(grid.chunk_depth), region_(region), out_(out) {
    n_ = grid.leaves_per_side();
    // A region no finer than the leaves is read row by row; a finer one leaf by leaf.
    if (region_ != nullptr && depth_ >= region_->depth()) region_shift_ = depth_ - region_->depth();
  }

  size_t Run() {
    const Eigen::AlignedBox3d& box = hull_.box;
    if (box.isEmpty() || !box.min().allFinite() || !box.max().allFinite()) return 0;
    if (!BoxRanges()) return 0;
    if (!IndexPlanes()) return 0;
    ProjectOnRows();
    const double slack = 1e-6;  // index units, against rounding of the row bounds
    for (int v = lo_[v_]; v <= hi_[v_]; ++v) {
      double ulo = lo_[u_], uhi = hi_[u_];
      const RowBound* h = row_bounds_.data();
      const size_t n = row_bounds_.size(), lower = upper_bounds_, flat = lower + lower_bounds_;
      for (size_t i = 0; i < lower; ++i) {
        uhi = std::min(uhi, (h[i].c0 - h[i].cv * v) * h[i].inv_cu);
      }
      for (size_t i = lower; i < flat; ++i) {
        ulo = std::max(ulo, (h[i].c0 - h[i].cv * v) * h[i].inv_cu);
      }
      bool empty = false;
      for (size_t i = flat; i < n; ++i) empty |= h[i].c0 - h[i].cv * v < -slack;
      if (empty || !(ulo <= uhi + 2)) continue;
      // One row of margin either way: Row settles each one exactly.
      const int u0 = std::max(lo_[u_], int(std::ceil(std::max(ulo, lo_[u_] - 1.0))) - 1);
      const int u1 = std::min(hi_[u_], int(std::floor(std::min(uhi, hi_[u_] + 1.0))) + 1);
      for (int u = u0; u <= u1; ++u) Row(u, v);
    }
    return count_;
  }

 private:
  // Per axis, the leaves whose boxes overlap the hull's box, with NodeBox's arithmetic (and,
  // in a region read row by row, its cells' bounding box).
  bool BoxRanges() {
    for (int d = 0; d < 3; ++d) {
      const double mn = hull_.box.min()[d], mx = hull_.box.max()[d];
      const double lo = std::floor((mn - origin_[d]) / s_) - 1;
      const double hi = std::floor((mx - origin_[d]) / s_) + 1;
      if (hi < 0 || lo > n_ - 1) return false;
      int i0 = int(std::max(lo, 0.0)), i1 = int(std::min(hi, double(n_ - 1)));
      while (i0 <= i1 && origin_[d] + i0 * s_ + s_ < mn) ++i0;  // hi < min: apart
      while (i1 >= i0 && origin_[d] + i1 * s_ > mx) --i1;       // lo > max: apart
      if (region_shift_ >= 0) {
        // No leaf outside the region's cells is listed: rows beyond them need no visit.
        i0 = std::max(i0, region_->cells_lo()[d] << region_shift_);
        i1 = std::min(i1, ((region_->cells_hi()[d] + 1) << region_shift_) - 1);
      }
      if (i0 > i1) return false;
      lo_[d] = i0;
      hi_[d] = i1;
    }
    return true;
  }

  // The planes in leaf indices; planes every leaf of the box ranges satisfies are dropped.
  bool IndexPlanes() {
    planes_.clear();
    for (const Eigen::Vector4d& q : hull_.planes) {
      const Eigen::Vector3d nrm = q.head<3>();
      // n·c − Σ|n_d|·s/2 ≤ q3 with c_d = origin_d + (i_d + ½)s.
      IndexPlane p;
      p.a = nrm[a_];
      p.b = nrm[u_];
      p.c = nrm[v_];
      p.g = (q[3] - nrm.dot(origin_)) / s_ + 0.5 * (nrm.cwiseAbs().sum() - nrm.sum());
      p.inv_a = p.a != 0 ? 1 / p.a : 0;
      double most = 0, least = 0;
      for (auto [coef, d] : {std::pair{p.a, a_}, std::pair{p.b, u_}, std::pair{p.c, v_}}) {
        most += std::max(coef * lo_[d], coef * hi_[d]);
        least += std::min(coef * lo_[d], coef * hi_[d]);
      }
      if ((p.g - most) * s_ > kAmbiguousM) continue;    // holds for every leaf
      if ((p.g - least) * s_ < -kAmbiguousM) return false;  // holds for none
      planes_.push_back(p);
    }
    // Upper bounds on t first, then lower ones, then the planes along the rows: the loops over
    // them (Row, ProjectOnRows) need no branch per plane, whose sign no predictor guesses.
    auto lower =
        std::partition(planes_.begin(), planes_.end(), [](const IndexPlane& p) { return p.a > 0; });
    auto flat = std::partition(lower, planes_.end(), [](const IndexPlane& p) { return p.a < 0; });
    upper_planes_ = size_t(lower - planes_.begin());
    lower_planes_ = size_t(flat - lower);
    double a_min = std::numeric_limits<double>::infinity();
    for (const IndexPlane& p : planes_) {
      if (p.a != 0) a_min = std::min(a_min, std::abs(p.a));
    }
    tol_ = kAmbiguousM / (a_min * s_);  // 0 without such planes
    return true;
  }

  // Fourier–Motzkin elimination of t: a row holds leaves only where every lower bound on t is
  // below every upper bound and both meet the box range.
  void AddRowBound(double cu, double cv, double c0) {
    row_bounds_.push_back({cu, cv, c0, cu != 0 ? 1 / cu : 0});
  }

  void ProjectOnRows() {
    row_bounds_.clear();
    const double t0 = lo_[a_], t1 = hi_[a_];
    const std::span<const IndexPlane> upper(planes_.data(), upper_planes_);
    const std::span<const IndexPlane> lower(planes_.data() + upper_planes_, lower_planes_);
    const std::span<const IndexPlane> flat(lower.data() + lower.size(),
                                           planes_.size() - upper.size() - lower.size());
    // t ≤ or ≥ h(u, v) = (g − b·u − c·v)/a.
    for (const IndexPlane& q : upper) {
      AddRowBound(q.b * q.inv_a, q.c * q.inv_a, q.g * q.inv_a - t0);  // h ≥ t0
    }
    for (const IndexPlane& p : lower) {
      const double hb = p.b * p.inv_a, hc = p.c * p.inv_a, h0 = p.g * p.inv_a;
      AddRowBound(-hb, -hc, t1 - h0);  // h ≤ t1
      for (const IndexPlane& q : upper) {
        // lower h_p ≤ upper h_q
        const double qb = q.b * q.inv_a, qc = q.c * q.inv_a, q0 = q.g * q.inv_a;
        AddRowBound(qb - hb, qc - hc, q0 - h0);
      }
    }
    for (const IndexPlane& p : flat) AddRowBound(p.b, p.c, p.g);
    // As the planes: bounds on u from above, from below, then those on v alone.
    auto below = std::partition(row_bounds_.begin(), row_bounds_.end(),
                                [](const RowBound& h) { return h.cu > 0; });
    auto rest =
        std::partition(below, row_bounds_.end(), [](const RowBound& h) { return h.cu < 0; });
    upper_bounds_ = size_t(below - row_bounds_.begin());
    lower_bounds_ = size_t(rest - below);
  }

  [[nodiscard]] double MinMargin(int t, int u, int v) const {
    double m = std::numeric_limits<double>::infinity();
    for (const IndexPlane& p : planes_) m = std::min(m, p.g - p.a * t - p.b * u - p.c * v);
    return m * s_;
  }

  // HullIntersectsBox on the box NodeBox gives the leaf (the box ranges already hold).
  [[nodiscard]] bool LeafTouched(int t, int u, int v) const {
    Eigen::Vector3i local;
    local[a_] = t;
    local[u_] = u;
    local[v_] = v;
    const Eigen::Vector3d lo = origin_ + local.cast<double>() * s_;
    const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(s_);
    Eigen::AlignedBox3d box(lo, hi);
    return HullIntersectsBox(hull_, box);
  }

  // Whether leaf t of the row is touched: by its margins when they decide, exactly otherwise.
  [[nodiscard]] bool Touched(int t, int u, int v) const {
    const double m = MinMargin(t, u, v);
    if (m > kAmbiguousM) return true;
    if (m < -kAmbiguousM) return false;
    return LeafTouched(t, u, v);
  }

  void Row(int u, int v) {
    // §5.6.1's restricted pass: a row outside the region costs one lookup.
    std::span<const ChunkRegion::CellRun> region_runs;
    if (region_shift_ >= 0) {
      region_runs = region_->RowRuns(a_, u >> region_shift_, v >> region_shift_);
      if (region_runs.empty()) return;
    }
    double lo = -std::numeric_limits<double>::infinity(), hi = -lo, flat = hi;
    const IndexPlane* p = planes_.data();
    const size_t n = planes_.size(), lower = upper_planes_, along = lower + lower_planes_;
    for (size_t i = 0; i < lower; ++i) {
      hi = std::min(hi, (p[i].g - p[i].b * u - p[i].c * v) * p[i].inv_a);
    }
    for (size_t i = lower; i < along; ++i) {
      lo = std::max(lo, (p[i].g - p[i].b * u - p[i].c * v) * p[i].inv_a);
    }
    for (size_t i = along; i < n; ++i) flat = std::min(flat, p[i].g - p[i].b * u - p[i].c * v);
    if (flat * s_ < -kAmbiguousM || !(lo <= hi + 1)) return;  // also NaN
    // The analytic interval, inside the box range (exact already).
    int t0 = std::max(lo_[a_], int(std::ceil(std::max(lo, lo_[a_] - 1.0))));
    int t1 = std::min(hi_[a_], int(std::floor(std::min(hi, hi_[a_] + 1.0))));
    // A plane's margin at leaf t is at least min|a|·s·(distance from t to its bound), so the
    // analytic answer can only be wrong at a leaf nearer than `tol` to a bound: check those.
    const double tol = tol_;
    const bool flat_near = flat * s_ < kAmbiguousM;
    const bool near0 = flat_near || t0 - lo < tol || (t0 > lo_[a_] && lo - (t0 - 1) < tol) ||
                       hi - t0 < tol;
    const bool near1 = flat_near || hi - t1 < tol || (t1 < hi_[a_] && (t1 + 1) - hi < tol) ||
                       t1 - lo < tol;
    if (near0) {
      t0 = std::max(lo_[a_], t0 - 1);
      while (t0 <= std::min(t1 + 1, hi_[a_]) && !Touched(t0, u, v)) ++t0;
    }
    if (near1) {
      t1 = std::min(hi_[a_], t1 + 1);
      while (t1 >= t0 && !Touched(t1, u, v)) --t1;
    }
    if (t0 <= t1) Emit(u, v, t0, t1, region_runs);
  }

  void Emit(int u, int v, int lo, int hi, std::span<const ChunkRegion::CellRun> region_runs) {
    if (region_ == nullptr) {
      out_.push_back(MakeLeafRun(u, v, lo, hi));
      count_ += size_t(hi - lo + 1);
      return;
    }
    if (region_shift_ >= 0) {  // the run clipped to each of the row's region runs
      for (const ChunkRegion::CellRun& r : region_runs) {
        const int first = std::max(lo, int(r.first) << region_shift_);
        const int last = std::min(hi, ((int(r.last) + 1) << region_shift_) - 1);
        if (first > last) continue;
        out_.push_back(MakeLeafRun(u, v, first, last));
        count_ += size_t(last - first + 1);
      }
      return;
    }
    // A region finer than the leaves: split the run at the region's boundary leaf by leaf.
    ChunkNode leaf;
    leaf.depth = depth_;
    leaf.local[u_] = u;
    leaf.local[v_] = v;
    int start = -1;
    for (int t = lo; t <= hi + 1; ++t) {
      bool in = false;
      if (t <= hi) {
        leaf.local[a_] = t;
        in = region_->Intersects(leaf);
      }
      if (in && start < 0) start = t;
      if (!in && start >= 0) {
        out_.push_back(MakeLeafRun(u, v, start, t - 1));
        count_ += size_t(t - start);
        start = -1;
      }
    }
  }

  const WedgeHull& hull_;
  const int a_, u_, v_;
  const double s_;
  const Eigen::Vector3d origin_;
  const int depth_;
  const ChunkRegion* region_;
  int region_shift_ = -1;  // leaf depth − region depth when ≥ 0
  std::vector<LeafRun>& out_;
  int n_ = 0;
  std::array<int, 3> lo_{}, hi_{};
  // Inline: one rasterizer per wedge and chunk, so no allocation in the common case.
  absl::InlinedVector<IndexPlane, 16> planes_;  // a > 0, then a < 0, then a = 0
  size_t upper_planes_ = 0, lower_planes_ = 0;
  double tol_ = 0;  // index units: closer than this to a plane's bound, the test decides
  absl::InlinedVector<RowBound, 48> row_bounds_;  // cu > 0, then cu < 0, then cu = 0
  size_t upper_bounds_ = 0, lower_bounds_ = 0;
  size_t count_ = 0;
};

}  // namespace

size_t RasterizeHull(const WedgeHull& hull, const OctreeGrid& grid, const ChunkKey& chunk,
                     int axis, const ChunkRegion* region, std::vector<LeafRun>& out) {
  assert(axis >= 0 && axis < 3);
  return Rasterizer(hull, grid, chunk, axis, region, out).Run();
}

}  // namespace carvemap
