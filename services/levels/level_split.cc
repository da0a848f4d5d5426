#include "services/levels/level_split.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace carvemap {

absl::Status LevelSplitOptions::Validate() const {
  auto bad = [](const char* name, double v) {
    return absl::InvalidArgumentError(absl::StrCat("level_split: bad ", name, " = ", v));
  };
  auto finite_ge0 = [](double v) { return std::isfinite(v) && v >= 0; };
  if (!std::isfinite(max_tilt_deg) || max_tilt_deg < 0 || max_tilt_deg > 90) {
    return bad("max_tilt_deg", max_tilt_deg);
  }
  if (!finite_ge0(min_region_area_m2)) return bad("min_region_area_m2", min_region_area_m2);
  if (!std::isfinite(bin_m) || bin_m <= 0) return bad("bin_m", bin_m);
  if (!finite_ge0(smoothing_m)) return bad("smoothing_m", smoothing_m);
  if (!finite_ge0(peak_window_m)) return bad("peak_window_m", peak_window_m);
  if (!std::isfinite(min_peak_fraction) || min_peak_fraction < 0 || min_peak_fraction > 1) {
    return bad("min_peak_fraction", min_peak_fraction);
  }
  if (!finite_ge0(min_level_height_m)) return bad("min_level_height_m", min_level_height_m);
  if (!finite_ge0(min_ceiling_height_m)) return bad("min_ceiling_height_m", min_ceiling_height_m);
  if (!finite_ge0(end_margin_m)) return bad("end_margin_m", end_margin_m);
  if (!finite_ge0(default_ceiling_height_m)) {
    return bad("default_ceiling_height_m", default_ceiling_height_m);
  }
  return absl::OkStatus();
}

namespace {

constexpr int64_t kMaxBins = 10'000'000;

struct Peak {
  double z = 0;       // refined: weighted mean of the samples near the peak
  double weight = 0;  // Σ weights of those samples
};

absl::Status CheckSamples(std::span<const HeightSample> samples, const char* what) {
  for (size_t i = 0; i < samples.size(); ++i) {
    if (!std::isfinite(samples[i].z) || !std::isfinite(samples[i].weight) ||
        samples[i].weight < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("level_split: ", what, " sample ", i, " is not finite or has a negative "
                       "weight"));
    }
  }
  return absl::OkStatus();
}

// The significant local maxima of the smoothed weight histogram of `samples`, ascending in z.
// Exact sample heights are kept for the refinement, so a surface at a known elevation is found
// at that elevation, not at its bin's centre.
absl::StatusOr<std::vector<Peak>> FindPeaks(std::span<const HeightSample> samples,
                                            const LevelSplitOptions& o) {
  std::vector<Peak> peaks;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const HeightSample& s : samples) {
    if (s.weight <= 0) continue;
    lo = std::min(lo, s.z);
    hi = std::max(hi, s.z);
  }
  if (!(lo <= hi)) return peaks;
  const int64_t r = std::llround(o.smoothing_m / o.bin_m);      // kernel half-width, bins
  // Suppression radius: peaks exactly peak_window_m apart are both kept.
  const int64_t w = std::max<int64_t>(1, std::llround(o.peak_window_m / o.bin_m) - 1);
  const double z0 = lo - double(r + 1) * o.bin_m;
  const double span_bins = (hi - z0) / o.bin_m + double(r) + 2;
  if (span_bins > double(kMaxBins)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "level_split: heights span ", hi - lo, " m, more than ", kMaxBins, " bins of ", o.bin_m,
        " m"));
  }
  const int64_t n = int64_t(span_bins) + 1;
  std::vector<double> h(size_t(n), 0.0);
  for (const HeightSample& s : samples) {
    if (s.weight <= 0) continue;
    h[size_t(std::clamp<int64_t>(int64_t(std::floor((s.z - z0) / o.bin_m)), 0, n - 1))] +=
        s.weight;
  }
  // Triangular smoothing: a surface whose samples straddle a bin edge still makes one peak.
  std::vector<double> sm(size_t(n), 0.0);
  for (int64_t i = 0; i < n; ++i) {
    if (h[size_t(i)] == 0) continue;
    for (int64_t d = -r; d <= r; ++d) {
      const int64_t j = i + d;
      if (j < 0 || j >= n) continue;
      sm[size_t(j)] += h[size_t(i)] * (1.0 - double(std::abs(d)) / double(r + 1));
    }
  }
  const double top = *std::max_element(sm.begin(), sm.end());
  std::vector<int64_t> maxima;
  for (int64_t i = 0; i < n; ++i) {
    const double v = sm[size_t(i)];
    if (v <= 0 || v < o.min_peak_fraction * top) continue;
    bool is_max = true;
    for (int64_t j = std::max<int64_t>(0, i - w); j <= std::min(n - 1, i + w) && is_max; ++j) {
      // A plateau counts once, at its lowest bin.
      if (j < i ? sm[size_t(j)] >= v : sm[size_t(j)] > v) is_max = false;
    }
    if (is_max) maxima.push_back(i);
  }
  // Refine each peak from the samples within half a window of it.
  const double half = 0.5 * std::max(o.peak_window_m, o.bin_m);
  for (int64_t i : maxima) {
    const double zc = z0 + (double(i) + 0.5) * o.bin_m;
    double sw = 0, swz = 0;
    for (const HeightSample& s : samples) {
      if (s.weight > 0 && std::abs(s.z - zc) <= half) {
        sw += s.weight;
        swz += s.weight * s.z;
      }
    }
    if (sw > 0) peaks.push_back({swz / sw, sw});
  }
  return peaks;
}

}  // namespace

absl::StatusOr<std::vector<Level>> SplitLevelsFromSamples(std::span<const HeightSample> floors,
                                                          std::span<const HeightSample> ceilings,
                                                          const LevelSplitOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = CheckSamples(floors, "floor"); !s.ok()) return s;
  if (absl::Status s = CheckSamples(ceilings, "ceiling"); !s.ok()) return s;
  absl::StatusOr<std::vector<Peak>> fp = FindPeaks(floors, options);
  if (!fp.ok()) return fp.status();
  absl::StatusOr<std::vector<Peak>> cp = FindPeaks(ceilings, options);
  if (!cp.ok()) return cp.status();

  // Pairing, after §2.5's pruning ("the lowest floor maximum is the first level's floor; its
  // ceiling is the most populated ceiling maximum below the next floor"), with two changes:
  // - floor peaks within min_level_height_m of the first one are one level and its floor is
  //   the heaviest of them, so a table top, a landing or a sunken area never starts a level;
  // - the level's ceiling_z is its highest ceiling peak below the next floor, not the most
  //   populated one: rooms of a level have different ceilings (docs/DESIGN.md §4: a level's
  //   ceiling_z is its highest room ceiling), and the split above the level must clear all of
  //   them. The most populated one is kept as dominant_ceiling_z.
  std::vector<Level> levels;
  const std::vector<Peak>& F = *fp;
  const std::vector<Peak>& C = *cp;
  size_t i = 0;
  while (i < F.size()) {
    size_t best = i;
    for (size_t j = i; j < F.size() && F[j].z < F[i].z + options.min_level_height_m; ++j) {
      if (F[j].weight > F[best].weight) best = j;
    }
    size_t next = best + 1;
    while (next < F.size() && F[next].z < F[best].z + options.min_level_height_m) ++next;
    const double upper =
        next < F.size() ? F[next].z : std::numeric_limits<double>::infinity();
    Level level;
    level.index = int(levels.size());
    level.floor_z = F[best].z;
    level.floor_weight = F[best].weight;
    const Peak* highest = nullptr;
    const Peak* heaviest = nullptr;
    for (const Peak& c : C) {
      if (c.z < level.floor_z + options.min_ceiling_height_m || c.z >= upper) continue;
      if (highest == nullptr || c.z > highest->z) highest = &c;
      if (heaviest == nullptr || c.weight > heaviest->weight) heaviest = &c;
    }
    if (highest != nullptr) {
      level.ceiling_z = highest->z;
      level.ceiling_weight = highest->weight;
      level.dominant_ceiling_z = heaviest->z;
    } else {
      // §5.2 pairs each level's floor with a ceiling. A floor with none above it, over a level
      // whose ceiling was seen, is not a level: the scans that saw the lower ceiling would
      // have seen this one's too. It is carved space above a ceiling, e.g. the sheet that
      // drifted rays carve over a slab (Freiburg101, 3D route: a 33 m² "floor" 19 cm above
      // the 2.61 m ceiling). Its floor peaks join the level below, like a table top.
      if (!levels.empty() && levels.back().ceiling_found) {
        i = next;
        continue;
      }
      level.ceiling_found = false;
      level.ceiling_z = std::isfinite(upper) ? upper
                                             : level.floor_z + options.default_ceiling_height_m;
      level.dominant_ceiling_z = level.ceiling_z;
    }
    levels.push_back(level);
    i = next;
  }
  // §5.2: "The model can be split by level at the elevation halfway between the ceiling of the
  // lower level and the floor of the upper level."
  for (size_t k = 0; k < levels.size(); ++k) {
    levels[k].split_z_low = k == 0 ? levels[k].floor_z - options.end_margin_m
                                   : 0.5 * (levels[k - 1].ceiling_z + levels[k].floor_z);
    levels[k].split_z_high = k + 1 == levels.size()
                                 ? levels[k].ceiling_z + options.end_margin_m
                                 : 0.5 * (levels[k].ceiling_z + levels[k + 1].floor_z);
  }
  return levels;
}

absl::StatusOr<std::vector<Level>> SplitLevelsFromRegions(std::span<const PlanarRegion> regions,
                                                          const LevelSplitOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  // §5.2: horizontal (within max_tilt_deg of vertical) and large enough; floors face up,
  // ceilings down (normals point into free space). The plane's height is the centroid's z.
  const double cos_tilt = std::cos(options.max_tilt_deg * M_PI / 180.0);
  std::vector<HeightSample> floors, ceilings;
  for (const PlanarRegion& r : regions) {
    if (r.area_m2 < options.min_region_area_m2 || !r.normal.allFinite()) continue;
    const double nz = r.normal.z() / std::max(r.normal.norm(), 1e-300);
    if (nz >= cos_tilt) floors.push_back({r.centroid.z(), r.area_m2});
    if (nz <= -cos_tilt) ceilings.push_back({r.centroid.z(), r.area_m2});
  }
  return SplitLevelsFromSamples(floors, ceilings, options);
}

absl::StatusOr<HeightHistogram> BuildHeightHistogram(std::span<const double> floor_points_z,
                                                     std::span<const double> ceiling_points_z,
                                                     double bin_m) {
  if (!std::isfinite(bin_m) || bin_m <= 0) {
    return absl::InvalidArgumentError(absl::StrCat("level_split: bad bin_m = ", bin_m));
  }
  HeightHistogram h;
  h.bin_m = bin_m;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::span<const double> zs : {floor_points_z, ceiling_points_z}) {
    for (size_t i = 0; i < zs.size(); ++i) {
      if (!std::isfinite(zs[i])) {
        return absl::InvalidArgumentError(
            absl::StrCat("level_split: point height ", i, " is not finite"));
      }
      lo = std::min(lo, zs[i]);
      hi = std::max(hi, zs[i]);
    }
  }
  if (!(lo <= hi)) return h;
  h.z0_m = std::floor(lo / bin_m) * bin_m;
  const double bins = std::floor((hi - h.z0_m) / bin_m) + 1;
  if (bins > double(kMaxBins)) {
    return absl::InvalidArgumentError(
        absl::StrCat("level_split: point heights span ", hi - lo, " m, more than ", kMaxBins,
                     " bins"));
  }
  h.floor.assign(size_t(bins), 0.0);
  h.ceiling.assign(size_t(bins), 0.0);
  auto add = [&](std::span<const double> zs, std::vector<double>& out) {
    for (double z : zs) {
      const int64_t b = std::clamp<int64_t>(int64_t(std::floor((z - h.z0_m) / bin_m)), 0,
                                            int64_t(out.size()) - 1);
      out[size_t(b)] += 1.0;
    }
  };
  add(floor_points_z, h.floor);
  add(ceiling_points_z, h.ceiling);
  return h;
}

absl::StatusOr<std::vector<Level>> SplitLevelsFromHistogram(const HeightHistogram& histogram,
                                                            const LevelSplitOptions& options) {
  if (!std::isfinite(histogram.bin_m) || histogram.bin_m <= 0 ||
      !std::isfinite(histogram.z0_m) || histogram.floor.size() != histogram.ceiling.size()) {
    return absl::InvalidArgumentError(
        "level_split: point histogram needs bin_m > 0, a finite z0_m and floor and ceiling of "
        "the same length");
  }
  // Each bin is a sample at its centre weighted by its count (§2.5).
  std::vector<HeightSample> floors, ceilings;
  for (size_t i = 0; i < histogram.floor.size(); ++i) {
    const double z = histogram.z0_m + (double(i) + 0.5) * histogram.bin_m;
    if (histogram.floor[i] != 0) floors.push_back({z, histogram.floor[i]});
    if (histogram.ceiling[i] != 0) ceilings.push_back({z, histogram.ceiling[i]});
  }
  return SplitLevelsFromSamples(floors, ceilings, options);
}

absl::StatusOr<LevelSplit> SplitLevels(std::span<const PlanarRegion> regions,
                                       const HeightHistogram* point_heights,
                                       const LevelSplitOptions& options) {
  LevelSplit out;
  absl::StatusOr<std::vector<Level>> from_regions = SplitLevelsFromRegions(regions, options);
  if (!from_regions.ok()) return from_regions.status();
  if (!from_regions->empty()) {
    out.levels = *std::move(from_regions);
    out.source = "regions";
    return out;
  }
  if (point_heights != nullptr) {
    absl::StatusOr<std::vector<Level>> from_points =
        SplitLevelsFromHistogram(*point_heights, options);
    if (!from_points.ok()) return from_points.status();
    if (!from_points->empty()) {
      out.levels = *std::move(from_points);
      out.source = "points";
      return out;
    }
  }
  out.source = "none";
  return out;
}

nlohmann::json LevelsToJson(std::span<const Level> levels) {
  nlohmann::json out = nlohmann::json::array();
  for (const Level& l : levels) {
    out.push_back({{"index", l.index},
                   {"floor_z", l.floor_z},
                   {"ceiling_z", l.ceiling_z},
                   {"split_z", l.split_z_low},
                   {"split_z_high", l.split_z_high},
                   {"dominant_ceiling_z", l.dominant_ceiling_z},
                   {"ceiling_found", l.ceiling_found}});
  }
  return out;
}

}  // namespace carvemap
