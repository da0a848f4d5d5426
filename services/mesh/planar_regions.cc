#include "services/mesh/planar_regions.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <numeric>
#include <queue>
#include <span>
#include <tuple>
#include <utility>

#include <Eigen/Eigenvalues>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/convex_hull_3.h>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/sorted_runs.h"
#include "geometry/union_find.h"

namespace carvemap {

absl::Status PlanarRegionOptions::Validate() const {
  if (!std::isfinite(distance_tolerance_m) || distance_tolerance_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "planar_regions: distance_tolerance_m must be >= 0, got ", distance_tolerance_m));
  }
  if (!std::isfinite(merge_angle_deg) || merge_angle_deg < 0 || merge_angle_deg > 90) {
    return absl::InvalidArgumentError(absl::StrCat(
        "planar_regions: merge_angle_deg must be in [0, 90], got ", merge_angle_deg));
  }
  if (!std::isfinite(boundary_tolerance_factor) || boundary_tolerance_factor < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "planar_regions: boundary_tolerance_factor must be >= 0, got ",
        boundary_tolerance_factor));
  }
  return absl::OkStatus();
}

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Eigen::Vector3i;

// Area-weighted moments of a set of faces, kept as sums so that growing and merging regions
// refits their plane in O(1) (§4.2.4 asks for a PCA fit of every tentative union). Each face
// is a uniform square of side s around its isosurface point (§4.3.3: PCA on the isosurface
// positions), so it adds s²/12 of spread along its two in-plane axes: a single face or a
// one-face-wide strip then still has a well-defined plane (the dissertation's "four corners" do the
// same for voxel faces). Points are relative to a common origin to keep the sums well
// conditioned.
struct Moments {
  double w = 0;                           // Σ a, m²
  Vector3d s = Vector3d::Zero();          // Σ a p
  Matrix3d ss = Matrix3d::Zero();         // Σ a (p pᵀ + s²/12 in-plane)
  Vector3d sn = Vector3d::Zero();         // Σ a n: orients the PCA normal into free space

  void AddFace(double a, const Vector3d& p, int axis, double side, const Vector3d& n) {
    w += a;
    s += a * p;
    ss += a * (p * p.transpose());
    const double spread = a * side * side / 12.0;
    for (int i = 0; i < 3; ++i) {
      if (i != axis) ss(i, i) += spread;
    }
    sn += a * n;
  }
  void Add(const Moments& o) {
    w += o.w;
    s += o.s;
    ss += o.ss;
    sn += o.sn;
  }
};

struct Plane {
  Vector3d centroid = Vector3d::Zero();  // relative to the origin
  Vector3d normal = Vector3d::UnitZ();   // unit, oriented along Σ a n
  Vector3d eigenvalues = Vector3d::Zero();
  [[nodiscard]] double Distance(const Vector3d& p) const { return normal.dot(p - centroid); }
};

Plane FitPlane(const Moments& m) {
  Plane plane;
  plane.centroid = m.s / m.w;
  Matrix3d cov = m.ss / m.w - plane.centroid * plane.centroid.transpose();
  cov = 0.5 * (cov + cov.transpose());
  Eigen::SelfAdjointEigenSolver<Matrix3d> eig(cov);
  plane.eigenvalues = eig.eigenvalues().cwiseMax(0.0);
  plane.normal = eig.eigenvectors().col(0).normalized();
  if (plane.normal.dot(m.sn) < 0) plane.normal = -plane.normal;
  return plane;
}

double AngleDeg(const Vector3d& a, const Vector3d& b) {
  return std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * 180.0 / M_PI;
}

// A face snapped to the finest lattice, in canonical (geometric) order.
struct LatticeFace {
  int axis = 0;
  int sign = 1;                     // +1: normal along +axis
  Vector3i corner = Vector3i::Zero();  // min corner, finest cells
  int side = 1;                     // finest cells
  uint32_t input = 0;               // index in the caller's face list
};

// The boundary between two face sets: the number of finest unit edges they share and the sum
// of those edges' midpoints (in half cells, exact in doubles), for the relaxation's check that
// two planes meet where their regions touch.
struct Boundary {
  double edges = 0;
  Vector3d sum_mid2 = Vector3d::Zero();  // Σ 2·midpoint, cells
  void Add(const Boundary& o) {
    edges += o.edges;
    sum_mid2 += o.sum_mid2;
  }
};

struct Link {
  uint32_t a = 0, b = 0;  // a < b
  Boundary boundary;
};

// Sorts links by (a, b) and sums the boundaries of equal pairs, in place: the face links are
// the largest structure of the stage (about two per face), so no second copy is made.
std::vector<Link> Aggregate(std::vector<Link> links) {
  std::sort(links.begin(), links.end(),
            [](const Link& x, const Link& y) { return std::tie(x.a, x.b) < std::tie(y.a, y.b); });
  size_t kept = 0;
  for (size_t i = 0; i < links.size(); ++i) {
    if (kept > 0 && links[kept - 1].a == links[i].a && links[kept - 1].b == links[i].b) {
      links[kept - 1].boundary.Add(links[i].boundary);
    } else {
      links[kept++] = links[i];
    }
  }
  links.resize(kept);
  // A copy at the new size costs both vectors at once: worth it only when it frees much (the
  // groups' links, a fraction of the faces'), not for the face links, nearly all distinct.
  if (kept < links.capacity() / 2) links.shrink_to_fit();
  return links;
}

// A connected set of same-direction faces (flood fill) or a grown region: members are
// canonical face ids.
struct Group {
  // Of the faces the plane is fitted to: all of them, but for mesh_growth's sides (TryAbsorb).
  Moments moments;
  double area = 0;  // Σ area of all its faces, m²
  Plane plane;
  std::vector<uint32_t> faces;
  Vector3d box_min = Vector3d::Constant(INFINITY), box_max = Vector3d::Constant(-INFINITY);
  double max_dist = 0;  // max |distance| of the isosurface points from `plane`
  // Grown regions with mesh_growth: how far their points may lie from the plane,
  // max(tolerance, the seed group's own max_dist) (see TryAbsorb).
  double limit = 0;
  Vector3d axis_normal = Vector3d::Zero();  // flood-fill groups: their common face normal
  // mesh_growth: the vertices of the convex hull of the points of faces[0, hull_of) (built
  // lazily; see Fitter::MaxDist): the farthest point from any plane is one of them.
  std::vector<Vector3d> hull;
  size_t hull_of = 0;
};

class Fitter {
 public:
  Fitter(std::span<const BoundaryFace> faces, const OctreeGrid& grid,
         const PlanarRegionOptions& options)
      : in_(faces), res_(grid.resolution_m()), opt_(options) {
    tol_ = options.distance_tolerance_m > 0 ? options.distance_tolerance_m : res_;
  }

  absl::StatusOr<PlanarRegionSet> Run() {
    if (absl::Status s = Snap(); !s.ok()) return s;
    if (absl::Status s = MatchEdges(); !s.ok()) return s;
    FloodFill();
    Grow();
    Relax();
    return Output();
  }

 private:
  // --- Lattice snapping and canonical order -------------------------------------------------
  absl::Status Snap() {
    const size_t n = in_.size();
    if (n >= (size_t{1} << 31)) return absl::InvalidArgumentError("planar_regions: too many faces");
    std::vector<LatticeFace> lf(n);
    for (size_t i = 0; i < n; ++i) {
      const BoundaryFace& f = in_[i];
      if (f.axis < 0 || f.axis > 2 || !(f.size_m > 0) || !std::isfinite(f.size_m) ||
          !f.center.allFinite() || !std::isfinite(f.isosurface_m) ||
          (f.sign != 1 && f.sign != -1)) {
        return absl::InvalidArgumentError(
            absl::StrCat("planar_regions: face ", i, " has a bad axis, size or position"));
      }
      LatticeFace& l = lf[i];
      l.axis = f.axis;
      l.sign = f.sign;
      l.side = std::max(1, static_cast<int>(std::lround(f.size_m / res_)));
      for (int j = 0; j < 3; ++j) {
        const double lo = j == f.axis ? f.center[j] : f.center[j] - 0.5 * f.size_m;
        l.corner[j] = static_cast<int>(std::lround(lo / res_));
      }
      l.input = static_cast<uint32_t>(i);
    }
    // Canonical order depends on geometry only (ties, i.e. duplicated faces, by isosurface
    // then input index), so the result does not depend on the caller's order (§4.2.4 asks
    // for nothing else; a merge that reorders chunks must give the same regions).
    std::vector<uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
      const LatticeFace& x = lf[a];
      const LatticeFace& y = lf[b];
      const auto kx = std::make_tuple(x.axis, x.sign, x.corner[x.axis], x.corner.x(),
                                      x.corner.y(), x.corner.z(), x.side);
      const auto ky = std::make_tuple(y.axis, y.sign, y.corner[y.axis], y.corner.x(),
                                      y.corner.y(), y.corner.z(), y.side);
      if (kx != ky) return kx < ky;
      const Vector3d pa = in_[a].isosurface();
      const Vector3d pb = in_[b].isosurface();
      if (pa != pb) return std::lexicographical_compare(pa.data(), pa.data() + 3, pb.data(),
                                                        pb.data() + 3);
      return a < b;
    });
    faces_.resize(n);
    for (size_t i = 0; i < n; ++i) faces_[i] = lf[order[i]];
    if (n > 0) origin_ = in_[faces_[0].input].isosurface();
    points_.resize(n);
    for (size_t i = 0; i < n; ++i) points_[i] = in_[faces_[i].input].isosurface() - origin_;
    return absl::OkStatus();
  }

  // --- Adjacency: faces sharing (part of) an edge -------------------------------------------
  // Every face edge is cut into finest unit edges, keyed by (start cell corner, direction);
  // sorting the keys puts the faces that share a unit edge next to each other, whatever their
  // sizes. O(E log E) with E = Σ 4·side.
  absl::Status MatchEdges() {
    if (faces_.empty()) return absl::OkStatus();
    Vector3i lo = faces_[0].corner, hi = faces_[0].corner;
    for (const LatticeFace& f : faces_) {
      lo = lo.cwiseMin(f.corner);
      hi = hi.cwiseMax(f.corner + Vector3i::Constant(f.side));
    }
    constexpr int kBits = 20;
    if (((hi - lo).array() >= (1 << kBits)).any()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "planar_regions: faces span more than 2^", kBits, " cells along an axis"));
    }
    std::vector<std::pair<uint64_t, uint32_t>> keys;
    size_t total = 0;
    for (const LatticeFace& f : faces_) total += 4 * size_t(f.side);
    keys.reserve(total);
    auto key = [&](const Vector3i& p, int dir) {
      const Vector3i q = p - lo;
      return (uint64_t(q.x()) << (2 * kBits + 2)) | (uint64_t(q.y()) << (kBits + 2)) |
             (uint64_t(q.z()) << 2) | uint64_t(dir);
    };
    for (uint32_t i = 0; i < faces_.size(); ++i) {
      const LatticeFace& f = faces_[i];
      const int b = (f.axis + 1) % 3, c = (f.axis + 2) % 3;
      for (int t = 0; t < f.side; ++t) {
        Vector3i p = f.corner;  // edges along b at c = 0 and c = side
        p[b] += t;
        keys.emplace_back(key(p, b), i);
        p[c] += f.side;
        keys.emplace_back(key(p, b), i);
        p = f.corner;  // edges along c at b = 0 and b = side
        p[c] += t;
        keys.emplace_back(key(p, c), i);
        p[b] += f.side;
        keys.emplace_back(key(p, c), i);
      }
    }
    std::sort(keys.begin(), keys.end());
    // One link per pair of faces sharing a unit edge: counted first, so the vector is made at
    // its size instead of doubling (it and the keys are the stage's peak).
    const auto edge_of = [](const auto& k) { return k.first; };
    size_t pairs = 0;
    ForEachRun(keys, edge_of, [&](size_t g, size_t e) { pairs += (e - g) * (e - g - 1) / 2; });
    std::vector<Link> links;
    links.reserve(pairs);
    ForEachRun(keys, edge_of, [&](size_t g, size_t e) {
      if (e - g > 1) {
        const uint64_t k = keys[g].first;
        const int dir = int(k & 3);
        Vector3i p(int((k >> (2 * kBits + 2)) & ((1u << kBits) - 1)),
                   int((k >> (kBits + 2)) & ((1u << kBits) - 1)), int((k >> 2) & ((1u << kBits) - 1)));
        p += lo;
        Vector3d mid2 = 2.0 * p.cast<double>();
        mid2[dir] += 1.0;
        for (size_t x = g; x < e; ++x) {
          for (size_t y = x + 1; y < e; ++y) {
            if (keys[x].second == keys[y].second) continue;
            links.push_back({std::min(keys[x].second, keys[y].second),
                             std::max(keys[x].second, keys[y].second), Boundary{1.0, mid2}});
          }
        }
      }
    });
    std::vector<std::pair<uint64_t, uint32_t>>().swap(keys);
    face_links_ = Aggregate(std::move(links));
    return absl::OkStatus();
  }

  Vector3d AxisNormal(const LatticeFace& f) const {
    Vector3d n = Vector3d::Zero();
    n[f.axis] = f.sign;
    return n;
  }

  void AddFaceTo(Group& g, uint32_t i) const {
    const LatticeFace& f = faces_[i];
    const double side_m = f.side * res_;
    g.moments.AddFace(side_m * side_m, points_[i], f.axis, side_m, AxisNormal(f));
    g.area += side_m * side_m;
    g.faces.push_back(i);
    g.box_min = g.box_min.cwiseMin(points_[i]);
    g.box_max = g.box_max.cwiseMax(points_[i]);
  }

  double ExactMaxDist(const Group& g, const Plane& plane) const {
    double m = 0;
    for (uint32_t i : g.faces) m = std::max(m, std::abs(plane.Distance(points_[i])));
    return m;
  }

  // mesh_growth: max |distance| from `plane` of the group's isosurface points, exactly, and
  // without the budget of the default growth. Scanning all points at every tentative union
  // would make growing quadratic on big regions (a 400 m² floor absorbs thousands of groups),
  // and a capped budget leaves regions in fragments once it is spent (~15 % of the office's
  // observed walls). A linear function peaks at a vertex of the convex hull, so big groups keep
  // the hull of their points (CGAL's extreme_points_3: ~100 vertices for 90 000 noisy points
  // of a plane) plus the faces added since, rebuilt when those outnumber the hull twice:
  // amortized O(n log n) in all.
  double HullMaxDist(Group& g, const Plane& plane) const {
    constexpr size_t kSmall = 48;
    if (g.faces.size() <= kSmall) return ExactMaxDist(g, plane);
    if (g.faces.size() - g.hull_of > std::max(kSmall, 2 * g.hull.size())) {
      using K = CGAL::Exact_predicates_inexact_constructions_kernel;
      std::vector<K::Point_3> in, out;
      in.reserve(g.hull.size() + g.faces.size() - g.hull_of);
      for (const Vector3d& x : g.hull) in.emplace_back(x.x(), x.y(), x.z());
      for (size_t k = g.hull_of; k < g.faces.size(); ++k) {
        const Vector3d& x = points_[g.faces[k]];
        in.emplace_back(x.x(), x.y(), x.z());
      }
      CGAL::extreme_points_3(in, std::back_inserter(out));
      g.hull.clear();
      for (const K::Point_3& q : out) g.hull.emplace_back(q.x(), q.y(), q.z());
      g.hull_of = g.faces.size();
    }
    double m = 0;
    for (const Vector3d& x : g.hull) m = std::max(m, std::abs(plane.Distance(x)));
    for (size_t k = g.hull_of; k < g.faces.size(); ++k) {
      m = std::max(m, std::abs(plane.Distance(points_[g.faces[k]])));
    }
    return m;
  }

  double MaxDist(Group& g, const Plane& plane) const {
    return opt_.mesh_growth ? HullMaxDist(g, plane) : ExactMaxDist(g, plane);
  }

  // Max over the group's bounding box of |a·(x − o)| (a linear function peaks at a corner).
  static double BoxMaxAbs(const Group& g, const Vector3d& a, const Vector3d& o) {
    double m = 0;
    for (int c = 0; c < 8; ++c) {
      const Vector3d x((c & 1) ? g.box_max.x() : g.box_min.x(),
                       (c & 2) ? g.box_max.y() : g.box_min.y(),
                       (c & 4) ? g.box_max.z() : g.box_min.z());
      m = std::max(m, std::abs(a.dot(x - o)));
    }
    return m;
  }

  // --- (a) Flood fill: connected faces with the same normal (§4.2.4, Fig 4.6b) --------------
  // Two faces with the same axis and direction that share an edge are coplanar, so every
  // group lies exactly on one lattice plane.
  void FloodFill() {
    UnionFind<uint32_t> uf(faces_.size());  // roots: each set's smallest member
    for (const Link& l : face_links_) {
      const LatticeFace& a = faces_[l.a];
      const LatticeFace& b = faces_[l.b];
      if (a.axis == b.axis && a.sign == b.sign) uf.Union(l.a, l.b);
    }
    face_comp_.assign(faces_.size(), 0);
    std::vector<int64_t> comp_of_root(faces_.size(), -1);
    // Made at their number: a group is ~350 B, and a doubling vector holds up to three times
    // as many during its last copy.
    size_t num_comps = 0;
    for (uint32_t i = 0; i < faces_.size(); ++i) num_comps += uf.Find(i) == i;
    comps_.reserve(num_comps);
    for (uint32_t i = 0; i < faces_.size(); ++i) {  // ids in canonical order of first face
      const uint32_t r = uf.Find(i);
      if (comp_of_root[r] < 0) {
        comp_of_root[r] = int64_t(comps_.size());
        comps_.emplace_back();
        comps_.back().axis_normal = AxisNormal(faces_[i]);
      }
      face_comp_[i] = uint32_t(comp_of_root[r]);
      AddFaceTo(comps_[face_comp_[i]], i);
    }
    for (Group& g : comps_) {
      g.plane = FitPlane(g.moments);
      g.max_dist = MaxDist(g, g.plane);
    }
    // The face links become the groups' links in place: nothing reads them after this.
    std::vector<Link> links = std::move(face_links_);
    size_t kept = 0;
    for (size_t i = 0; i < links.size(); ++i) {
      const uint32_t a = face_comp_[links[i].a], b = face_comp_[links[i].b];
      if (a == b) continue;
      links[kept++] = {std::min(a, b), std::max(a, b), links[i].boundary};
    }
    links.resize(kept);
    comp_links_ = Aggregate(std::move(links));
    // Each group's neighbours, sorted: one flat array (CSR) rather than a vector per group.
    comp_adj_start_.assign(comps_.size() + 1, 0);
    for (const Link& l : comp_links_) {
      ++comp_adj_start_[l.a + 1];
      ++comp_adj_start_[l.b + 1];
    }
    std::partial_sum(comp_adj_start_.begin(), comp_adj_start_.end(), comp_adj_start_.begin());
    comp_adj_.resize(comp_adj_start_.back());
    std::vector<uint32_t> fill(comp_adj_start_.begin(), comp_adj_start_.end() - 1);
    for (const Link& l : comp_links_) {
      comp_adj_[fill[l.a]++] = l.b;
      comp_adj_[fill[l.b]++] = l.a;
    }
    for (size_t c = 0; c < comps_.size(); ++c) {
      std::sort(comp_adj_.begin() + comp_adj_start_[c], comp_adj_.begin() + comp_adj_start_[c + 1]);
    }
  }

  std::span<const uint32_t> Neighbours(uint32_t c) const {
    return std::span<const uint32_t>(comp_adj_).subspan(
        comp_adj_start_[c], comp_adj_start_[c + 1] - comp_adj_start_[c]);
  }

  // --- (b) PCA region growing (§4.2.4, Fig 4.6c) --------------------------------------------
  // Seeds are the flood-fill groups by decreasing area; a region absorbs a neighbouring group
  // when the PCA plane of their union keeps every isosurface point of the group within the
  // tolerance ("the maximum distance of V from the plane is at most the grid size") and keeps
  // the region's own points as close as before (within max(tolerance, their current maximum):
  // a noisy flood-fill group is accepted as the dissertation says, but growing may not make it
  // worse). The union plane comes from the summed moments in O(1); the candidate's points are
  // checked exactly (after an O(1) rejection by its centroid); the region's points by a bound over
  // its bounding box, recomputed exactly (within a budget) only when the bound is not enough.
  //
  // mesh_growth differs in three ways, all toward fewer and bigger regions for the planar mesh:
  // - the region's points keep the fixed bound max(tolerance, the seed group's spread): a
  //   flood-fill group is one lattice plane and is accepted as the dissertation says even where its
  //   isosurface points spread wider (faces of big leaves against unobserved space are offset
  //   up to 0.45 of their size, Fig 4.9's clamp). A bound that follows the region's current
  //   maximum refuses any absorption that tilts the plane by a hair once a point sits at the
  //   limit (24 000 refusals on the office: the floor keeps one-face bumps it fits within 2 cm
  //   as separate regions);
  // - the exact recheck has no budget (HullMaxDist keeps it amortized O(n log n));
  // - a group "faces away" only when its axis normal is more than ~105° from the region's
  //   normal (cos = −0.25): the risers of a zig-zag (§4.2.4, Fig 4.7a) and the one-cell steps
  //   of a carved wall that is axis-aligned are at 90° to its plane, give or take the fit's
  //   tilt, and they are what connects the wall's terraces (refusing them leaves ~70 % of a
  //   carved room's regions single faces). The opposite side of a thin slab is at 180° and
  //   stays out. Such sides (more than 45° from the normal) join without a say in the plane:
  //   the strips of floor, ceiling or furniture top one cell wide along a wall all lie on its
  //   free side, half a cell out, and fitting them pulls the wall's plane into the room (on
  //   the office: true wall points within 5 cm of the planar mesh 53.5 % with them in the
  //   fit, 54.4 % without; the zig-zag's terraces alone give its slope).
  // The floor plans do not use it: vertical regions that absorb steps and risers give worse
  // wall samples (§5.3.1; object_segmentation_test found 19 % of objects instead of 25 %).
  // Bigger planes also follow the carved walls less closely than many small ones: true wall
  // points within 5 cm of the planar mesh fall by 3 points on the office (docs/BENCHMARKS.md).
  static constexpr double kMeshFacingMin = -0.25;
  static constexpr double kMeshSideMax = 0.70710678;  // cos 45°
  bool TryAbsorb(Group& r, Group& c) {
    const double facing_min = opt_.mesh_growth ? kMeshFacingMin : 0.0;
    if (c.axis_normal.dot(r.plane.normal) <= facing_min) return false;
    const bool side = opt_.mesh_growth && c.axis_normal.dot(r.plane.normal) < kMeshSideMax;
    Moments u = r.moments;
    if (!side) u.Add(c.moments);
    const Plane p = side ? r.plane : FitPlane(u);
    if (c.axis_normal.dot(p.normal) <= facing_min) return false;
    // The mean of the candidate's points is within the tolerance if all of them are.
    if (std::abs(p.Distance(c.plane.centroid)) > tol_) return false;
    double cand = 0;
    if (BoxMaxAbs(c, p.normal, p.centroid) <= tol_) {
      cand = BoxMaxAbs(c, p.normal, p.centroid);
    } else {
      cand = MaxDist(c, p);
      if (cand > tol_) return false;
    }
    const double allowed = opt_.mesh_growth ? r.limit : std::max(tol_, r.max_dist);
    // |n'·(x − c')| ≤ |n·(x − c)| + |(n' − n)·(x − c)| + |n'·(c − c')| for the region's points.
    double old = r.max_dist + BoxMaxAbs(r, p.normal - r.plane.normal, r.plane.centroid) +
                 std::abs(p.normal.dot(r.plane.centroid - p.centroid));
    if (old > allowed) {
      if (opt_.mesh_growth) {
        old = HullMaxDist(r, p);
      } else {
        if (recompute_budget_ < double(r.faces.size())) return false;
        recompute_budget_ -= double(r.faces.size());
        old = ExactMaxDist(r, p);
      }
      if (old > allowed) return false;
    }
    r.moments = u;
    r.area += c.area;
    r.plane = p;
    r.max_dist = std::max(old, cand);
    r.faces.insert(r.faces.end(), c.faces.begin(), c.faces.end());
    r.box_min = r.box_min.cwiseMin(c.box_min);
    r.box_max = r.box_max.cwiseMax(c.box_max);
    return true;
  }

  void Grow() {
    const size_t nc = comps_.size();
    std::vector<uint32_t> order(nc);
    std::iota(order.begin(), order.end(), 0u);
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
      return comps_[a].moments.w > comps_[b].moments.w;
    });
    comp_region_.assign(nc, -1);
    std::vector<int64_t> tested_region(nc, -1);
    std::vector<double> tested_weight(nc, 0);
    // Exact rechecks of a region's points are bounded by a few passes over all faces in
    // total, so growth stays near-linear whatever the input.
    recompute_budget_ = 8.0 * double(faces_.size()) + 1e5;
    for (uint32_t seed : order) {
      if (comp_region_[seed] >= 0) continue;
      const int64_t rid = int64_t(regions_.size());
      // A group is read no more once it is in a region: the seed is moved into it, and an
      // absorbed group's faces freed, so the groups' faces are not held twice.
      Group r = std::move(comps_[seed]);
      r.limit = std::max(tol_, r.max_dist);
      comp_region_[seed] = rid;
      const std::span<const uint32_t> seed_adj = Neighbours(seed);
      std::deque<uint32_t> queue(seed_adj.begin(), seed_adj.end());
      while (!queue.empty()) {
        const uint32_t c = queue.front();
        queue.pop_front();
        if (comp_region_[c] >= 0) continue;
        if (tested_region[c] == rid && tested_weight[c] == r.area) continue;
        tested_region[c] = rid;
        tested_weight[c] = r.area;
        if (!TryAbsorb(r, comps_[c])) continue;
        comp_region_[c] = rid;
        comps_[c] = Group();
        for (uint32_t d : Neighbours(c)) {
          if (comp_region_[d] < 0) queue.push_back(d);
        }
      }
      regions_.push_back(std::move(r));
    }
    flood_fill_groups_ = comps_.size();
    std::vector<Group>().swap(comps_);
    std::vector<uint32_t>().swap(comp_adj_);
    std::vector<size_t>().swap(comp_adj_start_);
  }

  // --- (c) Relaxation: merge adjacent regions within 15° (§4.2.4, Fig 4.6d) -----------------
  // Pairs are merged smallest angle first (a priority queue with lazy invalidation), refitting
  // the union each time. Besides the dissertation's angle test the planes must stay consistent:
  // both meet the regions' shared boundary (no step between parallel planes) and the union's plane
  // is within the angle of both parts. Ties are broken by region ids, which come from the
  // canonical face order, so the result does not depend on hash order.
  bool Consistent(const Group& a, const Group& b, const Boundary& bd, Plane* merged) const {
    if (AngleDeg(a.plane.normal, b.plane.normal) >= opt_.merge_angle_deg) return false;
    const Vector3d q = bd.sum_mid2 / (2.0 * bd.edges) * res_ - origin_;
    const double btol = opt_.boundary_tolerance_factor * tol_;
    if (std::abs(a.plane.Distance(q)) > btol || std::abs(b.plane.Distance(q)) > btol) {
      return false;
    }
    Moments u = a.moments;
    u.Add(b.moments);
    *merged = FitPlane(u);
    // For the planar mesh (mesh_growth) the union must also stay a plane: its RMS distance
    // from the fitted plane within the grid-size tolerance. The dissertation's relaxation has no
    // distance test ("aesthetically pleasing"), so facets of a curved wall, each within 15° of
    // the next, chain into one plane: on the simulated office's lobby (an arc of 1.5 m
    // sagitta) the planar mesh then lay up to ~10 cm off the wall the dense mesh follows.
    if (opt_.mesh_growth && merged->eigenvalues[0] > tol_ * tol_) return false;
    return AngleDeg(merged->normal, a.plane.normal) < opt_.merge_angle_deg &&
           AngleDeg(merged->normal, b.plane.normal) < opt_.merge_angle_deg;
  }

  void Relax() {
    const uint32_t nr = uint32_t(regions_.size());
    grown_regions_ = nr;
    std::vector<Link> links;
    for (const Link& l : comp_links_) {
      const uint32_t a = uint32_t(comp_region_[l.a]), b = uint32_t(comp_region_[l.b]);
      if (a != b) links.push_back({std::min(a, b), std::max(a, b), l.boundary});
    }
    std::vector<Link>().swap(comp_links_);
    std::vector<int64_t>().swap(comp_region_);
    links = Aggregate(std::move(links));
    std::vector<absl::flat_hash_map<uint32_t, Boundary>> adj(nr);
    for (const Link& l : links) {
      adj[l.a][l.b] = l.boundary;
      adj[l.b][l.a] = l.boundary;
    }
    std::vector<uint32_t> version(nr, 0);
    std::vector<bool> alive(nr, true);
    struct Candidate {
      double angle;
      uint32_t a, b, va, vb;
      bool operator>(const Candidate& o) const {
        return std::tie(angle, a, b) > std::tie(o.angle, o.a, o.b);
      }
    };
    std::priority_queue<Candidate, std::vector<Candidate>, std::greater<Candidate>> pq;
    // Queued pairs keep their key when a region's normal moves by less than kRequeueDeg, so a
    // big region absorbing many small ones does not re-queue all its pairs each time (that
    // would be quadratic); pairs are queued up to the angle plus twice that slack (both
    // regions may have moved) and Consistent() checks the current planes.
    constexpr double kRequeueDeg = 0.5;
    std::vector<Vector3d> queued_normal(nr);
    for (uint32_t i = 0; i < nr; ++i) queued_normal[i] = regions_[i].plane.normal;
    auto push = [&](uint32_t a, uint32_t b) {
      if (a > b) std::swap(a, b);
      const double ang = AngleDeg(regions_[a].plane.normal, regions_[b].plane.normal);
      if (ang < opt_.merge_angle_deg + 2 * kRequeueDeg) {
        pq.push({ang, a, b, version[a], version[b]});
      }
    };
    for (const Link& l : links) push(l.a, l.b);
    std::vector<uint32_t> ns;
    while (!pq.empty()) {
      const Candidate c = pq.top();
      pq.pop();
      if (!alive[c.a] || !alive[c.b] || version[c.a] != c.va || version[c.b] != c.vb) continue;
      auto it = adj[c.a].find(c.b);
      if (it == adj[c.a].end()) continue;
      Plane merged;
      if (!Consistent(regions_[c.a], regions_[c.b], it->second, &merged)) continue;
      // The region with more faces survives and absorbs the other's faces and neighbours, so
      // every face and adjacency entry moves O(log n) times; ties keep the smaller id.
      uint32_t k = c.a, g = c.b;
      if (regions_[g].faces.size() > regions_[k].faces.size()) std::swap(k, g);
      Group& keep = regions_[k];
      Group& gone = regions_[g];
      keep.moments.Add(gone.moments);
      keep.area += gone.area;
      keep.plane = merged;
      keep.faces.insert(keep.faces.end(), gone.faces.begin(), gone.faces.end());
      keep.box_min = keep.box_min.cwiseMin(gone.box_min);
      keep.box_max = keep.box_max.cwiseMax(gone.box_max);
      gone.faces.clear();
      gone.faces.shrink_to_fit();
      alive[g] = false;
      adj[k].erase(g);
      ns.clear();
      for (const auto& [n, bd] : adj[g]) {
        if (n == k) continue;
        adj[k][n].Add(bd);
        const Boundary moved = adj[n][g];
        adj[n].erase(g);
        adj[n][k].Add(moved);
        ns.push_back(n);
      }
      absl::flat_hash_map<uint32_t, Boundary>().swap(adj[g]);
      if (AngleDeg(keep.plane.normal, queued_normal[k]) > kRequeueDeg) {
        // The plane moved: every pair of the merged region gets a fresh key.
        ++version[k];
        queued_normal[k] = keep.plane.normal;
        ns.clear();
        for (const auto& [n, bd] : adj[k]) ns.push_back(n);
      }
      std::sort(ns.begin(), ns.end());
      for (uint32_t n : ns) push(k, n);
    }
    std::vector<Group> kept;
    for (uint32_t i = 0; i < nr; ++i) {
      if (alive[i]) kept.push_back(std::move(regions_[i]));
    }
    regions_ = std::move(kept);
  }

  PlanarRegionSet Output() const {
    PlanarRegionSet out;
    out.flood_fill_groups = flood_fill_groups_;
    out.grown_regions = grown_regions_;
    out.face_region.assign(faces_.size(), -1);
    std::vector<std::pair<uint32_t, size_t>> by_first;  // (smallest input index, region)
    for (size_t r = 0; r < regions_.size(); ++r) {
      uint32_t first = UINT32_MAX;
      for (uint32_t f : regions_[r].faces) first = std::min(first, faces_[f].input);
      by_first.emplace_back(first, r);
    }
    std::sort(by_first.begin(), by_first.end());
    out.regions.reserve(regions_.size());
    for (const auto& [first, r] : by_first) {
      const Group& g = regions_[r];
      PlanarRegion pr;
      pr.id = int(out.regions.size());
      pr.normal = g.plane.normal;
      pr.centroid = g.plane.centroid + origin_;
      pr.area_m2 = g.area;
      pr.eigenvalues = g.plane.eigenvalues;
      pr.faces.reserve(g.faces.size());
      for (uint32_t f : g.faces) {
        pr.faces.push_back(faces_[f].input);
        out.face_region[faces_[f].input] = pr.id;
      }
      std::sort(pr.faces.begin(), pr.faces.end());
      out.regions.push_back(std::move(pr));
    }
    return out;
  }

  std::span<const BoundaryFace> in_;
  double res_;
  PlanarRegionOptions opt_;
  double tol_ = 0;
  Vector3d origin_ = Vector3d::Zero();
  std::vector<LatticeFace> faces_;  // canonical order
  std::vector<Vector3d> points_;    // isosurface points − origin, canonical order
  std::vector<Link> face_links_;
  std::vector<uint32_t> face_comp_;
  std::vector<Group> comps_;
  std::vector<Link> comp_links_;
  std::vector<uint32_t> comp_adj_;      // groups' neighbours, group c's at
  std::vector<size_t> comp_adj_start_;  // [comp_adj_start_[c], comp_adj_start_[c + 1])
  size_t flood_fill_groups_ = 0;
  std::vector<int64_t> comp_region_;
  std::vector<Group> regions_;
  double recompute_budget_ = 0;
  size_t grown_regions_ = 0;
};

}  // namespace

absl::StatusOr<PlanarRegionSet> FitPlanarRegions(std::span<const BoundaryFace> faces,
                                                 const OctreeGrid& grid,
                                                 const PlanarRegionOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  return Fitter(faces, grid, options).Run();
}

}  // namespace carvemap
