#include "services/floorplan/samples/grid_visibility.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// Samples bucketed on a square grid of side = match distance (CSR layout), so the nearest sample
// to a hit point is among the 3×3 buckets around it. Hand-written rather than a CGAL kd-tree:
// the query radius is fixed and tiny, and a flat bucket grid answers it in a few memory reads,
// which matters at ~10^6 ray hits per map.
class SampleBuckets {
 public:
  SampleBuckets(const std::vector<WallSample>& samples, double bucket_m) : bucket_m_(bucket_m) {
    if (samples.empty()) return;
    Eigen::Vector2d lo = samples[0].position, hi = lo;
    for (const WallSample& s : samples) {
      lo = lo.cwiseMin(s.position);
      hi = hi.cwiseMax(s.position);
    }
    lo_ = lo;
    nx_ = static_cast<int>(std::floor((hi.x() - lo.x()) / bucket_m_)) + 1;
    ny_ = static_cast<int>(std::floor((hi.y() - lo.y()) / bucket_m_)) + 1;
    start_.assign(static_cast<size_t>(nx_) * ny_ + 1, 0);
    std::vector<size_t> key(samples.size());
    for (size_t i = 0; i < samples.size(); ++i) {
      key[i] = Key(samples[i].position);
      ++start_[key[i] + 1];
    }
    for (size_t b = 1; b < start_.size(); ++b) start_[b] += start_[b - 1];
    index_.resize(samples.size());
    std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
    // Ascending sample order within a bucket, so ties resolve to the lower index.
    for (size_t i = 0; i < samples.size(); ++i) index_[fill[key[i]]++] = static_cast<uint32_t>(i);
  }

  // Nearest sample to p within max_d (ties: lowest index); -1 if none.
  int64_t Nearest(const std::vector<WallSample>& samples, const Eigen::Vector2d& p,
                  double max_d) const {
    if (nx_ == 0) return -1;
    const int bx = static_cast<int>(std::floor((p.x() - lo_.x()) / bucket_m_));
    const int by = static_cast<int>(std::floor((p.y() - lo_.y()) / bucket_m_));
    double best_d2 = max_d * max_d;
    int64_t best = -1;
    for (int y = std::max(by - 1, 0); y <= std::min(by + 1, ny_ - 1); ++y) {
      for (int x = std::max(bx - 1, 0); x <= std::min(bx + 1, nx_ - 1); ++x) {
        const size_t b = static_cast<size_t>(y) * nx_ + x;
        for (uint32_t k = start_[b]; k < start_[b + 1]; ++k) {
          const uint32_t i = index_[k];
          const double d2 = (samples[i].position - p).squaredNorm();
          if (d2 < best_d2 || (d2 == best_d2 && best >= 0 && i < best)) {
            best_d2 = d2;
            best = i;
          }
        }
      }
    }
    return best;
  }

 private:
  size_t Key(const Eigen::Vector2d& p) const {
    const int x =
        std::clamp(static_cast<int>(std::floor((p.x() - lo_.x()) / bucket_m_)), 0, nx_ - 1);
    const int y =
        std::clamp(static_cast<int>(std::floor((p.y() - lo_.y()) / bucket_m_)), 0, ny_ - 1);
    return static_cast<size_t>(y) * nx_ + x;
  }

  double bucket_m_;
  Eigen::Vector2d lo_ = Eigen::Vector2d::Zero();
  int nx_ = 0, ny_ = 0;
  std::vector<uint32_t> start_;
  std::vector<uint32_t> index_;
};

// Amanatides & Woo (1987) grid traversal in cell units from (gx, gy) along unit (dx, dy): the
// ray parameter t (cells) at which it enters the first blocked cell, or -1 if it leaves the grid
// or passes max_t first. The start cell counts: a pose inside a blocked cell hits at t = 0.
double FirstBlocked(const OccupancyGrid2D& grid, double gx, double gy, double dx, double dy,
                    double max_t) {
  int ix = static_cast<int>(std::floor(gx));
  int iy = static_cast<int>(std::floor(gy));
  if (grid.Blocked(ix, iy)) return 0;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const int step_x = dx > 0 ? 1 : -1;
  const int step_y = dy > 0 ? 1 : -1;
  const double delta_x = dx != 0 ? std::abs(1.0 / dx) : kInf;
  const double delta_y = dy != 0 ? std::abs(1.0 / dy) : kInf;
  double t_max_x = dx != 0 ? ((dx > 0 ? ix + 1 - gx : gx - ix) * delta_x) : kInf;
  double t_max_y = dy != 0 ? ((dy > 0 ? iy + 1 - gy : gy - iy) * delta_y) : kInf;
  // Linear cell index and the steps left before leaving the grid on each axis, so the inner
  // loop is one compare, one add and one load per cell.
  const uint8_t* cells = grid.cells.data();
  const ptrdiff_t w = grid.width;
  ptrdiff_t idx = iy * w + ix;
  const ptrdiff_t di_x = step_x, di_y = step_y * w;
  int left_x = step_x > 0 ? grid.width - 1 - ix : ix;
  int left_y = step_y > 0 ? grid.height - 1 - iy : iy;
  while (true) {
    double t;
    if (t_max_x < t_max_y) {
      if (--left_x < 0) return -1;
      t = t_max_x;
      t_max_x += delta_x;
      idx += di_x;
    } else {
      if (--left_y < 0) return -1;
      t = t_max_y;
      t_max_y += delta_y;
      idx += di_y;
    }
    if (t > max_t) return -1;
    if (cells[idx] != 0) return t;
  }
}

}  // namespace

absl::Status OccupancyGrid2D::Validate() const {
  if (!std::isfinite(resolution_m) || resolution_m <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: resolution_m must be finite and > 0, got ", resolution_m));
  }
  if (!std::isfinite(origin_x_m) || !std::isfinite(origin_y_m)) {
    return absl::InvalidArgumentError("occupancy grid: origin is not finite");
  }
  if (width < 0 || height < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("occupancy grid: negative size ", width, "×", height));
  }
  if (cells.size() != static_cast<size_t>(width) * static_cast<size_t>(height)) {
    return absl::InvalidArgumentError(absl::StrCat("occupancy grid: ", cells.size(),
                                                   " cells for a ", width, "×", height, " grid"));
  }
  return absl::OkStatus();
}

absl::Status VisibilityOptions::Validate() const {
  if (!std::isfinite(max_range_m) || max_range_m <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("visibility: max_range_m must be finite and > 0, got ", max_range_m));
  }
  if (!std::isfinite(angle_step_deg) || angle_step_deg <= 0 || angle_step_deg > 360) {
    return absl::InvalidArgumentError(
        absl::StrCat("visibility: angle_step_deg must be in (0, 360], got ", angle_step_deg));
  }
  if (!std::isfinite(min_pose_spacing_m) || min_pose_spacing_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "visibility: min_pose_spacing_m must be finite and ≥ 0, got ", min_pose_spacing_m));
  }
  if (!std::isfinite(match_distance_m) || match_distance_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "visibility: match_distance_m must be finite and ≥ 0, got ", match_distance_m));
  }
  return absl::OkStatus();
}

absl::Status AssignVisiblePoses(const OccupancyGrid2D& grid, const VisibilityOptions& options,
                                WallSampleSet& set) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = grid.Validate(); !s.ok()) return s;
  for (WallSample& s : set.samples) s.poses.clear();
  // Validate after clearing: stale pose lists are replaced anyway, so they are no error.
  if (absl::Status s = set.Validate(); !s.ok()) return s;
  if (set.samples.empty() || set.poses.empty() || grid.width == 0 || grid.height == 0) {
    return absl::OkStatus();
  }

  const double res = grid.resolution_m;
  const double match_m = options.match_distance_m > 0 ? options.match_distance_m : 1.5 * res;
  const SampleBuckets buckets(set.samples, match_m);
  const double max_t = options.max_range_m / res;

  const int rays = std::max(1, static_cast<int>(std::lround(360.0 / options.angle_step_deg)));
  std::vector<double> cos_a(rays), sin_a(rays);
  for (int k = 0; k < rays; ++k) {
    const double a = (k * options.angle_step_deg) * M_PI / 180.0;
    cos_a[k] = std::cos(a);
    sin_a[k] = std::sin(a);
  }

  // Last pose that saw each sample, so each pose is added once; poses run in ascending order,
  // so every pose list comes out ascending.
  std::vector<int64_t> last_seen(set.samples.size(), -1);
  size_t next_break = 0;
  double walked_m = 0;  // path length since the last kept pose
  bool have_kept = false;
  for (size_t p = 0; p < set.poses.size(); ++p) {
    const Eigen::Vector2d& pose = set.poses[p];
    // A path break starts a new piece: path length does not carry across it, so its first
    // pose is always kept.
    const bool starts_piece =
        next_break < set.path_breaks.size() && set.path_breaks[next_break] == p;
    if (starts_piece) ++next_break;
    if (p > 0 && !starts_piece) walked_m += (pose - set.poses[p - 1]).norm();
    if (have_kept && !starts_piece && walked_m < options.min_pose_spacing_m) continue;
    have_kept = true;
    walked_m = 0;

    const double gx = (pose.x() - grid.origin_x_m) / res;
    const double gy = (pose.y() - grid.origin_y_m) / res;
    if (!(gx >= 0 && gy >= 0 && gx < grid.width && gy < grid.height)) continue;
    for (int k = 0; k < rays; ++k) {
      const double t = FirstBlocked(grid, gx, gy, cos_a[k], sin_a[k], max_t);
      if (t < 0) continue;
      const Eigen::Vector2d hit(pose.x() + t * res * cos_a[k], pose.y() + t * res * sin_a[k]);
      const int64_t i = buckets.Nearest(set.samples, hit, match_m);
      if (i < 0 || last_seen[i] == static_cast<int64_t>(p)) continue;
      last_seen[i] = static_cast<int64_t>(p);
      set.samples[i].poses.push_back(static_cast<uint32_t>(p));
    }
  }
  return absl::OkStatus();
}

}  // namespace carvemap
