#include "services/segment/plan_volume.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "services/floorplan/eval/room_scoring.h"

namespace carvemap {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// 1D squared distance transform of sampled function f (Felzenszwalb & Huttenlocher 2012, the
// lower envelope of parabolas), in place. Our own: no Debian package offers it for plain arrays.
void Edt1d(std::vector<float>& f, std::vector<float>& d, std::vector<int>& v,
           std::vector<float>& z) {
  const int n = static_cast<int>(f.size());
  d.resize(n);
  v.resize(n);
  z.resize(n + 1);
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kInf) continue;
    if (k < 0) {
      k = 0;
      v[0] = q;
      z[0] = -kInf;
      z[1] = kInf;
      continue;
    }
    float s;
    while (true) {
      const int p = v[k];
      s = ((f[q] + static_cast<float>(q) * q) - (f[p] + static_cast<float>(p) * p)) /
          (2.0f * (q - p));
      if (s <= z[k] && k > 0) {
        --k;
        continue;
      }
      break;
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kInf;
  }
  if (k < 0) {
    std::fill(d.begin(), d.end(), kInf);
  } else {
    int j = 0;
    for (int q = 0; q < n; ++q) {
      while (z[j + 1] < q) ++j;
      const float dq = static_cast<float>(q - v[j]);
      d[q] = dq * dq + f[v[j]];
    }
  }
  f.swap(d);
}

// Squared distance, in columns, from every column to the nearest column where `target` holds.
std::vector<float> SquaredDistanceTo(const std::vector<int>& room, int w, int h, bool inside) {
  std::vector<float> g(room.size());
  for (size_t i = 0; i < room.size(); ++i) g[i] = ((room[i] >= 0) == inside) ? 0.0f : kInf;
  std::vector<float> f, d, z;
  std::vector<int> v;
  for (int j = 0; j < h; ++j) {  // rows
    f.assign(g.begin() + static_cast<size_t>(j) * w, g.begin() + static_cast<size_t>(j + 1) * w);
    Edt1d(f, d, v, z);
    std::copy(f.begin(), f.end(), g.begin() + static_cast<size_t>(j) * w);
  }
  f.resize(h);
  for (int i = 0; i < w; ++i) {  // columns
    for (int j = 0; j < h; ++j) f[j] = g[static_cast<size_t>(j) * w + i];
    Edt1d(f, d, v, z);
    for (int j = 0; j < h; ++j) g[static_cast<size_t>(j) * w + i] = f[j];
  }
  return g;
}

}  // namespace

absl::StatusOr<PlanVolume> RasterizePlanVolume(std::span<const PlanLevelInput> levels,
                                               double res_m, double margin_m) {
  if (!(res_m > 0)) return absl::InvalidArgumentError("plan volume: resolution must be > 0");
  if (!(margin_m >= 0)) return absl::InvalidArgumentError("plan volume: margin must be ≥ 0");
  PlanVolume out;
  for (size_t k = 0; k < levels.size(); ++k) {
    const PlanLevelInput& in = levels[k];
    if (in.plan == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat("plan volume: level ", in.level, " has no plan"));
    }
    if (!(in.z_low < in.z_high)) {
      return absl::InvalidArgumentError(
          absl::StrCat("plan volume: level ", in.level, " has an empty z range"));
    }
    for (size_t m = 0; m < k; ++m) {
      if (in.z_low < levels[m].z_high && levels[m].z_low < in.z_high) {
        return absl::InvalidArgumentError(absl::StrCat("plan volume: levels ", levels[m].level,
                                                       " and ", in.level, " overlap in z"));
      }
    }
    const FloorPlan& plan = *in.plan;
    PlanLevelRaster r;
    r.level = in.level;
    r.z_low = in.z_low;
    r.z_high = in.z_high;
    r.res = res_m;
    for (const FloorPlanRoom& room : plan.rooms) {
      r.room_floor_z.push_back(room.floor_z);
      r.room_ceiling_z.push_back(room.ceiling_z);
    }
    if (!plan.triangles.empty()) {
      Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
      Eigen::Vector2d hi = -lo;
      for (const auto& t : plan.triangles) {
        for (uint32_t v : t) {
          if (v >= plan.vertices.size()) {
            return absl::InvalidArgumentError(absl::StrCat(
                "plan volume: level ", in.level, ": triangle vertex ", v, " out of range"));
          }
          lo = lo.cwiseMin(plan.vertices[v]);
          hi = hi.cwiseMax(plan.vertices[v]);
        }
      }
      // Aligned to the grid so columns coincide with finest octree cells.
      r.origin = ((lo.array() - margin_m) / res_m).floor() * res_m;
      const Eigen::Vector2d top = ((hi.array() + margin_m) / res_m).ceil() * res_m;
      r.width = std::max(1, static_cast<int>(std::lround((top.x() - r.origin.x()) / res_m)));
      r.height = std::max(1, static_cast<int>(std::lround((top.y() - r.origin.y()) / res_m)));
      const LabelImage img =
          RasterizeFloorPlan(plan, r.width, r.height, res_m, r.origin.x(), r.origin.y());
      const size_t n = static_cast<size_t>(r.width) * r.height;
      r.room.assign(n, -1);
      for (int row = 0; row < r.height; ++row) {
        const int j = r.height - 1 - row;  // image rows run top down, ours bottom up
        for (int i = 0; i < r.width; ++i) {
          const int room = img.labels[static_cast<size_t>(row) * r.width + i];
          if (room < 0 || room >= static_cast<int>(plan.rooms.size())) continue;
          const size_t c = static_cast<size_t>(j) * r.width + i;
          r.room[c] = room;
        }
      }
      const std::vector<float> to_outside = SquaredDistanceTo(r.room, r.width, r.height, false);
      const std::vector<float> to_inside = SquaredDistanceTo(r.room, r.width, r.height, true);
      r.signed_distance.resize(n);
      const float half = static_cast<float>(0.5 * res_m);
      for (size_t c = 0; c < n; ++c) {
        if (r.room[c] >= 0) {
          // No outside column in the raster (cannot happen with margin > 0): far inside.
          r.signed_distance[c] = to_outside[c] == kInf
                                     ? kInf
                                     : std::sqrt(to_outside[c]) * static_cast<float>(res_m) - half;
        } else {
          r.signed_distance[c] = to_inside[c] == kInf
                                     ? -kInf
                                     : -(std::sqrt(to_inside[c]) * static_cast<float>(res_m) - half);
        }
      }
    }
    out.levels.push_back(std::move(r));
  }
  return out;
}

namespace {

// The raster of the level whose z range holds x.z(), or null.
const PlanLevelRaster* LevelAt(const PlanVolume& volume, double z) {
  for (const PlanLevelRaster& r : volume.levels) {
    if (z >= r.z_low && z < r.z_high) return &r;
  }
  return nullptr;
}

// x's column (i, j) in `r`; may lie outside [0, width) × [0, height).
Eigen::Vector2i ColumnOf(const PlanLevelRaster& r, const Eigen::Vector3d& x) {
  return Eigen::Vector2i(static_cast<int>(std::floor((x.x() - r.origin.x()) / r.res)),
                         static_cast<int>(std::floor((x.y() - r.origin.y()) / r.res)));
}

}  // namespace

PlanColumn LookupPlan(const PlanVolume& volume, const Eigen::Vector3d& x) {
  PlanColumn col;
  const PlanLevelRaster* r = LevelAt(volume, x.z());
  if (r == nullptr) return col;
  col.level = r->level;
  const Eigen::Vector2i ij = ColumnOf(*r, x);
  if (ij.x() < 0 || ij.y() < 0 || ij.x() >= r->width || ij.y() >= r->height) return col;
  const size_t c = static_cast<size_t>(ij.y()) * r->width + ij.x();
  col.room = r->room[c];
  col.signed_distance_m = r->signed_distance[c];
  if (col.room >= 0) {
    col.floor_z = r->room_floor_z[col.room];
    col.ceiling_z = r->room_ceiling_z[col.room];
  }
  return col;
}

Eigen::Vector2d PlanAwayFromWalls(const PlanVolume& volume, const Eigen::Vector3d& x) {
  const PlanLevelRaster* r = LevelAt(volume, x.z());
  if (r == nullptr) return Eigen::Vector2d::Zero();
  const Eigen::Vector2i ij = ColumnOf(*r, x);
  const int i = ij.x(), j = ij.y();
  if (i < 1 || j < 1 || i + 1 >= r->width || j + 1 >= r->height) return Eigen::Vector2d::Zero();
  auto d = [r](int a, int b) { return r->signed_distance[static_cast<size_t>(b) * r->width + a]; };
  const Eigen::Vector2d g(d(i + 1, j) - d(i - 1, j), d(i, j + 1) - d(i, j - 1));
  if (!g.allFinite() || g.norm() < 1e-9) return Eigen::Vector2d::Zero();
  return g.normalized();
}

}  // namespace carvemap
