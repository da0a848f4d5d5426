#include "coordinator/wedge_builder.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

constexpr float kNoReturn = std::numeric_limits<float>::quiet_NaN();
// Frames farther apart than max_frame_gap_m join only on a surface met within 26.6° of head-on
// along the step between them: their ranges differ by at most this share of their spacing.
// Measured (docs/BENCHMARKS.md): the office's objects 74 % found with 0.5 (67 % without the
// frame limit, 75 % dropping every such wedge); dropping them all left the `room` preset, where
// the walker turns on the spot, speckled (planar mesh 10.9 % of the dense one against 8.6 %).
constexpr double kWideGapRangeStep = 0.5;

// Where b's point lies from a's: `apart`, the distance between the points, and `spacing`, the
// distance of a's point from b's ray, the rays' spacing there. A surface met at θ from head-on
// puts neighbouring points 1/cos θ spacings apart.
struct NeighbourGap {
  double apart, spacing;
};
NeighbourGap GapBetween(const RayModel& a, const RayModel& b) {
  const Eigen::Vector3d p = a.point_mean.cast<double>();
  const Eigen::Vector3d s_b = b.sensor_mean.cast<double>();
  const Eigen::Vector3d u = (b.point_mean.cast<double>() - s_b).normalized();
  const Eigen::Vector3d to_p = p - s_b;
  return {(b.point_mean.cast<double>() - p).norm(), (to_p - to_p.dot(u) * u).norm()};
}

SensorNoiseParams NoiseParamsOf(const SensorInfo& info) {
  SensorNoiseParams p;
  p.R_s2c = info.R_s2c;
  p.T_s2c = info.T_s2c;
  p.sigma_t_s = info.sigma_t_s;
  p.range_sigma_a_m = info.range_sigma[0];
  p.range_sigma_b = info.range_sigma[1];
  return p;
}

absl::Status Invalid(const SensorInfo& info, uint64_t row, const std::string& what) {
  return absl::InvalidArgumentError(
      absl::StrCat("wedge_builder sensor ", info.name, " frame ", row, ": ", what));
}

}  // namespace

absl::Status WedgeBuilderOptions::Validate() const {
  if (auto s = noise.Validate(); !s.ok()) return s;
  if (!std::isfinite(max_range_ratio) || max_range_ratio < 1.0) {
    return absl::InvalidArgumentError(
        absl::StrCat("wedge_builder options: max_range_ratio must be >= 1, got ", max_range_ratio));
  }
  if (!std::isfinite(max_obliquity) || max_obliquity < 1.0) {
    return absl::InvalidArgumentError(
        absl::StrCat("wedge_builder options: max_obliquity must be >= 1, got ", max_obliquity));
  }
  for (auto [name, v] : {std::pair{"min_jump_m", min_jump_m}, std::pair{"min_range_m", min_range_m},
                         std::pair{"max_frame_gap_s", max_frame_gap_s},
                         std::pair{"max_frame_gap_m", max_frame_gap_m},
                         std::pair{"sampling_share", sampling_share}}) {
    if (!std::isfinite(v) || v < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("wedge_builder options: ", name, " must be finite and >= 0, got ", v));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<FrameContext> FrameContextAt(std::span<const TimedPose> path,
                                            std::span<const PathCovariance> path_cov, double t,
                                            const NoiseModelOptions& options) {
  if (path.empty()) return absl::InvalidArgumentError("wedge_builder: empty path");
  absl::StatusOr<PoseCovariance> cov = PoseCovarianceAtTime(path, path_cov, t, options);
  if (!cov.ok()) return cov.status();
  return FrameContext{PoseAtTime(path, t), *cov, AngularVelocityAt(path, t)};
}

absl::StatusOr<WedgeBuilder> WedgeBuilder::Create(std::vector<SensorInfo> sensors,
                                                  const WedgeBuilderOptions& options,
                                                  WedgeSink sink) {
  if (auto s = options.Validate(); !s.ok()) return s;
  if (!sink) return absl::InvalidArgumentError("wedge_builder: no sink");
  std::vector<SensorState> states;
  states.reserve(sensors.size());
  for (SensorInfo& info : sensors) {
    if (info.kind == SensorKind::kGrid && (info.rows == 0 || info.cols == 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("wedge_builder sensor ", info.name, ": grid sensor without rows/cols"));
    }
    SensorState st;
    st.index = uint32_t(states.size());
    st.noise = NoiseParamsOf(info);
    st.info = std::move(info);
    states.push_back(std::move(st));
  }
  return WedgeBuilder(std::move(states), options, std::move(sink));
}

WedgeBuilder::WedgeBuilder(std::vector<SensorState> sensors, const WedgeBuilderOptions& options,
                           WedgeSink sink)
    : sensors_(std::move(sensors)), options_(options), sink_(std::move(sink)) {}

void WedgeBuilder::ComputeRays(const SensorState& s, const ScanFrame& frame,
                               const FrameContext& context) {
  const size_t n = frame.points_sensor.size();
  cur_rays_.resize(n);
  cur_range_.resize(n);
  cur_covered_.assign(n, 0);
  // Eq 4.5 and the pose-only parts of eq 4.6 once per frame: its rays share one timestamp.
  const FrameNoiseModel model(context.pose_world_sys, context.covariance, context.omega_world,
                              s.noise, options_.noise);
  ++stats_.frames;
  stats_.rays += n;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = frame.points_sensor[i];
    const float range = p.norm();
    // NaN rows have no return (docs/DESIGN.md §3); a return at the sensor has no direction.
    if (!p.allFinite() || !(range >= options_.min_range_m)) {
      cur_range_[i] = kNoReturn;
      ++stats_.rays_without_return;
      continue;
    }
    cur_range_[i] = range;
    RayModel& ray = cur_rays_[i];
    ray = model.Ray(p.cast<double>());
    // The pose terms' cross terms would tilt F_p (AlongAndAcross); the sampling term's are kept.
    const Eigen::Vector3d d =
        (ray.point_mean.cast<double>() - ray.sensor_mean.cast<double>()).normalized();
    ray.point_cov = ToSymCov(AlongAndAcross(ToMatrix(ray.point_cov), d));
  }
}

void WedgeBuilder::AddSamplingCovariance(const SensorState& s, const SensorState* prev) {
  if (options_.sampling_share == 0) return;
  const size_t n = cur_rays_.size();
  const bool grid = s.info.kind == SensorKind::kGrid;
  const size_t cols = grid ? s.info.cols : n;
  // Reads only ranges and means, which this does not change: each ray's covariance is updated
  // in place, in any order.
  for (size_t i = 0; i < n; ++i) {
    const float range = cur_range_[i];
    if (std::isnan(range)) continue;
    RayModel& r = cur_rays_[i];
    const Eigen::Vector3d p = r.point_mean.cast<double>();
    // Only neighbours on the same surface: the wedges' discontinuity rule, and a surface met
    // no more obliquely than max_obliquity allows. A step from a desk's edge to the floor behind it
    // passes the range rule at a glance but is many times the rays' spacing long; spread along
    // it, the ray's surface would tilt into the free space in front of the edge.
    const auto joins = [&](std::span<const float> ranges, std::span<const RayModel> rays,
                           size_t k) {
      if (k >= ranges.size() || std::isnan(ranges[k]) ||
          !Continuous(range, range, ranges[k], ranges[k])) {
        return false;
      }
      const NeighbourGap g = GapBetween(r, rays[k]);
      return g.apart <= options_.max_obliquity * g.spacing;
    };
    std::array<Eigen::Vector3d, 2> a, b;
    size_t na = 0, nb = 0;
    const size_t x = i % cols;
    const std::span<const RayModel> cur(cur_rays_);
    if (x > 0 && joins(cur_range_, cur, i - 1)) a[na++] = cur[i - 1].point_mean.cast<double>();
    if (x + 1 < cols && joins(cur_range_, cur, i + 1)) {
      a[na++] = cur[i + 1].point_mean.cast<double>();
    }
    if (grid) {
      if (i >= cols && joins(cur_range_, cur, i - cols)) {
        b[nb++] = cur[i - cols].point_mean.cast<double>();
      }
      if (joins(cur_range_, cur, i + cols)) b[nb++] = cur[i + cols].point_mean.cast<double>();
    } else if (prev != nullptr && joins(prev->prev_range, prev->prev_rays, i)) {
      b[nb++] = prev->prev_rays[i].point_mean.cast<double>();
    }
    if (na + nb == 0) continue;
    r.point_cov = ToSymCov(ToMatrix(r.point_cov) + SamplingCovariance(p, {a.data(), na},
                                                                      {b.data(), nb},
                                                                      options_.sampling_share));
  }
}

bool WedgeBuilder::Continuous(float a, float b, float c, float d) const {
  const double lo = std::min(std::min(a, b), std::min(c, d));
  const double hi = std::max(std::max(a, b), std::max(c, d));
  return hi - lo <= std::max(options_.min_jump_m, (options_.max_range_ratio - 1.0) * lo);
}

bool WedgeBuilder::OneSurface(const RayModel& a, const RayModel& b, const RayModel& c,
                              const RayModel& d, bool line) const {
  auto joined = [&](const RayModel& x, const RayModel& y, bool across_frames) {
    const NeighbourGap g = GapBetween(x, y);
    if (g.apart > options_.max_obliquity * g.spacing) return false;
    if (!across_frames || g.spacing <= options_.max_frame_gap_m) return true;
    const double range_x = (x.point_mean - x.sensor_mean).norm();
    const double range_y = (y.point_mean - y.sensor_mean).norm();
    return std::abs(range_x - range_y) <= kWideGapRangeStep * g.spacing;
  };
  return joined(a, b, false) && joined(c, d, false) && joined(a, c, line) && joined(b, d, line);
}

absl::Status WedgeBuilder::EmitWedge(const RayModel& a, const RayModel& b, const RayModel& c,
                                     const RayModel& d, const std::array<RayId, 4>& ids) {
  wedge_.rays = {a, b, c, d};
  wedge_.num_rays = 4;
  ++stats_.wedges;
  return sink_(wedge_, ids);
}

absl::Status WedgeBuilder::EmitSingles(const SensorState& s, uint64_t frame,
                                       std::span<const RayModel> rays, std::span<const float> range,
                                       std::span<const uint8_t> covered, size_t begin, size_t end) {
  wedge_.num_rays = 1;
  end = std::min(end, rays.size());
  for (size_t i = begin; i < end; ++i) {
    if (std::isnan(range[i]) || covered[i]) continue;
    wedge_.rays.fill(rays[i]);
    ++stats_.single_ray_wedges;
    const RayId id{s.index, frame, uint32_t(i)};
    if (auto st = sink_(wedge_, {&id, 1}); !st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::Status WedgeBuilder::AddLineFrame(SensorState& s, const ScanFrame& frame) {
  const uint64_t cur = frame.row, prev = s.prev_row;
  const bool joined = s.has_prev && frame.t - s.prev_t <= options_.max_frame_gap_s;
  AddSamplingCovariance(s, joined ? &s : nullptr);
  if (joined) {
    const size_t n = std::min(s.prev_rays.size(), cur_rays_.size());
    const auto& pr = s.prev_range;
    const auto& cr = cur_range_;
    for (size_t j = 0; j + 1 < n; ++j) {
      if (std::isnan(pr[j]) || std::isnan(pr[j + 1]) || std::isnan(cr[j]) || std::isnan(cr[j + 1])) {
        continue;
      }
      if (!Continuous(pr[j], pr[j + 1], cr[j], cr[j + 1]) ||
          !OneSurface(s.prev_rays[j], s.prev_rays[j + 1], cur_rays_[j], cur_rays_[j + 1],
                      /*line=*/true)) {
        ++stats_.discontinuities;
        continue;
      }
      const uint32_t j0 = uint32_t(j), j1 = uint32_t(j + 1);
      if (auto st = EmitWedge(s.prev_rays[j], s.prev_rays[j + 1], cur_rays_[j],
                              cur_rays_[j + 1],
                              {RayId{s.index, prev, j0}, RayId{s.index, prev, j1},
                               RayId{s.index, cur, j0}, RayId{s.index, cur, j1}});
          !st.ok()) {
        return st;
      }
      s.prev_covered[j] = s.prev_covered[j + 1] = 1;
      cur_covered_[j] = cur_covered_[j + 1] = 1;
    }
  }
  // The previous frame has met both its neighbours now: whatever it has left carves alone.
  if (s.has_prev) {
    if (auto st = EmitSingles(s, prev, s.prev_rays, s.prev_range, s.prev_covered); !st.ok()) {
      return st;
    }
  }
  std::swap(s.prev_rays, cur_rays_);
  std::swap(s.prev_range, cur_range_);
  std::swap(s.prev_covered, cur_covered_);
  s.prev_t = frame.t;
  s.prev_row = frame.row;
  s.has_prev = true;
  return absl::OkStatus();
}

absl::Status WedgeBuilder::AddGridFrame(SensorState& s, const ScanFrame& frame) {
  const size_t rows = s.info.rows, cols = s.info.cols;
  const uint64_t f = frame.row;
  AddSamplingCovariance(s, nullptr);
  auto id = [&](size_t i) { return RayId{s.index, f, uint32_t(i)}; };
  const auto& r = cur_range_;
  for (size_t y = 0; y + 1 < rows; ++y) {
    for (size_t x = 0; x + 1 < cols; ++x) {
      const size_t i00 = y * cols + x, i01 = i00 + 1, i10 = i00 + cols, i11 = i10 + 1;
      if (std::isnan(r[i00]) || std::isnan(r[i01]) || std::isnan(r[i10]) || std::isnan(r[i11])) {
        continue;
      }
      if (!Continuous(r[i00], r[i01], r[i10], r[i11]) ||
          !OneSurface(cur_rays_[i00], cur_rays_[i01], cur_rays_[i10], cur_rays_[i11],
                      /*line=*/false)) {
        ++stats_.discontinuities;
        continue;
      }
      if (auto st = EmitWedge(cur_rays_[i00], cur_rays_[i01], cur_rays_[i10],
                              cur_rays_[i11], {id(i00), id(i01), id(i10), id(i11)});
          !st.ok()) {
        return st;
      }
      cur_covered_[i00] = cur_covered_[i01] = cur_covered_[i10] = cur_covered_[i11] = 1;
    }
    // Row y has met both its neighbouring rows: what it has left carves alone, now, so that
    // the wedges come in row order and a large frame can be carved in bands of rows.
    if (auto st = EmitSingles(s, f, cur_rays_, cur_range_, cur_covered_, y * cols, (y + 1) * cols);
        !st.ok()) {
      return st;
    }
  }
  return EmitSingles(s, f, cur_rays_, cur_range_, cur_covered_, (rows - 1) * cols, rows * cols);
}

absl::Status WedgeBuilder::AddFrame(const ScanFrame& frame, const FrameContext& context) {
  if (frame.sensor < 0 || static_cast<size_t>(frame.sensor) >= sensors_.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("wedge_builder: frame ", frame.row, " of unknown sensor ", frame.sensor));
  }
  SensorState& s = sensors_[frame.sensor];
  if (!std::isfinite(frame.t) || (s.has_prev && frame.t < s.prev_t)) {
    return Invalid(s.info, frame.row, absl::StrCat("time ", frame.t, " goes backwards"));
  }
  // Rows name the rays (RayId::frame): one row twice would make two rays one.
  if (s.seen_any && frame.row <= s.last_row) {
    return Invalid(s.info, frame.row, absl::StrCat("row not after the previous row ", s.last_row));
  }
  s.seen_any = true;
  s.last_row = frame.row;
  if (s.info.kind == SensorKind::kGrid &&
      frame.points_sensor.size() != size_t{s.info.rows} * s.info.cols) {
    return Invalid(s.info, frame.row,
                   absl::StrCat(frame.points_sensor.size(), " rays, expected rows·cols = ",
                                size_t{s.info.rows} * s.info.cols));
  }
  ComputeRays(s, frame, context);
  switch (s.info.kind) {
    case SensorKind::kLine:
      return AddLineFrame(s, frame);
    case SensorKind::kGrid:
      return AddGridFrame(s, frame);
    case SensorKind::kPoints:
      return EmitSingles(s, frame.row, cur_rays_, cur_range_, cur_covered_);
  }
  return absl::InternalError("wedge_builder: unknown sensor kind");
}

absl::Status WedgeBuilder::Finish() {
  for (SensorState& s : sensors_) {
    if (!s.has_prev) continue;
    if (auto st = EmitSingles(s, s.prev_row, s.prev_rays, s.prev_range, s.prev_covered);
        !st.ok()) {
      return st;
    }
    s.has_prev = false;
    s.prev_rays.clear();
    s.prev_range.clear();
    s.prev_covered.clear();
  }
  return absl::OkStatus();
}

absl::StatusOr<WedgeBuilderStats> BuildWedges(
    ScanReader& reader, const WedgeBuilderOptions& options, WedgeSink sink,
    const std::function<void(const WedgeBuilderStats&)>& after_frame) {
  absl::StatusOr<WedgeBuilder> builder =
      WedgeBuilder::Create(reader.sensors(), options, std::move(sink));
  if (!builder.ok()) return builder.status();
  const std::vector<TimedPose>& path = reader.timed_path();
  std::span<const PathCovariance> cov;
  if (reader.path_covariance().has_value()) cov = *reader.path_covariance();
  std::unique_ptr<ScanReader::FrameStream> stream = reader.StreamFrames();
  ScanFrame frame;
  while (true) {
    absl::StatusOr<bool> more = stream->Next(frame);
    if (!more.ok()) return more.status();
    if (!*more) break;
    absl::StatusOr<FrameContext> ctx = FrameContextAt(path, cov, frame.t, options.noise);
    if (!ctx.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat(reader.file(), ": frame at t=", frame.t, ": ", ctx.status().message()));
    }
    if (auto st = builder->AddFrame(frame, *ctx); !st.ok()) return st;
    if (after_frame) after_frame(builder->stats());
  }
  if (auto st = builder->Finish(); !st.ok()) return st;
  WedgeBuilderStats stats = builder->stats();
  stats.default_covariance = cov.empty();
  return stats;
}

}  // namespace carvemap
