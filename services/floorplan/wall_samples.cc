#include "services/floorplan/wall_samples.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

bool Finite(const Eigen::Vector2d& v) { return std::isfinite(v.x()) && std::isfinite(v.y()); }

}  // namespace

absl::Status WallSampleSet::Validate() const {
  if (!std::isfinite(spacing_m) || spacing_m <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("wall samples: spacing_m must be finite and > 0, got ", spacing_m));
  }
  for (size_t i = 0; i < poses.size(); ++i) {
    if (!Finite(poses[i])) {
      return absl::InvalidArgumentError(absl::StrCat("wall samples: pose ", i, " is not finite"));
    }
  }
  for (size_t i = 0; i < path_breaks.size(); ++i) {
    if (path_breaks[i] >= poses.size() || (i > 0 && path_breaks[i] <= path_breaks[i - 1])) {
      return absl::InvalidArgumentError(absl::StrCat(
          "wall samples: path_breaks[", i, "] = ", path_breaks[i],
          " is out of range or not ascending (", poses.size(), " poses)"));
    }
  }
  for (size_t i = 0; i < samples.size(); ++i) {
    const WallSample& s = samples[i];
    if (!Finite(s.position) || !Finite(s.normal) || !std::isfinite(s.floor_z) ||
        !std::isfinite(s.ceiling_z)) {
      return absl::InvalidArgumentError(
          absl::StrCat("wall samples: sample ", i, " has a non-finite value"));
    }
    if (s.floor_z >= s.ceiling_z) {
      return absl::InvalidArgumentError(absl::StrCat("wall samples: sample ", i, " has floor_z ",
                                                     s.floor_z, " ≥ ceiling_z ", s.ceiling_z));
    }
    const double n = s.normal.norm();
    if (n != 0 && std::abs(n - 1) > 1e-6) {
      return absl::InvalidArgumentError(
          absl::StrCat("wall samples: sample ", i, " has a normal of length ", n));
    }
    for (size_t k = 0; k < s.poses.size(); ++k) {
      if (s.poses[k] >= poses.size() || (k > 0 && s.poses[k] <= s.poses[k - 1])) {
        return absl::InvalidArgumentError(absl::StrCat(
            "wall samples: sample ", i, " pose index ", s.poses[k],
            " is out of range or not ascending (", poses.size(), " poses)"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace carvemap
