#include "services/floorplan/eigencrust/wall_curve_fit.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <utility>

#include <Eigen/Dense>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/union_find.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

struct Model {
  WallCurve::Kind kind = WallCurve::Kind::kLine;
  Vector2d p = Vector2d::Zero();  // line point / circle centre
  Vector2d d = Vector2d::UnitX(); // line direction
  double r = 0;
  // Normal orientation: line: +1/−1 = the normal is ±perp(d); circle: +1 = normals point away
  // from the centre, −1 towards it; 0 = unknown (both accepted).
  int orient = 0;

  [[nodiscard]] double Distance(const Vector2d& x) const {
    if (kind == WallCurve::Kind::kLine) return std::abs((x - p).dot(Vector2d(-d.y(), d.x())));
    return std::abs((x - p).norm() - r);
  }
  // The model's unit normal at x (oriented when orient ≠ 0).
  [[nodiscard]] Vector2d NormalAt(const Vector2d& x) const {
    Vector2d n = kind == WallCurve::Kind::kLine ? Vector2d(-d.y(), d.x())
                                                : Vector2d((x - p).normalized());
    return orient < 0 ? Vector2d(-n) : n;
  }
  [[nodiscard]] Vector2d Project(const Vector2d& x) const {
    if (kind == WallCurve::Kind::kLine) return p + (x - p).dot(d) * d;
    const Vector2d v = x - p;
    const double n = v.norm();
    return n > 0 ? Vector2d(p + r * v / n) : x;
  }
};

// Orients a model by the summed normals of its samples (sign of their agreement with the
// unoriented model normal).
void Orient(Model& m, const std::vector<Vector2d>& pts, const std::vector<Vector2d>& normals,
            const std::vector<int>& ids) {
  m.orient = 0;
  double s = 0;
  for (int i : ids) s += normals[i].dot(m.NormalAt(pts[i]));
  if (s > 1e-9) m.orient = 1;
  if (s < -1e-9) m.orient = -1;
}

// Total least squares line through points (their principal direction through their mean).
Model FitLine(const std::vector<Vector2d>& pts, const std::vector<int>& ids) {
  Vector2d mean = Vector2d::Zero();
  for (int i : ids) mean += pts[i];
  mean /= static_cast<double>(ids.size());
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (int i : ids) cov += (pts[i] - mean) * (pts[i] - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  Model m;
  m.kind = WallCurve::Kind::kLine;
  m.p = mean;
  m.d = eig.eigenvectors().col(1).normalized();
  return m;
}

// Algebraic (Kåsa) circle fit: x² + y² + D x + E y + F = 0 in least squares, relative to the
// mean for conditioning. False for (nearly) collinear points.
bool FitCircle(const std::vector<Vector2d>& pts, const std::vector<int>& ids, Model* out) {
  Vector2d mean = Vector2d::Zero();
  for (int i : ids) mean += pts[i];
  mean /= static_cast<double>(ids.size());
  Eigen::MatrixXd a(ids.size(), 3);
  Eigen::VectorXd b(ids.size());
  for (size_t k = 0; k < ids.size(); ++k) {
    const Vector2d q = pts[ids[k]] - mean;
    a(k, 0) = q.x();
    a(k, 1) = q.y();
    a(k, 2) = 1;
    b(k) = -q.squaredNorm();
  }
  const Eigen::Vector3d sol = a.colPivHouseholderQr().solve(b);
  const Vector2d c(-sol(0) / 2, -sol(1) / 2);
  const double r2 = c.squaredNorm() - sol(2);
  if (!std::isfinite(r2) || r2 <= 0 || !c.allFinite()) return false;
  out->kind = WallCurve::Kind::kCircle;
  out->p = c + mean;
  out->r = std::sqrt(r2);
  return true;
}

bool CircleThrough(const Vector2d& a, const Vector2d& b, const Vector2d& c, Model* out) {
  const Vector2d ab = b - a, ac = c - a;
  const double det = 2 * (ab.x() * ac.y() - ab.y() * ac.x());
  const double scale = ab.squaredNorm() * ac.squaredNorm();
  if (std::abs(det) <= 1e-12 * std::max(scale, 1e-300) || det == 0) return false;
  const double ux = (ac.y() * ab.squaredNorm() - ab.y() * ac.squaredNorm()) / det;
  const double uy = (ab.x() * ac.squaredNorm() - ac.x() * ab.squaredNorm()) / det;
  out->kind = WallCurve::Kind::kCircle;
  out->p = a + Vector2d(ux, uy);
  out->r = Vector2d(ux, uy).norm();
  return std::isfinite(out->r);
}

// Samples bucketed on a square grid.
class Grid {
 public:
  Grid(const std::vector<Vector2d>& pts, const std::vector<int>& ids, double cell)
      : cell_(cell) {
    for (int i : ids) cells_[Key(Cell(pts[i]))].push_back(i);
    for (const auto& [key, members] : cells_) {
      keys_.push_back(key);
      const auto [cx, cy] = Unkey(key);
      centres_.emplace_back((cx + 0.5) * cell_, (cy + 0.5) * cell_);
    }
    // Deterministic iteration order.
    std::vector<size_t> order(keys_.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return keys_[a] < keys_[b]; });
    std::vector<uint64_t> k2;
    std::vector<Vector2d> c2;
    for (size_t o : order) {
      k2.push_back(keys_[o]);
      c2.push_back(centres_[o]);
    }
    keys_ = std::move(k2);
    centres_ = std::move(c2);
  }
  [[nodiscard]] double cell() const { return cell_; }
  [[nodiscard]] std::pair<int64_t, int64_t> Cell(const Vector2d& p) const {
    return {static_cast<int64_t>(std::floor(p.x() / cell_)),
            static_cast<int64_t>(std::floor(p.y() / cell_))};
  }
  [[nodiscard]] const std::vector<int>* At(int64_t cx, int64_t cy) const {
    const auto it = cells_.find(Key({cx, cy}));
    return it == cells_.end() ? nullptr : &it->second;
  }
  [[nodiscard]] size_t size() const { return keys_.size(); }
  [[nodiscard]] const Vector2d& centre(size_t k) const { return centres_[k]; }
  [[nodiscard]] const std::vector<int>& members(size_t k) const { return cells_.at(keys_[k]); }

 private:
  static uint64_t Key(std::pair<int64_t, int64_t> c) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(c.first)) << 32) |
           static_cast<uint32_t>(c.second);
  }
  static std::pair<int64_t, int64_t> Unkey(uint64_t k) {
    return {static_cast<int32_t>(k >> 32), static_cast<int32_t>(k & 0xFFFFFFFFu)};
  }
  double cell_;
  absl::flat_hash_map<uint64_t, std::vector<int>> cells_;
  std::vector<uint64_t> keys_;
  std::vector<Vector2d> centres_;
};


}  // namespace

absl::Status WallCurveFitOptions::Validate() const {
  auto bad = [](const char* name, double v) {
    return absl::InvalidArgumentError(absl::StrCat("wall curve fit: bad ", name, " = ", v));
  };
  for (auto [name, v] : {std::pair{"inlier_distance_m", inlier_distance_m},
                         std::pair{"max_snap_m", max_snap_m},
                         std::pair{"corner_snap_m", corner_snap_m},
                         std::pair{"min_component_m", min_component_m}}) {
    if (!std::isfinite(v) || v < 0) return bad(name, v);
  }
  if (!std::isfinite(max_normal_angle_deg) || max_normal_angle_deg < 0 ||
      max_normal_angle_deg > 180) {
    return bad("max_normal_angle_deg", max_normal_angle_deg);
  }
  if (min_inliers < 3) return bad("min_inliers (≥ 3)", min_inliers);
  if (iterations < 1) return bad("iterations", iterations);
  if (!std::isfinite(neighbourhood_m) || neighbourhood_m <= 0) {
    return bad("neighbourhood_m", neighbourhood_m);
  }
  if (!std::isfinite(min_radius_m) || !std::isfinite(max_radius_m) || min_radius_m < 0 ||
      max_radius_m < min_radius_m) {
    return bad("min_radius_m / max_radius_m", min_radius_m);
  }
  return absl::OkStatus();
}

absl::StatusOr<WallCurveFit> FitWallCurves(const std::vector<Vector2d>& vertices,
                                           const std::vector<Vector2d>& normals,
                                           const std::vector<std::array<int, 2>>& boundary,
                                           double spacing_m, const WallCurveFitOptions& options,
                                           WallCurveFitReport* report) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (!std::isfinite(spacing_m) || spacing_m <= 0) {
    return absl::InvalidArgumentError(absl::StrCat("wall curve fit: bad spacing ", spacing_m));
  }
  if (normals.size() != vertices.size()) {
    return absl::InvalidArgumentError("wall curve fit: normals and vertices differ in size");
  }
  const int nv = static_cast<int>(vertices.size());
  for (size_t e = 0; e < boundary.size(); ++e) {
    for (int v : boundary[e]) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(
            absl::StrCat("wall curve fit: boundary edge ", e, " has vertex ", v, " out of range"));
      }
    }
  }
  const double tol = options.inlier_distance_m > 0 ? options.inlier_distance_m : spacing_m;
  const double snap = options.max_snap_m > 0 ? options.max_snap_m : 2 * spacing_m;
  const double corner_snap = options.corner_snap_m > 0 ? options.corner_snap_m : 3 * spacing_m;
  const double cos_max = std::cos(options.max_normal_angle_deg * M_PI / 180.0);
  WallCurveFitReport rep;

  // The samples of B and their neighbours along it.
  std::vector<std::vector<int>> adjacent(nv);
  for (const auto& e : boundary) {
    if (e[0] == e[1]) continue;
    adjacent[e[0]].push_back(e[1]);
    adjacent[e[1]].push_back(e[0]);
  }
  std::vector<int> ids;
  for (int v = 0; v < nv; ++v) {
    if (adjacent[v].empty()) continue;
    std::sort(adjacent[v].begin(), adjacent[v].end());
    adjacent[v].erase(std::unique(adjacent[v].begin(), adjacent[v].end()), adjacent[v].end());
    ids.push_back(v);
  }
  rep.boundary_samples = ids.size();
  WallCurveFit out;
  out.curve_of.assign(nv, -1);
  out.fitted = vertices;
  if (ids.empty()) {
    if (report != nullptr) *report = rep;
    return out;
  }

  const Grid coarse(vertices, ids, options.neighbourhood_m);
  const Grid fine(vertices, ids, std::max(4 * tol, 0.05));
  std::vector<int>& model_of = out.curve_of;
  std::vector<Model> models;
  std::mt19937_64 rng(options.seed);
  auto random_below = [&](size_t n) { return static_cast<size_t>(rng() % n); };

  auto accepts = [&](const Model& m, int v) {
    if (m.Distance(vertices[v]) > tol) return false;
    const Vector2d& n = normals[v];
    if (n.squaredNorm() == 0) return true;
    const double c = n.dot(m.NormalAt(vertices[v]));
    return (m.orient == 0 ? std::abs(c) : c) >= cos_max;
  };
  // Unassigned inliers of m, searched in the fine cells near it; their mean distance.
  auto inliers_of = [&](const Model& m, std::vector<int>& in) {
    in.clear();
    double sum = 0;
    const double reach = tol + fine.cell() * M_SQRT1_2;
    for (size_t k = 0; k < fine.size(); ++k) {
      if (m.Distance(fine.centre(k)) > reach) continue;
      for (int v : fine.members(k)) {
        if (model_of[v] >= 0 || !accepts(m, v)) continue;
        in.push_back(v);
        sum += m.Distance(vertices[v]);
      }
    }
    return in.empty() ? 0.0 : sum / static_cast<double>(in.size());
  };

  // ---- Step 1: models one by one.
  std::vector<int> pool, near, in, best_in;
  while (true) {
    pool.clear();
    for (int v : ids) {
      if (model_of[v] < 0) pool.push_back(v);
    }
    if (pool.size() < static_cast<size_t>(options.min_inliers)) break;
    Model best;
    double best_err = std::numeric_limits<double>::infinity();
    best_in.clear();
    for (int it = 0; it < options.iterations; ++it) {
      const int a = pool[random_below(pool.size())];
      near.clear();
      const auto [cx, cy] = coarse.Cell(vertices[a]);
      for (int64_t dx = -1; dx <= 1; ++dx) {
        for (int64_t dy = -1; dy <= 1; ++dy) {
          const std::vector<int>* cell = coarse.At(cx + dx, cy + dy);
          if (cell == nullptr) continue;
          for (int v : *cell) {
            if (v != a && model_of[v] < 0 &&
                (vertices[v] - vertices[a]).norm() <= options.neighbourhood_m) {
              near.push_back(v);
            }
          }
        }
      }
      if (near.size() < 2) continue;
      const int b = near[random_below(near.size())];
      int c = near[random_below(near.size())];
      if (c == b) c = near[(std::find(near.begin(), near.end(), b) - near.begin() + 1) % near.size()];
      if (c == b) continue;
      const std::vector<int> three = {a, b, c};
      Model candidates[2];
      int n_candidates = 0;
      candidates[n_candidates] = FitLine(vertices, three);
      Orient(candidates[n_candidates], vertices, normals, three);
      ++n_candidates;
      Model circle;
      if (CircleThrough(vertices[a], vertices[b], vertices[c], &circle) &&
          circle.r >= options.min_radius_m && circle.r <= options.max_radius_m) {
        Orient(circle, vertices, normals, three);
        candidates[n_candidates++] = circle;
      }
      for (int k = 0; k < n_candidates; ++k) {
        const double err = inliers_of(candidates[k], in);
        if (in.size() < static_cast<size_t>(options.min_inliers)) continue;
        if (err < best_err || (err == best_err && in.size() > best_in.size())) {
          best_err = err;
          best = candidates[k];
          best_in = in;
        }
      }
    }
    if (best_in.empty()) break;
    // Refit to the inliers and take them again; keep the first fit if the refit loses too many.
    Model refit = best;
    bool ok = true;
    if (best.kind == WallCurve::Kind::kLine) {
      refit = FitLine(vertices, best_in);
    } else {
      ok = FitCircle(vertices, best_in, &refit) && refit.r >= options.min_radius_m &&
           refit.r <= options.max_radius_m;
    }
    if (ok) {
      Orient(refit, vertices, normals, best_in);
      inliers_of(refit, in);
      if (in.size() >= static_cast<size_t>(options.min_inliers)) {
        best = refit;
        best_in = in;
      }
    }
    for (int v : best_in) model_of[v] = static_cast<int>(models.size());
    models.push_back(best);
  }
  rep.models_found = models.size();

  // ---- Step 2: components along B shorter than min_component_m are dropped.
  {
    UnionFind<int> uf(nv);
    for (const auto& e : boundary) {
      if (model_of[e[0]] >= 0 && model_of[e[0]] == model_of[e[1]]) uf.Union(e[0], e[1]);
    }
    absl::flat_hash_map<int, Eigen::AlignedBox2d> extent;
    for (int v : ids) {
      if (model_of[v] >= 0) extent[uf.Find(v)].extend(vertices[v]);
    }
    for (int v : ids) {
      if (model_of[v] < 0) continue;
      if (extent[uf.Find(v)].diagonal().norm() < options.min_component_m) {
        model_of[v] = -1;
        ++rep.dropped_short;
      }
    }
  }

  // ---- Step 3: unassigned samples join a neighbour's model, layer by layer.
  while (true) {
    std::vector<std::pair<int, int>> joins;
    for (int v : ids) {
      if (model_of[v] >= 0) continue;
      int best_model = -1;
      double best_d = snap;
      for (int w : adjacent[v]) {
        const int m = model_of[w];
        if (m < 0) continue;
        const double d = models[m].Distance(vertices[v]);
        if (d < best_d || (d == best_d && m < best_model)) {
          best_d = d;
          best_model = m;
        }
      }
      if (best_model >= 0) joins.emplace_back(v, best_model);
    }
    if (joins.empty()) break;
    for (const auto& [v, m] : joins) model_of[v] = m;
    rep.snapped += joins.size();
  }

  // ---- Step 4: onto the models; sharp corners between two lines.
  for (int v : ids) {
    if (model_of[v] >= 0) out.fitted[v] = models[model_of[v]].Project(vertices[v]);
  }
  std::vector<char> cornered(nv, 0);
  const double sin_min = std::sin(20.0 * M_PI / 180.0);
  for (const auto& e : boundary) {
    const int a = e[0], b = e[1];
    const int ma = model_of[a], mb = model_of[b];
    if (ma < 0 || mb < 0 || ma == mb) continue;
    const Model &la = models[ma], &lb = models[mb];
    if (la.kind != WallCurve::Kind::kLine || lb.kind != WallCurve::Kind::kLine) continue;
    const double cross = la.d.x() * lb.d.y() - la.d.y() * lb.d.x();
    if (std::abs(cross) < sin_min) continue;
    // la.p + s·la.d = lb.p + t·lb.d.
    const Vector2d w = lb.p - la.p;
    const double s = (w.x() * lb.d.y() - w.y() * lb.d.x()) / cross;
    const Vector2d x = la.p + s * la.d;
    const double da = (x - out.fitted[a]).norm(), db = (x - out.fitted[b]).norm();
    const int v = da <= db ? a : b;
    if (std::min(da, db) > corner_snap || cornered[v]) continue;
    out.fitted[v] = x;
    cornered[v] = 1;
    ++rep.corners;
  }

  // The curves that kept samples, renumbered.
  std::vector<int> renumber(models.size(), -1);
  for (int v : ids) {
    const int m = model_of[v];
    if (m < 0) continue;
    if (renumber[m] < 0) {
      renumber[m] = static_cast<int>(out.curves.size());
      WallCurve c;
      c.kind = models[m].kind;
      c.point = models[m].p;
      c.direction = models[m].d;
      c.radius = models[m].r;
      out.curves.push_back(c);
    }
    model_of[v] = renumber[m];
    ++out.curves[renumber[m]].samples;
  }
  double moved = 0;
  size_t n_moved = 0;
  for (int v : ids) {
    if (model_of[v] < 0) continue;
    ++rep.assigned;
    const double d = (out.fitted[v] - vertices[v]).norm();
    if (d > 0) {
      moved += d;
      ++n_moved;
    }
  }
  rep.mean_move_m = n_moved > 0 ? moved / static_cast<double>(n_moved) : 0;
  for (const WallCurve& c : out.curves) {
    (c.kind == WallCurve::Kind::kLine ? rep.lines : rep.circles) += 1;
  }
  if (report != nullptr) *report = rep;
  return out;
}

}  // namespace carvemap
