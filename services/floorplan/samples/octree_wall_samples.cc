#include "services/floorplan/samples/octree_wall_samples.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <map>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/convex_hull_2.h>

#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;

constexpr double kPi = 3.14159265358979323846;
// level_split's min_ceiling_height_m: a wall top lower than this above the floor is no ceiling.
constexpr double kMinCeilingHeightM = 1.8;

bool Finite(const Vector3d& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

uint64_t CellKey(int64_t i, int64_t j) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(i)) << 32) |
         static_cast<uint64_t>(static_cast<uint32_t>(j));
}

// A face whose exterior leaf was observed solid (LabelFromStats): a surface the scanners saw.
// The others close the carved volume against unobserved space (§4.3.2 counts unobserved as
// exterior): the edges of what the walk saw, through doorways and windows, are vertical too
// but are no walls.
bool SeenSurface(const BoundaryFace& f) {
  // The exterior leaf is not interior (p ≤ 0.5), so LabelFromStats reduces to its weight.
  return f.exterior_observed && f.exterior_weight >= kMinLabelWeightSum;
}

// The four corners of a face's square, moved onto its isosurface point (Fig 4.9).
std::array<Vector3d, 4> FaceCorners(const BoundaryFace& f) {
  const int a = (f.axis + 1) % 3, b = (f.axis + 2) % 3;
  const double h = f.size_m / 2;
  std::array<Vector3d, 4> c;
  for (int k = 0; k < 4; ++k) {
    c[k] = f.isosurface();
    c[k][a] += (k & 1) ? h : -h;
    c[k][b] += (k & 2) ? h : -h;
  }
  return c;
}

// The z interval of a convex polygon (in (u, z)) on the vertical line at u; false if it misses.
bool HullSpanAt(const std::vector<Vector2d>& hull, double u, double& z_lo, double& z_hi) {
  z_lo = std::numeric_limits<double>::infinity();
  z_hi = -z_lo;
  for (size_t k = 0; k < hull.size(); ++k) {
    const Vector2d& a = hull[k];
    const Vector2d& b = hull[(k + 1) % hull.size()];
    if (u < std::min(a.x(), b.x()) || u > std::max(a.x(), b.x())) continue;
    if (a.x() == b.x()) {
      z_lo = std::min({z_lo, a.y(), b.y()});
      z_hi = std::max({z_hi, a.y(), b.y()});
    } else {
      const double z = a.y() + (u - a.x()) / (b.x() - a.x()) * (b.y() - a.y());
      z_lo = std::min(z_lo, z);
      z_hi = std::max(z_hi, z);
    }
  }
  return z_lo <= z_hi;
}

// §5.3.3: the floors (normal up) and ceilings (normal down) among the large horizontal regions
// of the level, their faces binned on a coarse xy grid so the nearest one to a wall column is a
// ring search, not a scan of every face.
class HorizontalIndex {
 public:
  static constexpr double kCellM = 0.25;

  void Add(const BoundaryFace& f, double z, bool floor) {
    const int idx = static_cast<int>(entries_.size());
    entries_.push_back({Vector2d(f.center.x(), f.center.y()), f.size_m / 2, z, floor});
    const double h = f.size_m / 2;
    const int64_t i0 = Cell(f.center.x() - h), i1 = Cell(f.center.x() + h);
    const int64_t j0 = Cell(f.center.y() - h), j1 = Cell(f.center.y() + h);
    for (int64_t i = i0; i <= i1; ++i) {
      for (int64_t j = j0; j <= j1; ++j) cells_[CellKey(i, j)].push_back(idx);
    }
  }

  // The elevation of the horizontally nearest floor at or below `z_max` (floor = true) or
  // ceiling at or above `z_min` (floor = false), within max_m of q; false if none.
  bool Nearest(const Vector2d& q, bool floor, double z_min, double z_max, double max_m,
               double& z) const {
    const int64_t ci = Cell(q.x()), cj = Cell(q.y());
    const int64_t rings = static_cast<int64_t>(std::ceil(max_m / kCellM)) + 1;
    double best = std::numeric_limits<double>::infinity();
    for (int64_t r = 0; r <= rings; ++r) {
      // Every cell of ring r is at least (r − 1)·kCellM away from q.
      if (best <= (r - 1) * kCellM) break;
      for (int64_t i = ci - r; i <= ci + r; ++i) {
        for (int64_t j = cj - r; j <= cj + r; ++j) {
          if (std::max(std::abs(i - ci), std::abs(j - cj)) != r) continue;
          auto it = cells_.find(CellKey(i, j));
          if (it == cells_.end()) continue;
          for (int idx : it->second) {
            const Entry& e = entries_[idx];
            if (e.floor != floor || (floor ? e.z > z_max : e.z < z_min)) continue;
            const double dx = std::max(std::abs(q.x() - e.xy.x()) - e.half, 0.0);
            const double dy = std::max(std::abs(q.y() - e.xy.y()) - e.half, 0.0);
            const double d = std::hypot(dx, dy);
            if (d < best || (d == best && e.z < z)) {
              best = d;
              z = e.z;
            }
          }
        }
      }
    }
    return best <= max_m;
  }

 private:
  struct Entry {
    Vector2d xy;
    double half;
    double z;
    bool floor;
  };
  static int64_t Cell(double v) { return static_cast<int64_t>(std::floor(v / kCellM)); }
  std::vector<Entry> entries_;
  absl::flat_hash_map<uint64_t, std::vector<int>> cells_;
};

// One merged 2D sample under construction.
struct SampleAccumulator {
  Vector2d position_sum = Vector2d::Zero();
  Vector2d normal_sum = Vector2d::Zero();
  int count = 0;
  double z_bottom = std::numeric_limits<double>::infinity();
  double z_top = -std::numeric_limits<double>::infinity();
};

// The level's band of z and the grid its samples sit on.
struct LevelBand {
  const Level& level;
  double res = 0;  // the octree's leaf size
  double ds = 0;   // the samples' spacing
  [[nodiscard]] bool Contains(double z) const {
    return z >= level.split_z_low && z < level.split_z_high;
  }
};

// The 2D samples of a level as they are merged: one per (d_s cell, normal quadrant).
class SampleGrid {
 public:
  explicit SampleGrid(double ds) : ds_(ds) {}

  void Add(const Vector2d& p, const Vector2d& n, double z_bottom, double z_top) {
    // Walls seen from both sides give two samples a wall thickness apart: the normal's
    // quadrant is part of the key, so they never merge even when they share a cell.
    const int quadrant =
        static_cast<int>(std::floor((std::atan2(n.y(), n.x()) + kPi / 4) / (kPi / 2))) & 3;
    const int64_t i = static_cast<int64_t>(std::floor(p.x() / ds_));
    const int64_t j = static_cast<int64_t>(std::floor(p.y() / ds_));
    const uint64_t key = CellKey(i, j) * 4 + quadrant;
    auto [it, inserted] = index_.try_emplace(key, acc_.size());
    if (inserted) acc_.emplace_back();
    SampleAccumulator& a = acc_[it->second];
    a.position_sum += p;
    a.normal_sum += n;
    ++a.count;
    a.z_bottom = std::min(a.z_bottom, z_bottom);
    a.z_top = std::max(a.z_top, z_top);
  }

  [[nodiscard]] const std::vector<SampleAccumulator>& accumulators() const { return acc_; }

 private:
  double ds_;
  std::vector<SampleAccumulator> acc_;
  absl::flat_hash_map<uint64_t, size_t> index_;  // (xy cell, normal quadrant) → acc_
};

absl::Status CheckInputs(std::span<const BoundaryFace> faces, const PlanarRegionSet& regions,
                         const Level& level, std::span<const Eigen::Vector3d> path_positions,
                         const OctreeLabelFn& label_at, const OctreeWallSampleOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (!label_at) return absl::InvalidArgumentError("octree wall samples: label_at is empty");
  if (!std::isfinite(level.floor_z) || !std::isfinite(level.ceiling_z) ||
      level.floor_z >= level.ceiling_z || !std::isfinite(level.split_z_low) ||
      !std::isfinite(level.split_z_high) || level.split_z_low >= level.split_z_high) {
    return absl::InvalidArgumentError(
        absl::StrCat("octree wall samples: level ", level.index, " has floor_z ", level.floor_z,
                     ", ceiling_z ", level.ceiling_z, ", split [", level.split_z_low, ", ",
                     level.split_z_high, "): want finite, floor < ceiling, low < high"));
  }
  for (size_t i = 0; i < path_positions.size(); ++i) {
    if (!Finite(path_positions[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("octree wall samples: path position ", i, " is not finite"));
    }
  }
  for (const PlanarRegion& r : regions.regions) {
    for (uint32_t f : r.faces) {
      if (f >= faces.size()) {
        return absl::InvalidArgumentError(absl::StrCat("octree wall samples: region ", r.id,
                                                       " has face index ", f, " but there are ",
                                                       faces.size(), " faces"));
      }
    }
  }
  return absl::OkStatus();
}

// §5.3.3: the large horizontal regions of this level (the part of each on the level).
HorizontalIndex LevelHorizontals(std::span<const BoundaryFace> faces,
                                 const PlanarRegionSet& regions, const LevelBand& band,
                                 double cos_tilt, const OctreeWallSampleOptions& options,
                                 OctreeWallSampleReport& rep) {
  HorizontalIndex horizontal;
  for (const PlanarRegion& r : regions.regions) {
    if (std::abs(r.normal.z()) < cos_tilt) continue;
    double area = 0, wz = 0;
    for (uint32_t fi : r.faces) {
      const BoundaryFace& f = faces[fi];
      if (!band.Contains(f.isosurface().z()) || !SeenSurface(f)) continue;
      area += f.area_m2();
      wz += f.area_m2() * f.isosurface().z();
    }
    if (area <= 0 || area < options.min_horizontal_area_m2) continue;
    ++rep.horizontal_regions;
    const double z = wz / area;  // the plane's elevation over the faces on this level
    for (uint32_t fi : r.faces) {
      if (band.Contains(faces[fi].isosurface().z()) && SeenSurface(faces[fi])) {
        horizontal.Add(faces[fi], z, r.normal.z() > 0);
      }
    }
  }
  return horizontal;
}

struct VerticalPlane {
  Vector2d normal;  // unit, horizontal, into free space
  double offset;    // normal · x on the plane
};

// The wall region's plane made vertical and fitted to the isosurface points of its faces
// `mine` on this level (area `area`), from the region's horizontal normal `n_xy`.
VerticalPlane FitVerticalPlane(std::span<const BoundaryFace> faces,
                               const std::vector<uint32_t>& mine, double area, const Vector2d& n_xy,
                               double res) {
  // §5.3.1 assumes walls are vertical: the plane is made exactly vertical, fitted again (2D
  // PCA, area-weighted) to the isosurface points of the faces kept on this level. The
  // region's own normal comes from all its faces, and relaxation (§4.2.4) chains pieces up
  // to 15° apart: along a 30 m corridor a 3° error moves the wall's end by 1.5 m.
  Vector2d mean = Vector2d::Zero();
  for (uint32_t fi : mine) mean += faces[fi].area_m2() * faces[fi].isosurface().head<2>();
  mean /= area;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (uint32_t fi : mine) {
    const Vector2d d = faces[fi].isosurface().head<2>() - mean;
    cov += faces[fi].area_m2() * d * d.transpose();
  }
  Vector2d nh = n_xy.normalized();
  double offset = nh.dot(mean);
  // Two rounds of trimming: faces further than 2 leaves from the line (a door leaf, a
  // cabinet front chained in by relaxation) do not tilt it.
  for (int round = 0; round < 3; ++round) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    Vector2d n = eig.eigenvectors().col(0).normalized();  // smallest spread: the normal
    if (n.dot(n_xy) < 0) n = -n;                          // into free space, as the faces
    // A narrow region (a door jamb, a pillar's side) has no direction of its own in xy, and
    // a fit more than 20° off the region's normal is not this wall: keep the region's.
    const bool elongated = eig.eigenvalues()(1) > 4 * eig.eigenvalues()(0) + 1e-12;
    nh = elongated && n.dot(n_xy.normalized()) > std::cos(20 * kPi / 180) ? n : n_xy.normalized();
    offset = nh.dot(mean);
    if (round == 2) break;
    Vector2d m = Vector2d::Zero();
    double w = 0;
    for (uint32_t fi : mine) {
      const Vector2d p = faces[fi].isosurface().head<2>();
      if (std::abs(nh.dot(p) - offset) > 2 * res) continue;
      m += faces[fi].area_m2() * p;
      w += faces[fi].area_m2();
    }
    if (w < area / 2) break;  // no dominant line: keep the plain fit
    m /= w;
    Eigen::Matrix2d c = Eigen::Matrix2d::Zero();
    for (uint32_t fi : mine) {
      const Vector2d p = faces[fi].isosurface().head<2>();
      if (std::abs(nh.dot(p) - offset) > 2 * res) continue;
      c += faces[fi].area_m2() * (p - m) * (p - m).transpose();
    }
    mean = m;
    cov = c;
  }
  return {nh, offset};
}

// §5.3.1: fill the wall where something hid it, at `p` on a wall plane of normal `nh`. Half a
// leaf behind the plane is inside the wall: exterior there means solid wall (fill); interior
// means space was carved through the plane — a doorway or window (no fill). Unobserved behind
// (furniture hid the wall from every ray, or an opening nobody looked through, or a part of the
// level the walk barely saw) fills only when something solid stands in front: walking out from
// the plane through unobserved space (the furniture's inside, its shadow), the first observed
// point is exterior (the furniture's front) within max_occluder_depth_m. In a doorway it is the
// room's carved free space; in a barely seen area there is nothing.
absl::StatusOr<bool> FilledBehindOcclusion(const OctreeLabelFn& label_at, const Vector3d& p,
                                           const Vector2d& nh, double res,
                                           const OctreeWallSampleOptions& options) {
  const Vector3d n3(nh.x(), nh.y(), 0);
  absl::StatusOr<OctreeLabel> behind = label_at(p - res / 2 * n3);
  if (!behind.ok()) return behind.status();
  if (*behind == OctreeLabel::kExterior) return true;
  if (*behind != OctreeLabel::kUnobserved) return false;
  for (double d = res / 2; d <= options.max_occluder_depth_m; d += res / 2) {
    absl::StatusOr<OctreeLabel> ahead = label_at(p + d * n3);
    if (!ahead.ok()) return ahead.status();
    if (*ahead == OctreeLabel::kUnobserved) continue;
    return *ahead == OctreeLabel::kExterior;
  }
  return false;
}

// A column of d_s cells on a wall plane with something kept in it.
struct WallColumn {
  int64_t i;  // along the wall
  Vector2d xy;
  double z_lo, z_hi;  // the wall's hull there
  bool lintel;        // kept only above lintel_fraction of the hull: a doorway's head
};

// The columns (ascending i) into `samples`, but for runs of lintel columns at least
// min_opening_m wide: openings. A narrower run is no doorway but a wall whose lower part the
// region and the fill missed (noisy leaves at the wall): kept.
void AddColumnsBesideOpenings(const std::vector<WallColumn>& columns, const Vector2d& nh, double ds,
                              const OctreeWallSampleOptions& options, SampleGrid& samples,
                              OctreeWallSampleReport& rep) {
  for (size_t a = 0; a < columns.size();) {
    size_t b = a + 1;
    if (columns[a].lintel) {
      while (b < columns.size() && columns[b].lintel && columns[b].i == columns[b - 1].i + 1) ++b;
    }
    const bool opening =
        columns[a].lintel && static_cast<double>(b - a) * ds >= options.min_opening_m;
    for (size_t k = a; k < b; ++k) {
      if (opening) {
        ++rep.lintel_columns;
      } else {
        samples.Add(columns[k].xy, nh, columns[k].z_lo, columns[k].z_hi);
      }
    }
    a = b;
  }
}

// §5.3.1 for one wall region: its vertical plane, its columns of d_s cells, each kept where
// its faces cover it or something hid the wall there, and the kept columns into `samples`,
// except runs of them that are an opening (a doorway under its lintel).
absl::Status SampleWallRegion(std::span<const BoundaryFace> faces, const PlanarRegion& r,
                              const LevelBand& band, const OctreeLabelFn& label_at,
                              const OctreeWallSampleOptions& options, SampleGrid& samples,
                              OctreeWallSampleReport& rep) {
  const double res = band.res, ds = band.ds;
  double area = 0, z_min = std::numeric_limits<double>::infinity(), z_max = -z_min;
  std::vector<uint32_t> mine;
  for (uint32_t fi : r.faces) {
    const BoundaryFace& f = faces[fi];
    if (!band.Contains(f.isosurface().z()) || !SeenSurface(f)) continue;
    mine.push_back(fi);
    area += f.area_m2();
    for (const Vector3d& c : FaceCorners(f)) {
      z_min = std::min(z_min, c.z());
      z_max = std::max(z_max, c.z());
    }
  }
  if (mine.empty() || area < options.min_area_m2 || z_max - z_min < options.min_height_m) {
    return absl::OkStatus();
  }
  const Vector2d n_xy(r.normal.x(), r.normal.y());
  if (n_xy.norm() < 1e-9) return absl::OkStatus();
  ++rep.wall_regions;
  const VerticalPlane plane = FitVerticalPlane(faces, mine, area, n_xy, res);
  const Vector2d nh = plane.normal;
  const double offset = plane.offset;
  const Vector2d t(-nh.y(), nh.x());

  // The faces in wall coordinates (u along the wall, z): their hull, and the d_s cells they
  // cover ("on the region").
  std::vector<Kernel::Point_2> corners;
  corners.reserve(mine.size() * 4);
  absl::flat_hash_set<uint64_t> on_region;
  std::map<int64_t, std::pair<double, double>> column_offset;  // Σ area·offset, Σ area
  for (uint32_t fi : mine) {
    double u_lo = std::numeric_limits<double>::infinity(), u_hi = -u_lo;
    double f_lo = u_lo, f_hi = -u_lo;
    for (const Vector3d& c : FaceCorners(faces[fi])) {
      const double u = t.dot(c.head<2>());
      corners.emplace_back(u, c.z());
      u_lo = std::min(u_lo, u);
      u_hi = std::max(u_hi, u);
      f_lo = std::min(f_lo, c.z());
      f_hi = std::max(f_hi, c.z());
    }
    // Grid points sit at cell centres (k + ½)·d_s; a face covers those inside its square
    // (and at least the nearest one, so faces smaller than d_s still count).
    auto range = [&](double lo, double hi, int64_t& a, int64_t& b) {
      a = static_cast<int64_t>(std::ceil(lo / ds - 0.5 - 1e-9));
      b = static_cast<int64_t>(std::floor(hi / ds - 0.5 + 1e-9));
      if (b < a) a = b = static_cast<int64_t>(std::floor((lo + hi) / 2 / ds));
    };
    int64_t i0, i1, j0, j1;
    range(u_lo, u_hi, i0, i1);
    range(f_lo, f_hi, j0, j1);
    const double a = faces[fi].area_m2();
    const double o = nh.dot(faces[fi].isosurface().head<2>());
    for (int64_t i = i0; i <= i1; ++i) {
      for (int64_t j = j0; j <= j1; ++j) on_region.insert(CellKey(i, j));
      auto& [sum, weight] = column_offset[i];
      sum += a * o;
      weight += a;
    }
  }
  // Samples sit on the fitted line, which averages the faces' noise (measured on the room
  // preset: median 0.8 cm off the true wall on the line, 1.0 cm at each column's own mean).
  // Where a column's own faces are more than 2 leaves off it, the region bends (relaxation
  // chains pieces up to 15° apart; the curved wall of a round room) and the sample follows
  // them instead. Columns without faces (all filled) interpolate between their nearest
  // neighbours with faces.
  auto local_offset_at = [&](int64_t i) {
    if (auto it = column_offset.find(i); it != column_offset.end()) {
      return it->second.first / it->second.second;
    }
    auto right = column_offset.lower_bound(i);
    if (right == column_offset.end()) {
      return column_offset.empty()
                 ? offset
                 : std::prev(right)->second.first / std::prev(right)->second.second;
    }
    const double o_right = right->second.first / right->second.second;
    if (right == column_offset.begin()) return o_right;
    auto left = std::prev(right);
    const double o_left = left->second.first / left->second.second;
    const double f = double(i - left->first) / double(right->first - left->first);
    return o_left + f * (o_right - o_left);
  };
  auto offset_at = [&](int64_t i) {
    const double local = local_offset_at(i);
    return std::abs(local - offset) > 2 * res ? local : offset;
  };
  std::vector<Kernel::Point_2> hull_k;
  CGAL::convex_hull_2(corners.begin(), corners.end(), std::back_inserter(hull_k));
  std::vector<Vector2d> hull;
  hull.reserve(hull_k.size());
  for (const Kernel::Point_2& p : hull_k) hull.emplace_back(p.x(), p.y());
  double hu_lo = std::numeric_limits<double>::infinity(), hu_hi = -hu_lo;
  for (const Vector2d& p : hull) {
    hu_lo = std::min(hu_lo, p.x());
    hu_hi = std::max(hu_hi, p.x());
  }

  std::vector<WallColumn> columns;  // ascending i
  const int64_t i_first = static_cast<int64_t>(std::ceil(hu_lo / ds - 0.5));
  const int64_t i_last = static_cast<int64_t>(std::floor(hu_hi / ds - 0.5));
  for (int64_t i = i_first; i <= i_last; ++i) {
    const double u = (i + 0.5) * ds;
    double z_lo, z_hi;
    if (!HullSpanAt(hull, u, z_lo, z_hi)) continue;
    const Vector2d xy = offset_at(i) * nh + u * t;
    double lowest_kept = std::numeric_limits<double>::infinity();
    const int64_t j_first = static_cast<int64_t>(std::ceil(z_lo / ds - 0.5));
    const int64_t j_last = static_cast<int64_t>(std::floor(z_hi / ds - 0.5));
    for (int64_t j = j_first; j <= j_last; ++j) {
      const double z = (j + 0.5) * ds;
      if (!band.Contains(z)) continue;
      ++rep.grid_points;
      bool keep = false;
      if (on_region.contains(CellKey(i, j))) {
        keep = true;
        ++rep.on_region;
      } else {
        absl::StatusOr<bool> filled =
            FilledBehindOcclusion(label_at, Vector3d(xy.x(), xy.y(), z), nh, res, options);
        if (!filled.ok()) return filled.status();
        keep = *filled;
        if (keep) ++rep.filled_behind_occlusion;
      }
      if (keep) lowest_kept = std::min(lowest_kept, z);
    }
    if (!std::isfinite(lowest_kept)) continue;
    ++rep.columns;
    const bool lintel = lowest_kept > z_lo + options.lintel_fraction * (z_hi - z_lo);
    columns.push_back({i, xy, z_lo, z_hi, lintel});
  }
  AddColumnsBesideOpenings(columns, nh, ds, options, samples, rep);
  return absl::OkStatus();
}

// Each merged sample with the heights of §5.3.3: the nearest floor below and ceiling above.
std::vector<WallSample> SamplesWithHeights(const SampleGrid& samples,
                                           const HorizontalIndex& horizontal, const LevelBand& band,
                                           const OctreeWallSampleOptions& options,
                                           OctreeWallSampleReport& rep) {
  const double res = band.res;
  std::vector<WallSample> out;
  out.reserve(samples.accumulators().size());
  for (const SampleAccumulator& a : samples.accumulators()) {
    WallSample s;
    s.position = a.position_sum / a.count;
    s.normal = a.normal_sum.norm() > 1e-12 ? a.normal_sum.normalized() : Vector2d::UnitX();
    // §5.3.3: the heights of the nearest floor below and ceiling above, searched from just
    // inside the room (the room's own floor reaches its walls; the neighbour's is a wall
    // thickness further).
    const Vector2d q = s.position + res * s.normal;
    // A wall's hull ends within a leaf of its floor and ceiling; 0.3 m also tolerates the
    // hull's chord over a lower ceiling at one end of a wall, and still keeps table tops
    // (≈ 0.75 m above the floor) from passing for floors.
    const double tol = std::max(2 * res, 0.3);
    if (!horizontal.Nearest(q, true, 0, a.z_bottom + tol, options.max_height_search_m, s.floor_z)) {
      s.floor_z = band.level.floor_z;
      ++rep.floor_fallbacks;
    }
    if (!horizontal.Nearest(q, false, a.z_top - tol, 0, options.max_height_search_m, s.ceiling_z)) {
      // No ceiling seen near: the wall's own top (§3.1's vertical extent, noisier than
      // §5.3.3 but this room's), unless it stops too low to be one (an unseen upper wall);
      // then the level's.
      s.ceiling_z =
          a.z_top >= s.floor_z + kMinCeilingHeightM && a.z_top <= band.level.ceiling_z + tol
              ? a.z_top
              : band.level.ceiling_z;
      ++rep.ceiling_fallbacks;
    }
    if (s.floor_z >= s.ceiling_z) {
      // Inconsistent pair (e.g. a ceiling found under a high floor piece): the level's own.
      s.floor_z = band.level.floor_z;
      s.ceiling_z = band.level.ceiling_z;
    }
    out.push_back(std::move(s));
  }
  return out;
}

// Poses (§3.1, §3.3.1): the path on this level, subsampled, broken where it left the level,
// into `set`; returns the heights of the path on the level.
std::vector<double> LevelPoses(std::span<const Eigen::Vector3d> path_positions,
                               const LevelBand& band, const OctreeWallSampleOptions& options,
                               WallSampleSet& set) {
  std::vector<double> level_z;
  bool off_level = false;
  Vector2d last = Vector2d::Zero();
  for (const Vector3d& p : path_positions) {
    if (!band.Contains(p.z())) {
      off_level = true;
      continue;
    }
    level_z.push_back(p.z());
    const Vector2d xy = p.head<2>();
    if (set.poses.empty() || off_level) {
      if (!set.poses.empty()) set.path_breaks.push_back(static_cast<uint32_t>(set.poses.size()));
      set.poses.push_back(xy);
      last = xy;
      off_level = false;
    } else if ((xy - last).norm() >= options.visibility.min_pose_spacing_m) {
      set.poses.push_back(xy);
      last = xy;
    }
  }
  return level_z;
}

// The visibility slice's height, a 2D scanner's view of the octree (§3.1.2): the median of the
// path on this level, kept off the floor and ceiling.
double ScannerHeight(std::vector<double> level_z, const Level& level) {
  double scanner_z = level.floor_z + 1.5;
  if (!level_z.empty()) {
    std::nth_element(level_z.begin(), level_z.begin() + level_z.size() / 2, level_z.end());
    scanner_z = level_z[level_z.size() / 2];
  }
  const double lo = level.floor_z + 0.3, hi = level.ceiling_z - 0.1;
  scanner_z = lo <= hi ? std::clamp(scanner_z, lo, hi) : (level.floor_z + level.ceiling_z) / 2;
  return scanner_z;
}

// Which poses see which samples, through the octree's slice at `scanner_z` (§3.1.2).
absl::Status AssignVisibility(const OctreeLabelFn& label_at, const LevelBand& band,
                              double scanner_z, const OctreeWallSampleOptions& options,
                              WallSampleSet& set) {
  const double ds = band.ds;
  Eigen::AlignedBox2d box;
  for (const WallSample& s : set.samples) box.extend(s.position);
  for (const Vector2d& p : set.poses) box.extend(p);
  constexpr double kMarginM = 1.0;
  OccupancyGrid2D occ;
  occ.resolution_m = ds;
  occ.origin_x_m = std::floor((box.min().x() - kMarginM) / ds) * ds;
  occ.origin_y_m = std::floor((box.min().y() - kMarginM) / ds) * ds;
  const double w = std::ceil((box.max().x() + kMarginM - occ.origin_x_m) / ds);
  const double h = std::ceil((box.max().y() + kMarginM - occ.origin_y_m) / ds);
  if (w * h > 1e8) {
    return absl::InvalidArgumentError(absl::StrCat("octree wall samples: level ", band.level.index,
                                                   " visibility grid of ", w, " x ", h,
                                                   " cells at ", ds, " m is too large"));
  }
  occ.width = static_cast<int>(w);
  occ.height = static_cast<int>(h);
  occ.cells.assign(static_cast<size_t>(occ.width) * occ.height, 0);
  for (int iy = 0; iy < occ.height; ++iy) {
    for (int ix = 0; ix < occ.width; ++ix) {
      const Vector3d c(occ.origin_x_m + (ix + 0.5) * ds, occ.origin_y_m + (iy + 0.5) * ds,
                       scanner_z);
      absl::StatusOr<OctreeLabel> l = label_at(c);
      if (!l.ok()) return l.status();
      if (*l == OctreeLabel::kExterior) occ.cells[static_cast<size_t>(iy) * occ.width + ix] = 1;
    }
  }
  // The samples' own cells stop rays too: a wall hidden by furniture at scanner height is
  // still a wall.
  for (const WallSample& s : set.samples) {
    const int ix = static_cast<int>(std::floor((s.position.x() - occ.origin_x_m) / ds));
    const int iy = static_cast<int>(std::floor((s.position.y() - occ.origin_y_m) / ds));
    if (ix >= 0 && iy >= 0 && ix < occ.width && iy < occ.height) {
      occ.cells[static_cast<size_t>(iy) * occ.width + ix] = 1;
    }
  }
  return AssignVisiblePoses(occ, options.visibility, set);
}

}  // namespace

absl::Status OctreeWallSampleOptions::Validate() const {
  auto bad = [](const char* field, double v) {
    return absl::InvalidArgumentError(
        absl::StrCat("octree wall samples: ", field, " out of range: ", v));
  };
  if (!std::isfinite(max_tilt_deg) || max_tilt_deg < 0 || max_tilt_deg >= 90) {
    return bad("max_tilt_deg (want [0, 90))", max_tilt_deg);
  }
  if (!std::isfinite(min_area_m2) || min_area_m2 < 0) return bad("min_area_m2", min_area_m2);
  if (!std::isfinite(min_height_m) || min_height_m < 0) return bad("min_height_m", min_height_m);
  if (!std::isfinite(spacing_m) || spacing_m < 0) return bad("spacing_m", spacing_m);
  if (!std::isfinite(min_horizontal_area_m2) || min_horizontal_area_m2 < 0) {
    return bad("min_horizontal_area_m2", min_horizontal_area_m2);
  }
  if (!std::isfinite(lintel_fraction) || lintel_fraction < 0 || lintel_fraction > 1) {
    return bad("lintel_fraction (want [0, 1])", lintel_fraction);
  }
  if (!std::isfinite(min_opening_m) || min_opening_m < 0) {
    return bad("min_opening_m", min_opening_m);
  }
  if (!std::isfinite(max_occluder_depth_m) || max_occluder_depth_m < 0) {
    return bad("max_occluder_depth_m", max_occluder_depth_m);
  }
  if (!std::isfinite(max_height_search_m) || max_height_search_m < 0) {
    return bad("max_height_search_m", max_height_search_m);
  }
  if (absl::Status s = visibility.Validate(); !s.ok()) {
    return absl::Status(s.code(), absl::StrCat("octree wall samples: visibility: ", s.message()));
  }
  return absl::OkStatus();
}

absl::StatusOr<WallSampleSet> OctreeWallSamples(std::span<const BoundaryFace> faces,
                                                const PlanarRegionSet& regions,
                                                const OctreeGrid& grid, const Level& level,
                                                std::span<const Eigen::Vector3d> path_positions,
                                                const OctreeLabelFn& label_at,
                                                const OctreeWallSampleOptions& options,
                                                OctreeWallSampleReport* report) {
  if (absl::Status s = CheckInputs(faces, regions, level, path_positions, label_at, options);
      !s.ok()) {
    return s;
  }
  OctreeWallSampleReport rep;
  const double res = grid.resolution_m();
  const LevelBand band{level, res, options.spacing_m > 0 ? options.spacing_m : res};
  const double sin_tilt = std::sin(options.max_tilt_deg * kPi / 180);
  const double cos_tilt = std::cos(options.max_tilt_deg * kPi / 180);

  const HorizontalIndex horizontal = LevelHorizontals(faces, regions, band, cos_tilt, options, rep);
  // §5.3.1: the wall regions, sampled.
  SampleGrid samples(band.ds);
  for (const PlanarRegion& r : regions.regions) {
    if (std::abs(r.normal.z()) > sin_tilt) continue;
    if (absl::Status s = SampleWallRegion(faces, r, band, label_at, options, samples, rep);
        !s.ok()) {
      return s;
    }
  }
  WallSampleSet set;
  set.spacing_m = band.ds;
  set.samples = SamplesWithHeights(samples, horizontal, band, options, rep);
  rep.samples = set.samples.size();
  std::vector<double> level_z = LevelPoses(path_positions, band, options, set);
  rep.poses = set.poses.size();
  rep.scanner_z = ScannerHeight(std::move(level_z), level);
  if (!set.samples.empty() && !set.poses.empty()) {
    if (absl::Status s = AssignVisibility(label_at, band, rep.scanner_z, options, set); !s.ok()) {
      return s;
    }
  }
  for (const WallSample& s : set.samples) rep.samples_with_poses += !s.poses.empty();

  if (absl::Status s = set.Validate(); !s.ok()) {
    return absl::InternalError(absl::StrCat("octree wall samples: ", s.message()));
  }
  if (report != nullptr) *report = rep;
  return set;
}

}  // namespace carvemap
