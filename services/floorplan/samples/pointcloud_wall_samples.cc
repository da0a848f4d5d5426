#include "services/floorplan/samples/pointcloud_wall_samples.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

#include <Eigen/Eigenvalues>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// Coordinates beyond this are refused: cell indices must fit the 32-bit halves of a key.
constexpr double kMaxCoordinate_m = 1e6;

bool Finite(const Vector3d& v) { return v.allFinite(); }

// Cell (ix, iy) covers [ix·d_s, (ix+1)·d_s) × [iy·d_s, (iy+1)·d_s); its centre is at +d_s/2.
uint64_t CellKey(int64_t ix, int64_t iy) {
  constexpr int64_t kOffset = int64_t{1} << 31;
  return (static_cast<uint64_t>(iy + kOffset) << 32) | static_cast<uint64_t>(ix + kOffset);
}
int64_t KeyX(uint64_t key) { return static_cast<int64_t>(key & 0xFFFFFFFFu) - (int64_t{1} << 31); }
int64_t KeyY(uint64_t key) { return static_cast<int64_t>(key >> 32) - (int64_t{1} << 31); }

// Calls fn(key, dx, dy) for every cell whose centre is within d_s (horizontally) of (x, y),
// with (dx, dy) the point relative to that centre.
template <typename Fn>
void ForNeighbourCells(double x, double y, double ds, Fn&& fn) {
  const double fx = x / ds, fy = y / ds;
  const int64_t x0 = static_cast<int64_t>(std::ceil(fx - 1.5));
  const int64_t x1 = static_cast<int64_t>(std::floor(fx + 0.5));
  const int64_t y0 = static_cast<int64_t>(std::ceil(fy - 1.5));
  const int64_t y1 = static_cast<int64_t>(std::floor(fy + 0.5));
  const double r2 = ds * ds;
  for (int64_t iy = y0; iy <= y1; ++iy) {
    const double dy = y - (static_cast<double>(iy) + 0.5) * ds;
    for (int64_t ix = x0; ix <= x1; ++ix) {
      const double dx = x - (static_cast<double>(ix) + 0.5) * ds;
      if (dx * dx + dy * dy <= r2) fn(CellKey(ix, iy), dx, dy);
    }
  }
}

// Pass 2's per-cell state: enough for the density, height, histogram and PCA tests.
struct CellStats {
  uint32_t count = 0;
  uint16_t bins = 0;  // bit b: height bin b is non-empty
  float zmin = std::numeric_limits<float>::infinity();
  float zmax = -std::numeric_limits<float>::infinity();
  double sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0;  // relative to the cell centre
  float tx = 0, ty = 0;  // Σ unit vectors from the point to its sensor (normal orientation)
};

// Pass 3's per-candidate state.
struct Candidate {
  uint64_t key = 0;
  Vector2d normal = Vector2d::Zero();
  float zmin = 0, zmax = 0;
  uint32_t count = 0;
  std::vector<uint32_t> xhist, yhist;
  std::vector<uint32_t> poses;
};

// The kept poses of one level: positions (xy), their times, the path breaks.
struct LevelPoses {
  std::vector<Vector2d> xy;
  std::vector<double> t;
  std::vector<uint32_t> breaks;
};

LevelPoses KeepPoses(std::span<const TimedPose> path, const Level& level, double spacing) {
  LevelPoses out;
  bool off_level = false;
  Vector2d last = Vector2d::Zero();
  for (const TimedPose& p : path) {
    const Vector3d& x = p.pose.translation;
    if (!(x.z() >= level.split_z_low && x.z() < level.split_z_high)) {
      off_level = true;
      continue;
    }
    const Vector2d xy = x.head<2>();
    if (out.xy.empty() || off_level) {
      if (!out.xy.empty()) out.breaks.push_back(static_cast<uint32_t>(out.xy.size()));
      out.xy.push_back(xy);
      out.t.push_back(p.t);
      last = xy;
      off_level = false;
    } else if ((xy - last).norm() >= spacing) {
      out.xy.push_back(xy);
      out.t.push_back(p.t);
      last = xy;
    }
  }
  return out;
}

// Median of a histogram over [lo, lo + bins·width) holding n values, linear within a bin.
double HistogramMedian(const std::vector<uint32_t>& hist, uint32_t n, double lo, double width) {
  const double half = 0.5 * static_cast<double>(n);
  double cum = 0;
  for (size_t b = 0; b < hist.size(); ++b) {
    if (hist[b] == 0) continue;
    if (cum + hist[b] >= half) {
      return lo + width * (static_cast<double>(b) + (half - cum) / hist[b]);
    }
    cum += hist[b];
  }
  return lo + width * static_cast<double>(hist.size());
}

absl::Status CheckPoint(const CloudPoint& p) {
  if (!Finite(p.point) || !Finite(p.sensor) || !std::isfinite(p.t)) {
    return absl::InvalidArgumentError("point cloud wall samples: a point is not finite");
  }
  if (p.point.head<2>().cwiseAbs().maxCoeff() > kMaxCoordinate_m) {
    return absl::InvalidArgumentError(absl::StrCat(
        "point cloud wall samples: a point lies more than ", kMaxCoordinate_m,
        " m from the origin (", p.point.x(), ", ", p.point.y(), ")"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status PointCloudWallSampleOptions::Validate() const {
  auto bad = [](const char* name, double v) {
    return absl::InvalidArgumentError(
        absl::StrCat("point cloud wall samples: bad ", name, " = ", v));
  };
  if (!std::isfinite(spacing_m) || spacing_m <= 0) return bad("spacing_m", spacing_m);
  if (min_points < 1) return bad("min_points", min_points);
  if (!std::isfinite(min_wall_height_m) || min_wall_height_m < 0) {
    return bad("min_wall_height_m", min_wall_height_m);
  }
  if (height_bins < 1 || height_bins > 16) return bad("height_bins (1..16)", height_bins);
  if (min_filled_bins < 0 || min_filled_bins > height_bins) {
    return bad("min_filled_bins", min_filled_bins);
  }
  if (top_bins < 0 || top_bins > height_bins) return bad("top_bins", top_bins);
  if (min_filled_top_bins < 0 || min_filled_top_bins > top_bins) {
    return bad("min_filled_top_bins", min_filled_top_bins);
  }
  if (!std::isfinite(min_normal_confidence) || min_normal_confidence < 0 ||
      min_normal_confidence > 1) {
    return bad("min_normal_confidence", min_normal_confidence);
  }
  if (median_bins < 2 || median_bins > 4096) return bad("median_bins (2..4096)", median_bins);
  if (!std::isfinite(min_pose_spacing_m) || min_pose_spacing_m < 0) {
    return bad("min_pose_spacing_m", min_pose_spacing_m);
  }
  return absl::OkStatus();
}

absl::StatusOr<HeightHistogram> PointCloudHeightHistogram(const CloudStreamFn& stream,
                                                          double bin_m, double min_elevation_deg) {
  if (!std::isfinite(bin_m) || bin_m <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("point cloud height histogram: bad bin_m = ", bin_m));
  }
  if (!(min_elevation_deg >= 0 && min_elevation_deg < 90)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "point cloud height histogram: bad min_elevation_deg = ", min_elevation_deg));
  }
  const double min_sin = std::sin(min_elevation_deg * M_PI / 180);
  // Bins keyed by index, so the range need not be known in advance.
  std::map<int64_t, std::pair<double, double>> bins;  // floor, ceiling counts
  absl::Status s = stream([&](std::span<const CloudPoint> batch) -> absl::Status {
    for (const CloudPoint& p : batch) {
      if (absl::Status c = CheckPoint(p); !c.ok()) return c;
      if (std::abs(p.point.z()) > kMaxCoordinate_m) {
        return absl::InvalidArgumentError("point cloud height histogram: a point is too high");
      }
      const double dz = p.sensor.z() - p.point.z();
      if (dz == 0 || std::abs(dz) < min_sin * (p.sensor - p.point).norm()) continue;
      auto& b = bins[static_cast<int64_t>(std::floor(p.point.z() / bin_m))];
      (dz > 0 ? b.first : b.second) += 1;
    }
    return absl::OkStatus();
  });
  if (!s.ok()) return s;
  HeightHistogram h;
  h.bin_m = bin_m;
  if (bins.empty()) return h;
  const int64_t lo = bins.begin()->first, hi = bins.rbegin()->first;
  if (hi - lo >= 1000000) {
    return absl::InvalidArgumentError(absl::StrCat(
        "point cloud height histogram: heights span ", (hi - lo) * bin_m, " m, too many bins"));
  }
  h.z0_m = static_cast<double>(lo) * bin_m;
  h.floor.assign(static_cast<size_t>(hi - lo + 1), 0.0);
  h.ceiling.assign(h.floor.size(), 0.0);
  for (const auto& [b, counts] : bins) {
    h.floor[static_cast<size_t>(b - lo)] = counts.first;
    h.ceiling[static_cast<size_t>(b - lo)] = counts.second;
  }
  return h;
}

absl::StatusOr<std::vector<WallSampleSet>> PointCloudWallSamples(
    const CloudStreamFn& stream, std::span<const Level> levels, std::span<const TimedPose> path,
    const PointCloudWallSampleOptions& options,
    std::vector<PointCloudWallSampleReport>* reports) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  for (size_t k = 0; k < levels.size(); ++k) {
    const Level& l = levels[k];
    if (!std::isfinite(l.floor_z) || !std::isfinite(l.ceiling_z) || l.floor_z >= l.ceiling_z ||
        !(l.split_z_low < l.split_z_high) || std::isnan(l.split_z_low) ||
        std::isnan(l.split_z_high)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "point cloud wall samples: level ", k, " needs finite floor_z < ceiling_z and "
          "split_z_low < split_z_high"));
    }
  }
  for (size_t i = 0; i < path.size(); ++i) {
    if (!path[i].pose.translation.allFinite() || !std::isfinite(path[i].t) ||
        (i > 0 && path[i].t < path[i - 1].t)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "point cloud wall samples: path pose ", i, " is not finite or not in time order"));
    }
  }
  const size_t nl = levels.size();
  const double ds = options.spacing_m;
  std::vector<PointCloudWallSampleReport> rep(nl);
  std::vector<LevelPoses> poses(nl);
  for (size_t k = 0; k < nl; ++k) {
    poses[k] = KeepPoses(path, levels[k], options.min_pose_spacing_m);
    rep[k].poses = poses[k].xy.size();
  }
  auto level_of = [&](double z) { return LevelContaining(levels, z); };

  // Pass 2: per-cell statistics.
  std::vector<absl::flat_hash_map<uint64_t, CellStats>> cells(nl);
  const int nbins = options.height_bins;
  absl::Status s = stream([&](std::span<const CloudPoint> batch) -> absl::Status {
    for (const CloudPoint& p : batch) {
      if (absl::Status c = CheckPoint(p); !c.ok()) return c;
      const int k = level_of(p.point.z());
      if (k < 0) continue;
      ++rep[k].points;
      const Level& l = levels[k];
      const int bin = std::clamp(
          static_cast<int>(std::floor((p.point.z() - l.floor_z) / (l.ceiling_z - l.floor_z) * nbins)),
          0, nbins - 1);
      Vector2d toward = (p.sensor - p.point).head<2>();
      const double tn = toward.norm();
      toward = tn > 0 ? Vector2d(toward / tn) : Vector2d::Zero();
      const float z = static_cast<float>(p.point.z());
      ForNeighbourCells(p.point.x(), p.point.y(), ds, [&](uint64_t key, double dx, double dy) {
        CellStats& c = cells[k][key];
        ++c.count;
        c.bins |= static_cast<uint16_t>(1u << bin);
        c.zmin = std::min(c.zmin, z);
        c.zmax = std::max(c.zmax, z);
        c.sx += dx;
        c.sy += dy;
        c.sxx += dx * dx;
        c.sxy += dx * dy;
        c.syy += dy * dy;
        c.tx += static_cast<float>(toward.x());
        c.ty += static_cast<float>(toward.y());
      });
    }
    return absl::OkStatus();
  });
  if (!s.ok()) return s;

  // The tests of §3.1.1 on each cell; the survivors are pass 3's candidates.
  std::vector<absl::flat_hash_map<uint64_t, Candidate>> candidates(nl);
  const uint16_t top_mask = static_cast<uint16_t>(
      ((1u << options.top_bins) - 1u) << (nbins - options.top_bins));
  for (size_t k = 0; k < nl; ++k) {
    rep[k].cells = cells[k].size();
    for (const auto& [key, c] : cells[k]) {
      if (c.count < options.min_points) continue;
      ++rep[k].dense;
      if (static_cast<double>(c.zmax) - static_cast<double>(c.zmin) < options.min_wall_height_m) {
        continue;
      }
      ++rep[k].tall;
      if (std::popcount(c.bins) < options.min_filled_bins ||
          std::popcount(static_cast<uint16_t>(c.bins & top_mask)) < options.min_filled_top_bins) {
        continue;
      }
      ++rep[k].uniform;
      const double n = c.count;
      const double mx = c.sx / n, my = c.sy / n;
      Eigen::Matrix2d cov;
      cov << c.sxx / n - mx * mx, c.sxy / n - mx * my, c.sxy / n - mx * my, c.syy / n - my * my;
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
      const double l1 = std::max(0.0, eig.eigenvalues()(0)), l2 = std::max(0.0, eig.eigenvalues()(1));
      const double confidence = l1 + l2 > 0 ? 1 - 2 * l1 / (l1 + l2) : 0;
      if (confidence < options.min_normal_confidence) continue;
      ++rep[k].flat;
      Candidate cand;
      cand.key = key;
      cand.normal = eig.eigenvectors().col(0).normalized();
      // §3.1.1: "flipped to guarantee that it points towards the laser scanner".
      if (cand.normal.dot(Vector2d(c.tx, c.ty)) < 0) cand.normal = -cand.normal;
      cand.zmin = c.zmin;
      cand.zmax = c.zmax;
      cand.count = c.count;
      cand.xhist.assign(options.median_bins, 0);
      cand.yhist.assign(options.median_bins, 0);
      candidates[k].emplace(key, std::move(cand));
    }
    absl::flat_hash_map<uint64_t, CellStats>().swap(cells[k]);
  }

  // Pass 3: medians and poses of the candidates.
  const double bin_w = 2 * ds / options.median_bins;
  const double max_pose_gap = 2 * options.min_pose_spacing_m;
  std::vector<double> last_t(nl, std::numeric_limits<double>::quiet_NaN());
  std::vector<int64_t> last_pose(nl, -1);
  s = stream([&](std::span<const CloudPoint> batch) -> absl::Status {
    for (const CloudPoint& p : batch) {
      if (absl::Status c = CheckPoint(p); !c.ok()) return c;
      const int k = level_of(p.point.z());
      if (k < 0 || candidates[k].empty()) continue;
      // The pose of the point's frame; frames share a time, so it is looked up once a frame.
      if (!(p.t == last_t[k])) {
        last_t[k] = p.t;
        last_pose[k] = -1;
        const LevelPoses& lp = poses[k];
        if (!lp.t.empty()) {
          const size_t hi = std::lower_bound(lp.t.begin(), lp.t.end(), p.t) - lp.t.begin();
          size_t best = hi < lp.t.size() ? hi : lp.t.size() - 1;
          if (hi > 0 && (hi == lp.t.size() || p.t - lp.t[hi - 1] < lp.t[hi] - p.t)) best = hi - 1;
          const Vector2d at = PoseAtTime(path, p.t).translation.head<2>();
          if ((at - lp.xy[best]).norm() <= max_pose_gap) last_pose[k] = static_cast<int64_t>(best);
        }
      }
      ForNeighbourCells(p.point.x(), p.point.y(), ds, [&](uint64_t key, double dx, double dy) {
        auto it = candidates[k].find(key);
        if (it == candidates[k].end()) return;
        Candidate& c = it->second;
        const int bx = std::clamp(static_cast<int>(std::floor((dx + ds) / bin_w)), 0,
                                  options.median_bins - 1);
        const int by = std::clamp(static_cast<int>(std::floor((dy + ds) / bin_w)), 0,
                                  options.median_bins - 1);
        ++c.xhist[bx];
        ++c.yhist[by];
        if (last_pose[k] >= 0 && (c.poses.empty() || c.poses.back() != last_pose[k])) {
          c.poses.push_back(static_cast<uint32_t>(last_pose[k]));
        }
      });
    }
    return absl::OkStatus();
  });
  if (!s.ok()) return s;

  std::vector<WallSampleSet> out(nl);
  for (size_t k = 0; k < nl; ++k) {
    WallSampleSet& set = out[k];
    set.spacing_m = ds;
    set.poses = std::move(poses[k].xy);
    set.path_breaks = std::move(poses[k].breaks);
    std::vector<Candidate*> order;
    order.reserve(candidates[k].size());
    for (auto& [key, c] : candidates[k]) order.push_back(&c);
    std::sort(order.begin(), order.end(), [](const Candidate* a, const Candidate* b) {
      return std::pair(KeyY(a->key), KeyX(a->key)) < std::pair(KeyY(b->key), KeyX(b->key));
    });
    for (Candidate* c : order) {
      const double cx = (static_cast<double>(KeyX(c->key)) + 0.5) * ds;
      const double cy = (static_cast<double>(KeyY(c->key)) + 0.5) * ds;
      const Vector2d median(HistogramMedian(c->xhist, c->count, cx - ds, bin_w),
                            HistogramMedian(c->yhist, c->count, cy - ds, bin_w));
      // §3.1.1: the median must lie within the bounds of g.
      if (!(std::abs(median.x() - cx) < 0.5 * ds && std::abs(median.y() - cy) < 0.5 * ds)) {
        continue;
      }
      WallSample w;
      w.position = median;
      w.normal = c->normal;
      w.floor_z = c->zmin;
      w.ceiling_z = c->zmax;
      std::sort(c->poses.begin(), c->poses.end());
      c->poses.erase(std::unique(c->poses.begin(), c->poses.end()), c->poses.end());
      w.poses = std::move(c->poses);
      rep[k].samples_with_poses += w.poses.empty() ? 0 : 1;
      set.samples.push_back(std::move(w));
    }
    rep[k].samples = set.samples.size();
  }
  if (reports != nullptr) *reports = std::move(rep);
  return out;
}

}  // namespace carvemap
