#include "geometry/wedge_geometry.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>

#include "absl/strings/str_cat.h"
#include "geometry/carve_map.h"

namespace carvemap {
namespace {

using Eigen::Vector3d;
using Eigen::Vector4d;

// A flat wedge (e.g. two identical frames while the operator stands still) or a collinear one
// has zero volume; it is given this half-thickness. Not more: §4.3.1's wedge is the hull itself,
// without lateral dilation, and thicker flat wedges would be discontinuous with nearly flat ones
// (which the hull handles exactly). Not less: float32 world coordinates (~1 mm steps at 10 km)
// only place the plane to about a millimetre, and a zero-thickness slab would make "touches the
// box" hinge on rounding. 1 mm is well below the finest leaf (7.8 mm).
constexpr double kMinHalfThicknessM = 1e-3;
// A single-ray wedge (§4.3.1 defines wedges between neighbouring rays; a lone ray is ours) has
// no neighbours to bound it across the ray, so it is widened by 1σ of its lateral spread, not
// 3σ. Its eq 4.7 value beside the ray is 0.5 + f_⊥·(F_s(1 − F_p) − 0.5): above 0.5 wherever
// the leaf lies before the point, whatever is between them. 3σ let the long grazing rays that
// fail the discontinuity test (a horizontal scanner's rays meeting the ceiling 20–30 m away,
// σ_⊥ 8–23 cm there) mark as interior, with nothing to contradict them, a layer 0.25–0.9 m
// above the ceiling, through a 0.2 m roof: the spurious level at 2.85–2.93 m on the simulated
// floor maps (docs/BENCHMARKS.md). Along the ray it ends where every wedge does: at the sensor
// mean and `sigmas`·σ_∥ past the point (behind the sensor eq 4.7 says exterior, F_s ≈ 0).
constexpr double kSingleRayLateralSigmas = 1.0;
// Every plane offset and the bounding box are widened by this, so that rounding in the dot
// products of HullIntersectsBox can never turn a touching box into a separated one.
constexpr double kSlackM = 1e-7;
// A triple of points whose cross product is below this (relative to the squared extent) has no
// reliable normal; the brute-force hull skips it (a skipped facet only enlarges the hull).
constexpr double kMinRelativeCross = 1e-10;

struct PointSet {
  std::array<Vector3d, 16> p;  // relative to `origin`, for precision far from the world origin
  int n = 0;
  Vector3d origin = Vector3d::Zero();
  void Add(const Vector3d& x) { p[n++] = x - origin; }
};

Vector3d RayDirection(const RayModel& ray) {
  const Vector3d d = (ray.point_mean - ray.sensor_mean).cast<double>();
  const double len = d.norm();
  return len > 1e-9 ? Vector3d(d / len) : Vector3d::Zero();
}

// σ of the point's range along the ray; for a zero-length ray, the largest σ.
double SigmaAlong(const RayModel& ray, const Vector3d& d) {
  const Eigen::Matrix3d c = ToMatrix(ray.point_cov);
  if (d.isZero()) {
    return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(
                                       c, Eigen::EigenvaluesOnly)
                                       .eigenvalues()
                                       .maxCoeff()));
  }
  // F_p's σ (the range given the lateral offset, carve_map.h): past 3 of those the ray says
  // nothing more, whatever its spread along a surface it meets obliquely.
  return PointRangeGivenLateral(c, d).sigma;
}

// Principal axes across the ray (unit, ⊥ d) of the point Gaussian's lateral spread P C_p P,
// P = I − ddᵀ, and along each the larger σ of the point and the sensor Gaussians. A box with
// these half-widths contains both 1σ ellipses across the ray (an ellipse's support along a unit
// e is sqrt(eᵀ C e)), while a round tube of the largest σ would reach as far in every direction.
struct LateralSpread {
  Vector3d axis[2];
  double sigma[2];
};
LateralSpread LateralSigmas(const RayModel& ray, const Vector3d& d) {
  const Eigen::Matrix3d cp = ToMatrix(ray.point_cov);
  const Eigen::Matrix3d cs = ToMatrix(ray.sensor_cov);
  // P C_p P restricted to the plane ⊥ d is the 2×2 [[a, b], [b, c]] in any orthonormal pair of
  // that plane; its larger eigenvector is at angle ½·atan2(2b, a − c) from the pair's first.
  // Closed form rather than a 3×3 eigensolver: this runs for every single-ray hull, in the
  // binning and again in each chunk it reaches. The box holds the ellipses along any pair of
  // axes (the half-widths below are the supports along them), so rounding in the angle only
  // changes how tight it is. An isotropic (or zero) spread gives angle 0: the pair itself.
  const Vector3d e1 = d.unitOrthogonal();
  const Vector3d e2 = d.cross(e1);
  const Vector3d c1 = cp * e1;
  const double a = e1.dot(c1), b = e2.dot(c1), c = e2.dot(cp * e2);
  const double angle = 0.5 * std::atan2(2 * b, a - c);
  LateralSpread out;
  out.axis[0] = (std::cos(angle) * e1 + std::sin(angle) * e2).normalized();
  out.axis[1] = d.cross(out.axis[0]);
  for (int i = 0; i < 2; ++i) {
    const Vector3d& e = out.axis[i];
    out.sigma[i] = std::sqrt(std::max({0.0, e.dot(cp * e), e.dot(cs * e)}));
  }
  return out;
}

// Adds the plane n·x <= max over the points, if n is new. Offsets are the exact support of the
// points, so every plane added contains all of them: the result is always conservative.
void AddSupportPlane(const PointSet& s, const Vector3d& n, double extra, WedgeHull& hull) {
  double support = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < s.n; ++i) support = std::max(support, n.dot(s.p[i]));
  for (const Vector4d& q : hull.planes) {
    if (q.head<3>().dot(n) > 1 - 1e-12) return;  // duplicate (the coplanar faces of a quad)
  }
  hull.planes.emplace_back(n.x(), n.y(), n.z(), support + extra + n.dot(s.origin) + kSlackM);
}

// Adds the plane n·x <= support (n unit, support over the points relative to s.origin), if n
// is new.
void AddPlane(const PointSet& s, const Vector3d& n, double support, WedgeHull& hull) {
  for (const Vector4d& q : hull.planes) {
    if (q.head<3>().dot(n) > 1 - 1e-12) return;  // duplicate (the coplanar faces of a quad)
  }
  hull.planes.emplace_back(n.x(), n.y(), n.z(), support + n.dot(s.origin) + kSlackM);
}

void SetBox(const PointSet& s, const Vector3d& widen, WedgeHull& hull) {
  Eigen::AlignedBox3d box;
  for (int i = 0; i < s.n; ++i) box.extend(s.p[i]);
  const Vector3d w = widen + Vector3d::Constant(kSlackM);
  hull.box = Eigen::AlignedBox3d(box.min() + s.origin - w, box.max() + s.origin + w);
}

// Oriented box along the orthonormal axes, dilated by half_widths along each axis.
void OrientedBoxHull(const PointSet& s, const Eigen::Matrix3d& axes, const Vector3d& half_widths,
                     WedgeHull& hull) {
  Vector3d widen = Vector3d::Zero();
  for (int a = 0; a < 3; ++a) {
    const Vector3d e = axes.col(a);
    AddSupportPlane(s, e, half_widths[a], hull);
    AddSupportPlane(s, -e, half_widths[a], hull);
    widen += half_widths[a] * e.cwiseAbs();
  }
  SetBox(s, widen, hull);
}

// Convex hull of points spanning 3D: a plane through every non-degenerate triple that has all
// points on one side is a facet plane (n ≤ 8, so ≤ 56 triples; simpler and sturdier than an
// incremental hull for this size). `thinnest` receives the smallest width of the points along
// a facet normal (about the hull's thickness). Triples are numbered in (i, j, k) order; the
// facets' bits are added to *found. With a nonzero `only`, just those triples are tried (a
// replay of an earlier search on the same points: the same planes, bit for bit); false if one
// of them is not a facet.
bool BruteForceHull(const PointSet& s, double extent, WedgeHull& hull, double& thinnest,
                    uint64_t* found, uint64_t only) {
  const double tol = 1e-9 * extent;
  const double min_cross = kMinRelativeCross * extent * extent;
  int t = -1;
  for (int i = 0; i < s.n; ++i) {
    for (int j = i + 1; j < s.n; ++j) {
      const Vector3d eij = s.p[j] - s.p[i];
      for (int k = j + 1; k < s.n; ++k) {
        ++t;
        if (only != 0 && !(only >> t & 1)) continue;
        Vector3d n = eij.cross(s.p[k] - s.p[i]);
        const double len2 = n.squaredNorm();
        if (len2 <= min_cross * min_cross) {
          if (only != 0) return false;
          continue;
        }
        // Sides first with the unnormalized normal (distances scaled by |n|): most triples
        // are not facets, and they need no square root. A replay's triples were facets of
        // these very points: the pass below checks them on its own.
        if (only == 0) {
          const double o = n.dot(s.p[i]), tol2 = tol * tol * len2;
          bool above = false, below = false;
          for (int m = 0; m < s.n && !(above && below); ++m) {
            const double dist = n.dot(s.p[m]) - o;
            above |= dist > 0 && dist * dist > tol2;
            below |= dist < 0 && dist * dist > tol2;
          }
          if (above && below) {  // a plane through the hull, not a facet
            if (only != 0) return false;
            continue;
          }
        }
        n /= std::sqrt(len2);
        const double o = n.dot(s.p[i]);
        double lo = 0, hi = 0;
        for (int m = 0; m < s.n; ++m) {
          const double dist = n.dot(s.p[m]) - o;
          lo = std::min(lo, dist);
          hi = std::max(hi, dist);
        }
        const bool below = lo < -tol;
        if (only != 0 && below && hi > tol) return false;  // a plane through the hull
        thinnest = std::min(thinnest, hi - lo);
        if (found != nullptr) *found |= uint64_t{1} << t;
        // Outward: away from the points. The offset is the points' exact support.
        if (below) {
          AddPlane(s, n, o + hi, hull);
        } else {
          AddPlane(s, -n, -(o + lo), hull);
        }
      }
    }
  }
  SetBox(s, Vector3d::Zero(), hull);
  return true;
}

// A flat point set (normal e3): the prism over its 2D hull in the (e1, e2) plane, half-thickness
// t along e3.
void PrismHull(const PointSet& s, const Eigen::Matrix3d& axes, double t, WedgeHull& hull) {
  const Vector3d e1 = axes.col(0), e2 = axes.col(1), e3 = axes.col(2);
  std::array<Eigen::Vector2d, 16> q;
  for (int i = 0; i < s.n; ++i) q[i] = Eigen::Vector2d(e1.dot(s.p[i]), e2.dot(s.p[i]));
  std::sort(q.begin(), q.begin() + s.n, [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  // Andrew's monotone chain; collinear points are dropped.
  std::array<Eigen::Vector2d, 34> h;
  int m = 0;
  auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
  };
  for (int i = 0; i < s.n; ++i) {
    while (m >= 2 && cross(h[m - 2], h[m - 1], q[i]) <= 0) --m;
    h[m++] = q[i];
  }
  for (int i = s.n - 2, lower = m + 1; i >= 0; --i) {
    while (m >= lower && cross(h[m - 2], h[m - 1], q[i]) <= 0) --m;
    h[m++] = q[i];
  }
  // Counter-clockwise: the outward normal of edge a→b is (dy, −dx).
  for (int i = 0; i + 1 < m; ++i) {
    const Eigen::Vector2d d = h[i + 1] - h[i];
    const double len = d.norm();
    if (len <= 0) continue;
    AddSupportPlane(s, (d.y() * e1 - d.x() * e2) / len, 0.0, hull);
  }
  AddSupportPlane(s, e3, t, hull);
  AddSupportPlane(s, -e3, t, hull);
  SetBox(s, t * e3.cwiseAbs(), hull);
}

WedgeHull SingleRayHull(const RayModel& ray, double sigmas) {
  const Vector3d d = RayDirection(ray);
  PointSet s;
  s.origin = ray.sensor_mean.cast<double>();
  s.Add(ray.sensor_mean.cast<double>());
  s.Add(ExtendedPointMean(ray, sigmas));
  WedgeHull hull;
  hull.planes.reserve(6);
  if (d.isZero()) {
    // No direction: a cube of half-width sigmas·σ_max around the point.
    const double half = std::max(kMinHalfThicknessM, sigmas * SigmaAlong(ray, d));
    OrientedBoxHull(s, Eigen::Matrix3d::Identity(), Vector3d::Constant(half), hull);
    return hull;
  }
  // The segment from the sensor to the point extended `sigmas`·σ_∥ (as for every wedge), widened
  // across the ray by kSingleRayLateralSigmas·σ along each lateral principal axis.
  const LateralSpread lateral = LateralSigmas(ray, d);
  Eigen::Matrix3d axes;
  axes.col(0) = d;
  axes.col(1) = lateral.axis[0];
  axes.col(2) = lateral.axis[1];
  const Vector3d half(kMinHalfThicknessM,
                      std::max(kMinHalfThicknessM, kSingleRayLateralSigmas * lateral.sigma[0]),
                      std::max(kMinHalfThicknessM, kSingleRayLateralSigmas * lateral.sigma[1]));
  OrientedBoxHull(s, axes, half, hull);
  return hull;
}

}  // namespace

WedgeHull MakeWedgeHull(const Wedge& wedge, double sigmas, uint64_t* facets) {
  const int num_rays = std::clamp<int>(wedge.num_rays, 1, 4);
  if (num_rays == 1) {
    if (facets != nullptr) *facets = 0;
    return SingleRayHull(wedge.rays[0], sigmas);
  }
  std::array<Vector3d, 4> sensors, ends;
  for (int i = 0; i < num_rays; ++i) {
    sensors[i] = wedge.rays[i].sensor_mean.cast<double>();
    ends[i] = ExtendedPointMean(wedge.rays[i], sigmas);
  }
  return HullOfWedgePoints(std::span(sensors.data(), num_rays), std::span(ends.data(), num_rays),
                           facets);
}

WedgeHull HullOfWedgePoints(std::span<const Vector3d> sensor_means,
                            std::span<const Vector3d> far_ends, uint64_t* facets) {
  assert(!far_ends.empty() && sensor_means.size() + far_ends.size() <= 8);
  const uint64_t hint = facets != nullptr ? *facets : 0;
  if (facets != nullptr) *facets = 0;
  PointSet s;
  s.origin = far_ends[0];
  // Rays of one frame share their sensor mean: a repeated point adds no facet, only work.
  auto add = [&s](const Vector3d& x) {
    const Vector3d rel = x - s.origin;
    for (int i = 0; i < s.n; ++i) {
      if (s.p[i] == rel) return;
    }
    s.p[s.n++] = rel;
  };
  for (const Vector3d& x : sensor_means) add(x);
  for (const Vector3d& x : far_ends) add(x);

  // The usual wedge spans 3D well: its facets are the planes through triples of points with
  // every point on one side. Only a thin (flat or collinear) set needs the principal axes.
  if (s.n >= 4) {
    Eigen::AlignedBox3d box;
    for (int i = 0; i < s.n; ++i) box.extend(s.p[i]);
    const double extent = box.diagonal().norm();
    // With a hint, replay it; if it names a non-facet, search as without one.
    for (const uint64_t only : {hint, uint64_t{0}}) {
      WedgeHull hull;
      hull.planes.reserve(16);
      double thinnest = std::numeric_limits<double>::infinity();
      uint64_t found = 0;
      if (!BruteForceHull(s, extent, hull, thinnest, &found, only)) continue;
      if (hull.planes.size() >= 4 && thinnest >= 2 * kMinHalfThicknessM) {
        if (facets != nullptr) *facets = found;
        return hull;
      }
      break;  // thin: principal axes below
    }
  }

  // Principal axes of the points, to detect flat and collinear wedges.
  Vector3d mean = Vector3d::Zero();
  for (int i = 0; i < s.n; ++i) mean += s.p[i];
  mean /= s.n;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (int i = 0; i < s.n; ++i) scatter += (s.p[i] - mean) * (s.p[i] - mean).transpose();
  // Closed form is enough: the axes only choose the case and the prism frame; every plane is
  // then placed at the exact support of the points.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(scatter);
  Eigen::Matrix3d axes;  // columns by decreasing spread
  for (int a = 0; a < 3; ++a) axes.col(a) = eig.eigenvectors().col(2 - a);
  Vector3d extent;
  for (int a = 0; a < 3; ++a) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int i = 0; i < s.n; ++i) {
      const double v = axes.col(a).dot(s.p[i]);
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    extent[a] = hi - lo;
  }

  WedgeHull hull;
  hull.planes.reserve(16);
  if (extent[1] < 2 * kMinHalfThicknessM) {
    // Collinear (all rays along one line, or all points coincide).
    OrientedBoxHull(s, axes, Vector3d::Constant(kMinHalfThicknessM), hull);
  } else if (extent[2] < 2 * kMinHalfThicknessM) {
    PrismHull(s, axes, kMinHalfThicknessM, hull);
  } else {
    double thinnest = 0;
    BruteForceHull(s, extent[0], hull, thinnest, nullptr, 0);
  }
  return hull;
}

Eigen::AlignedBox3d WedgePointsBox(std::span<const Vector3d> sensor_means,
                                   std::span<const Vector3d> far_ends) {
  Eigen::AlignedBox3d box;
  for (const Vector3d& x : sensor_means) box.extend(x);
  for (const Vector3d& x : far_ends) box.extend(x);
  // HullOfWedgePoints' box is the points' widened by at most kMinHalfThicknessM along each of
  // three orthonormal axes (≤ √3 of it per coordinate) and kSlackM.
  const Vector3d widen = Vector3d::Constant(2 * kMinHalfThicknessM);
  return Eigen::AlignedBox3d(box.min() - widen, box.max() + widen);
}

Vector3d ExtendedPointMean(const RayModel& ray, double sigmas) {
  const Vector3d d = RayDirection(ray);
  if (d.isZero()) return ray.point_mean.cast<double>();
  return ray.point_mean.cast<double>() + sigmas * SigmaAlong(ray, d) * d;
}

bool HullContainsPoint(const WedgeHull& hull, const Eigen::Vector3d& x) {
  if (!hull.box.contains(x)) return false;
  for (const Vector4d& q : hull.planes) {
    if (q.head<3>().dot(x) > q[3]) return false;
  }
  return true;
}

bool HullIntersectsBox(const WedgeHull& hull, const Eigen::AlignedBox3d& box) {
  // Separating axes: the box's axes (bounding boxes), then the hull's face normals.
  if ((box.min().array() > hull.box.max().array()).any() ||
      (box.max().array() < hull.box.min().array()).any()) {
    return false;
  }
  const Vector3d c = box.center();
  const Vector3d h = 0.5 * (box.max() - box.min());
  for (const Vector4d& q : hull.planes) {
    // Lowest point of the box along the normal.
    const double lo = q[0] * c[0] + q[1] * c[1] + q[2] * c[2] -
                      (std::abs(q[0]) * h[0] + std::abs(q[1]) * h[1] + std::abs(q[2]) * h[2]);
    if (lo > q[3]) return false;
  }
  return true;
}

absl::Status ValidateWedge(const Wedge& wedge) {
  if (wedge.num_rays < 1 || wedge.num_rays > 4) {
    return absl::InvalidArgumentError(
        absl::StrCat("wedge has num_rays ", int(wedge.num_rays), ", want 1 to 4"));
  }
  for (int r = 0; r < wedge.num_rays; ++r) {
    const RayModel& ray = wedge.rays[r];
    const std::pair<const char*, bool> fields[] = {
        {"sensor_mean", ray.sensor_mean.allFinite()},
        {"point_mean", ray.point_mean.allFinite()},
        {"sensor_cov", std::all_of(ray.sensor_cov.begin(), ray.sensor_cov.end(),
                                   [](float v) { return std::isfinite(v); })},
        {"point_cov", std::all_of(ray.point_cov.begin(), ray.point_cov.end(),
                                  [](float v) { return std::isfinite(v); })}};
    for (const auto& [name, finite] : fields) {
      if (!finite) {
        return absl::InvalidArgumentError(
            absl::StrCat("wedge ray ", r, " has a non-finite ", name));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace carvemap
