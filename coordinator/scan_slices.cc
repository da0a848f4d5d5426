#include "coordinator/scan_slices.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace carvemap {

double SliceSeconds(const SlicePlanOptions& options, uint64_t rays, double duration_s) {
  if (options.slice_s > 0) return options.slice_s;
  if (rays == 0 || !(duration_s > 0)) return std::max(options.min_slice_s, 1.0);
  const double by_rays =
      std::max(options.min_slice_s, duration_s * double(options.target_rays) / double(rays));
  return std::min(by_rays,
                  std::max(options.shortest_slice_s, duration_s / std::max(options.min_slices, 1)));
}

absl::StatusOr<std::vector<ScanSlice>> PlanSlices(std::span<const std::vector<FrameRecord>> frames,
                                                  std::span<const SensorKind> kinds,
                                                  double slice_s) {
  if (frames.size() != kinds.size()) {
    return absl::InvalidArgumentError(absl::StrCat("scan slices: ", frames.size(),
                                                   " sensors' frames for ", kinds.size(),
                                                   " sensor kinds"));
  }
  if (!(slice_s > 0) || !std::isfinite(slice_s)) {
    return absl::InvalidArgumentError(absl::StrCat("scan slices: slice length ", slice_s,
                                                   " s is not a positive number"));
  }
  double t0 = std::numeric_limits<double>::infinity(), t1 = -t0;
  for (const std::vector<FrameRecord>& f : frames) {
    for (const FrameRecord& r : f) {
      if (!std::isfinite(r.t)) {
        return absl::InvalidArgumentError("scan slices: a frame time is not finite");
      }
    }
    if (!f.empty()) {
      t0 = std::min(t0, f.front().t);
      t1 = std::max(t1, f.back().t);
    }
  }
  std::vector<ScanSlice> slices;
  if (!(t0 <= t1)) return slices;  // no frames
  const uint64_t count = uint64_t(std::floor((t1 - t0) / slice_s)) + 1;
  const size_t n = frames.size();
  for (uint64_t k = 0; k < count; ++k) {
    ScanSlice s;
    s.t_begin = t0 + double(k) * slice_s;
    // The last slice takes everything to the end, so no frame falls past it by rounding.
    s.t_end = k + 1 == count ? std::numeric_limits<double>::infinity()
                             : t0 + double(k + 1) * slice_s;
    s.own.resize(n);
    s.read.resize(n);
    bool any = false;
    for (size_t i = 0; i < n; ++i) {
      const std::vector<FrameRecord>& f = frames[i];
      const auto at = [&f](double t) {
        return uint64_t(std::lower_bound(f.begin(), f.end(), t,
                                         [](const FrameRecord& r, double v) { return r.t < v; }) -
                        f.begin());
      };
      ScanReader::RowRange own{at(s.t_begin), at(s.t_end)};
      s.own[i] = own;
      ScanReader::RowRange read = own;
      if (own.begin < own.end && kinds[i] == SensorKind::kLine) {
        read.begin = own.begin - std::min(own.begin, kSliceFramesBefore);
        read.end = std::min<uint64_t>(f.size(), own.end + kSliceFramesAfter);
      }
      s.read[i] = read;
      for (uint64_t r = own.begin; r < own.end; ++r) s.own_rays += f[r].count;
      any |= own.begin < own.end;
    }
    if (!any) continue;
    s.index = uint32_t(slices.size());
    slices.push_back(std::move(s));
  }
  return slices;
}

absl::StatusOr<ScanSlicePlan> PlanScanSlices(ScanReader& reader, const SlicePlanOptions& options) {
  if (absl::Status s = reader.Validate(); !s.ok()) return s;
  std::vector<std::vector<FrameRecord>> frames;
  std::vector<SensorKind> kinds;
  for (size_t i = 0; i < reader.sensors().size(); ++i) {
    absl::StatusOr<std::vector<FrameRecord>> f = reader.FrameRecords(int(i));
    if (!f.ok()) return f.status();
    frames.push_back(*std::move(f));
    kinds.push_back(reader.sensors()[i].kind);
  }
  ScanSlicePlan plan;
  double t0 = std::numeric_limits<double>::infinity(), t1 = -t0;
  for (const std::vector<FrameRecord>& f : frames) {
    for (const FrameRecord& r : f) plan.rays += r.count;
    if (!f.empty()) {
      t0 = std::min(t0, f.front().t);
      t1 = std::max(t1, f.back().t);
    }
  }
  plan.slice_s = SliceSeconds(options, plan.rays, t1 > t0 ? t1 - t0 : 0.0);
  absl::StatusOr<std::vector<ScanSlice>> slices = PlanSlices(frames, kinds, plan.slice_s);
  if (!slices.ok()) {
    return absl::Status(slices.status().code(),
                        absl::StrCat(reader.file(), ": ", slices.status().message()));
  }
  plan.slices = *std::move(slices);
  return plan;
}

}  // namespace carvemap
