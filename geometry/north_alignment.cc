#include "geometry/north_alignment.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace carvemap {
namespace {

constexpr double kPi = std::numbers::pi;

double Wrap(double a) {  // to (-π, π]
  a = std::remainder(a, 2 * kPi);
  return a <= -kPi ? a + 2 * kPi : a;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  return v[mid];
}

// The heading with the most readings within ±`half` of it (a sliding window over the sorted
// headings, wrapping around): a start that outliers do not move, unlike the mean.
double DensestHeading(std::vector<double> headings, double half) {
  std::sort(headings.begin(), headings.end());
  const size_t n = headings.size();
  size_t best = 0, best_count = 0, j = 0;
  for (size_t i = 0; i < n; ++i) {
    // Readings in [headings[i], headings[i] + 2·half], continuing past 2π.
    if (j < i) j = i;
    auto at = [&](size_t k) { return k < n ? headings[k] : headings[k - n] + 2 * kPi; };
    while (j + 1 < i + n && at(j + 1) <= headings[i] + 2 * half) ++j;
    if (j - i + 1 > best_count) best_count = j - i + 1, best = i;
  }
  // The window's circular mean.
  double s = 0, c = 0;
  for (size_t k = best; k < best + best_count; ++k) {
    const double h = headings[k % n];
    s += std::sin(h), c += std::cos(h);
  }
  return std::atan2(s, c);
}

}  // namespace

NorthEstimate EstimateNorth(std::span<const Eigen::Vector3d> world_fields,
                            const NorthOptions& options) {
  NorthEstimate e;
  e.readings = int(world_fields.size());
  // θ_i: the turn that brings reading i's horizontal part to +y; weight: that part's length
  // (eq 2.1 fits the raw vectors, so a stronger horizontal field counts more).
  std::vector<double> theta, weight;
  for (const Eigen::Vector3d& f : world_fields) {
    const double h = std::hypot(f.x(), f.y());
    if (!(h > 0) || !std::isfinite(h)) continue;
    theta.push_back(Wrap(kPi / 2 - std::atan2(f.y(), f.x())));
    weight.push_back(h);
  }
  e.usable = int(theta.size());
  if (e.usable < options.min_readings) {
    e.why_not = absl::StrFormat("%d readings with a horizontal field, fewer than %d",
                                e.usable, options.min_readings);
    return e;
  }
  double yaw = DensestHeading(theta, 10.0 * kPi / 180);
  std::vector<double> residual(theta.size());
  double cutoff = kPi;
  for (int iteration = 0; iteration < 50; ++iteration) {
    std::vector<double> abs_residual(theta.size());
    for (size_t i = 0; i < theta.size(); ++i) {
      residual[i] = Wrap(theta[i] - yaw);
      abs_residual[i] = std::abs(residual[i]);
    }
    // Tukey's biweight at 4.685 robust standard deviations (95 % efficiency under Gaussian
    // noise); the scale is floored at 0.5° so that noise-free readings still converge.
    const double scale = std::max(1.4826 * Median(abs_residual), 0.5 * kPi / 180);
    cutoff = 4.685 * scale;
    double s = 0, c = 0;
    for (size_t i = 0; i < theta.size(); ++i) {
      const double u = residual[i] / cutoff;
      if (std::abs(u) >= 1) continue;
      const double w = weight[i] * (1 - u * u) * (1 - u * u);
      s += w * std::sin(residual[i]), c += w * std::cos(residual[i]);
    }
    if (s == 0 && c == 0) break;
    const double step = std::atan2(s, c);
    yaw = Wrap(yaw + step);
    if (std::abs(step) < 1e-12) break;
  }
  std::vector<double> kept_abs;
  for (size_t i = 0; i < theta.size(); ++i) {
    const double r = std::abs(Wrap(theta[i] - yaw));
    if (r < cutoff) kept_abs.push_back(r);
  }
  e.yaw_rad = yaw;
  e.kept = int(kept_abs.size());
  e.spread_rad = 1.4826 * Median(kept_abs);
  e.standard_error_rad = e.kept > 0 ? e.spread_rad / std::sqrt(double(e.kept)) : kPi;
  const double max_spread = options.max_spread_deg * kPi / 180;
  if (e.kept < options.min_readings || e.kept < options.min_kept_fraction * e.usable) {
    e.why_not = absl::StrFormat("only %d of %d readings agree on a heading", e.kept, e.usable);
  } else if (e.spread_rad > max_spread) {
    e.why_not = absl::StrFormat("the readings' headings spread %.1f° (more than %.1f°)",
                                e.spread_rad * 180 / kPi, options.max_spread_deg);
  } else {
    e.confident = true;
  }
  return e;
}

absl::StatusOr<NorthDecision> DecideNorth(NorthMode mode, bool has_readings,
                                          const NorthEstimate& estimate,
                                          double declination_rad, double min_turn_deg) {
  NorthDecision d;
  if (mode == NorthMode::kNone) {
    d.note = "--north none";
    return d;
  }
  if (!has_readings || estimate.readings == 0) {
    if (mode == NorthMode::kMagnetic) {
      return absl::FailedPreconditionError(
          "--north magnetic: the scan has no /magnetometer readings");
    }
    d.note = "the scan has no /magnetometer readings";
    return d;
  }
  if (!estimate.confident) {
    if (mode == NorthMode::kMagnetic) {
      return absl::FailedPreconditionError(
          absl::StrCat("--north magnetic: no confident fit: ", estimate.why_not));
    }
    d.note = absl::StrCat("no confident fit to the magnetometer: ", estimate.why_not,
                          "; the scan's frame is kept");
    d.warn = true;
    return d;
  }
  // Magnetic north lies `declination` east (clockwise) of true north: true north is that much
  // counter-clockwise of +y once the frame is turned to magnetic north.
  const double yaw = Wrap(estimate.yaw_rad - declination_rad);
  const double deg = yaw * 180 / kPi;
  if (mode == NorthMode::kAuto && std::abs(deg) < min_turn_deg) {
    d.note = absl::StrFormat("the turn to %s north, %.2f°, is under %.1f°: within the path's "
                             "own heading drift; the scan's frame is kept",
                             declination_rad == 0 ? "magnetic" : "true", deg, min_turn_deg);
    return d;
  }
  d.yaw_rad = yaw;
  d.turned = true;
  return d;
}

const char* NorthModeName(NorthMode mode) {
  switch (mode) {
    case NorthMode::kMagnetic:
      return "magnetic";
    case NorthMode::kNone:
      return "none";
    case NorthMode::kAuto:
      break;
  }
  return "auto";
}

absl::StatusOr<double> DecimalYear(const std::string& date) {
  int y = 0, m = 0, d = 0;
  char a = 0, b = 0, extra = 0;
  std::istringstream in(date);
  if (!(in >> y >> a >> m >> b >> d) || a != '-' || b != '-' || (in >> extra) || y < 1900 ||
      y > 2200 || m < 1 || m > 12 || d < 1 || d > 31) {
    return absl::InvalidArgumentError(absl::StrCat("'", date, "': expected YYYY-MM-DD"));
  }
  static constexpr int kBefore[12] = {0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334};
  const bool leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
  const int day = kBefore[m - 1] + (leap && m > 2 ? 1 : 0) + d - 1;
  return y + day / (leap ? 366.0 : 365.0);
}

absl::StatusOr<NorthPlace> ParseNorthPlace(std::string_view location, std::string_view date,
                                           std::string_view what) {
  NorthPlace place;
  const std::string text(location);
  char comma = 0, extra = 0;
  std::istringstream in(text);
  if (!(in >> place.lat_deg >> comma >> place.lon_deg) || comma != ',' || (in >> extra) ||
      !(place.lat_deg >= -90 && place.lat_deg <= 90) ||
      !(place.lon_deg >= -180 && place.lon_deg < 360)) {
    return absl::InvalidArgumentError(absl::StrCat(
        std::string(what), " '", text,
        "': expected LAT,LON in degrees (latitude -90..90, longitude -180..360)"));
  }
  place.survey_date = std::string(date);
  if (!place.survey_date.empty() && !DecimalYear(place.survey_date).ok()) {
    return absl::InvalidArgumentError(absl::StrCat(
        std::string(what), ": survey date '", place.survey_date, "': expected YYYY-MM-DD"));
  }
  return place;
}

absl::StatusOr<NorthMode> ParseNorthMode(std::string_view text) {
  if (text.empty() || text == "auto") return NorthMode::kAuto;
  if (text == "magnetic") return NorthMode::kMagnetic;
  if (text == "none") return NorthMode::kNone;
  return absl::InvalidArgumentError(
      absl::StrCat("north: '", std::string(text), "', expected auto, magnetic or none"));
}

}  // namespace carvemap
