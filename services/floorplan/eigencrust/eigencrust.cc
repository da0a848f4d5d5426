#include "services/floorplan/eigencrust/eigencrust.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <numeric>
#include <tuple>
#include <utility>

#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Spectra/MatOp/SparseSymMatProd.h>
#include <Spectra/SymGEigsShiftSolver.h>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/union_find.h"
#include "services/floorplan/orient_2d.h"
#include "services/floorplan/rooms/delaunay_mesh.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

using floorplan_internal::Orient;

struct Circle {
  Vector2d c = Vector2d::Zero();
  double r = 0;
};

// cos φ for the angle φ at which two circles intersect, in [−1, 1]: 1 when they only touch
// from outside (φ = 0), −1 when they coincide (φ = π); clamped for circles that miss each other
// or nest (Kolluri et al.: "If φ is close to 180°, u and v are likely to lie on the same side").
double CosIntersection(const Circle& a, const Circle& b) {
  const double d2 = (a.c - b.c).squaredNorm();
  return std::clamp((d2 - a.r * a.r - b.r * b.r) / (2 * a.r * b.r), -1.0, 1.0);
}

// Eq 3.2.
double PositiveWeight(const Circle& a, const Circle& b) {
  return std::exp(4 - 4 * CosIntersection(a, b));
}
// Eq 3.1 (a negative number); sin θ_i = |n_i · d| with d the unit direction across the shared
// segment (see the header).
double NegativeWeight(const Circle& a, const Circle& b, const Vector2d& n1, const Vector2d& n2,
                      const Vector2d& d) {
  const double s1 = std::abs(n1.dot(d)), s2 = std::abs(n2.dot(d));
  return -std::exp(4 + 4 * CosIntersection(a, b) + 2 * s1 + 2 * s2);
}

uint64_t PairKey(int a, int b) {
  const auto lo = static_cast<uint64_t>(std::min(a, b)), hi = static_cast<uint64_t>(std::max(a, b));
  return (lo << 32) | hi;
}

// The triangulation as flat arrays, with the walks of §3.2.2.
struct Mesh {
  const std::vector<Vector2d>* pts = nullptr;
  const std::vector<std::array<int, 3>>* tri = nullptr;
  const std::vector<std::array<int, 3>>* nbr = nullptr;

  const Vector2d& P(int v) const { return (*pts)[v]; }
  bool InClosed(int f, const Vector2d& p) const {
    const auto& t = (*tri)[f];
    return Orient(P(t[0]), P(t[1]), p) >= 0 && Orient(P(t[1]), P(t[2]), p) >= 0 &&
           Orient(P(t[2]), P(t[0]), p) >= 0;
  }
  Vector2d Centroid(int f) const {
    const auto& t = (*tri)[f];
    return (P(t[0]) + P(t[1]) + P(t[2])) / 3.0;
  }

  // Walks the segment a → b from face `f` (which holds a, closed), calling visit(face) for each
  // face on the way from the one holding `from` (a point of the segment; a itself when null) to
  // the one holding b; returns the face holding b, −1 when the segment leaves the triangulation,
  // −2 when the walk cannot go on (a on f's boundary and the segment leaving f away from it). A
  // vertex on the line counts as left of it (a symbolic perturbation of the line), so every face
  // has one exit edge and the walk needs no special cases. Each step costs two orientation
  // tests: the new vertex's side of the line, and b against the exit edge.
  template <typename Visit>
  int Walk(int f, const Vector2d& a, const Vector2d& b, Visit&& visit,
           const Vector2d* from = nullptr) const {
    bool counting = from == nullptr;
    const auto* t = &(*tri)[f];
    bool left[3];
    for (int j = 0; j < 3; ++j) left[j] = Orient(a, b, P((*t)[j])) >= 0;
    for (size_t steps = 0, limit = 4 * tri->size() + 8; steps < limit; ++steps) {
      int exit = -1;
      for (int i = 0; i < 3; ++i) {
        if (!left[(i + 1) % 3] && left[(i + 2) % 3]) exit = i;
      }
      if (exit < 0) {
        if (counting || InClosed(f, *from)) visit(f);
        return InClosed(f, b) ? f : -2;
      }
      // The segment leaves f through edge u → w (f on its left); a point of the segment is in
      // f (or behind it) when it is on the left of that edge.
      const int u = (*t)[(exit + 1) % 3], w = (*t)[(exit + 2) % 3];
      if (!counting) counting = Orient(P(u), P(w), *from) >= 0;
      if (counting) visit(f);
      if (Orient(P(u), P(w), b) >= 0) return f;
      const int g = (*nbr)[f][exit];
      if (g < 0) return -1;
      const auto* tg = &(*tri)[g];
      for (int j = 0; j < 3; ++j) {
        const int v = (*tg)[j];
        left[j] = v == u ? false : v == w ? true : Orient(a, b, P(v)) >= 0;
      }
      f = g;
      t = tg;
    }
    return -2;
  }

  int Locate(const Vector2d& p, int hint) const {
    if (tri->empty()) return -1;
    if (hint < 0 || hint >= static_cast<int>(tri->size())) hint = 0;
    // From the centroid (strictly inside its face) the walk never stalls.
    return std::max(-1, Walk(hint, Centroid(hint), p, [](int) {}));
  }
};


// Spectra operator y = (L − σD)⁻¹ x by Eigen's sparse LDLᵀ: L − σD is positive definite for
// σ < 0 (L = D − W is a signed graph Laplacian, positive semi-definite), so Cholesky-type
// factorisation is exact and cheaper than the LU Spectra's own SymShiftInvert uses.
class LdltShiftInvert {
 public:
  using Scalar = double;
  LdltShiftInvert(const Eigen::SparseMatrix<double>& a, const Eigen::SparseMatrix<double>& b)
      : a_(a), b_(b) {}
  [[nodiscard]] Eigen::Index rows() const { return a_.rows(); }
  [[nodiscard]] Eigen::Index cols() const { return a_.cols(); }
  void set_shift(double sigma) {
    solver_.compute(a_ - sigma * b_);
    if (solver_.info() != Eigen::Success) {
      throw std::runtime_error("sparse LDLT factorisation of L - sigma D failed");
    }
  }
  void perform_op(const double* x_in, double* y_out) const {
    Eigen::Map<const Eigen::VectorXd> x(x_in, a_.rows());
    Eigen::Map<Eigen::VectorXd> y(y_out, a_.rows());
    y.noalias() = solver_.solve(x);
  }

 private:
  const Eigen::SparseMatrix<double>& a_;
  const Eigen::SparseMatrix<double>& b_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver_;
};

struct Edge {
  int a, b;
  double w;
};

// Whether an eigenvector splits the nodes (entries of both signs), not a constant-sign vector.
bool Splits(const Eigen::VectorXd& x) {
  const double tol = 1e-9 * x.cwiseAbs().maxCoeff();
  bool pos = false, neg = false;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    pos |= x[i] > tol;
    neg |= x[i] < -tol;
  }
  return pos && neg;
}

// L x = λ D x for one connected graph of m nodes (edges with local indices): the eigenvector of
// the smallest eigenvalue that splits the nodes (the dissertation's "smallest non-zero eigenvalue":
// for a graph of positive edges only, λ = 0 belongs to the constant vector). Dense for small
// graphs, Spectra's shift-invert generalized solver otherwise.
absl::StatusOr<std::pair<Eigen::VectorXd, double>> SmallestSplittingEigenvector(
    int m, const std::vector<Edge>& edges) {
  std::vector<double> diag(m, 0.0);
  for (const Edge& e : edges) {
    diag[e.a] += std::abs(e.w);
    diag[e.b] += std::abs(e.w);
  }
  if (m <= 300) {
    Eigen::MatrixXd l = Eigen::MatrixXd::Zero(m, m), d = Eigen::MatrixXd::Zero(m, m);
    for (const Edge& e : edges) {
      l(e.a, e.b) -= e.w;
      l(e.b, e.a) -= e.w;
    }
    for (int i = 0; i < m; ++i) l(i, i) = d(i, i) = diag[i];
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> eig(l, d);
    if (eig.info() != Eigen::Success) {
      return absl::InternalError("eigencrust: dense generalized eigensolver failed");
    }
    for (int k = 0; k < m; ++k) {
      if (Splits(eig.eigenvectors().col(k))) {
        return std::pair(Eigen::VectorXd(eig.eigenvectors().col(k)), eig.eigenvalues()(k));
      }
    }
    return std::pair(Eigen::VectorXd(eig.eigenvectors().col(0)), eig.eigenvalues()(0));
  }
  std::vector<Eigen::Triplet<double>> lt, dt;
  lt.reserve(2 * edges.size() + m);
  for (const Edge& e : edges) {
    lt.emplace_back(e.a, e.b, -e.w);
    lt.emplace_back(e.b, e.a, -e.w);
  }
  for (int i = 0; i < m; ++i) {
    lt.emplace_back(i, i, diag[i]);
    dt.emplace_back(i, i, diag[i]);
  }
  Eigen::SparseMatrix<double> l(m, m), d(m, m);
  l.setFromTriplets(lt.begin(), lt.end());
  d.setFromTriplets(dt.begin(), dt.end());
  try {
    // The eigenvalues of L x = λ D x lie in [0, 2]; a shift just below 0 finds the smallest.
    // It must be small against their spacing (weakly joined parts of a building give
    // eigenvalues of 1e-6 and below), else ν = 1/(λ − σ) bunches them and Lanczos stalls.
    constexpr double kSigma = -1e-10;
    LdltShiftInvert op(l, d);
    Spectra::SparseSymMatProd<double> bop(d);
    const int nev = 2;
    const int ncv = std::min(m, 32);
    Spectra::SymGEigsShiftSolver<LdltShiftInvert, Spectra::SparseSymMatProd<double>,
                                 Spectra::GEigsMode::ShiftInvert>
        solver(op, bop, nev, ncv, kSigma);
    solver.init();
    const Eigen::Index converged =
        solver.compute(Spectra::SortRule::LargestMagn, 5000, 1e-8, Spectra::SortRule::SmallestAlge);
    if (converged < 1) {
      return absl::InternalError(absl::StrCat(
          "eigencrust: Spectra's generalized eigensolver did not converge (", m, " nodes)"));
    }
    const Eigen::VectorXd values = solver.eigenvalues();
    const Eigen::MatrixXd vectors = solver.eigenvectors();
    for (Eigen::Index k = 0; k < values.size(); ++k) {
      if (Splits(vectors.col(k))) return std::pair(Eigen::VectorXd(vectors.col(k)), values(k));
    }
    return std::pair(Eigen::VectorXd(vectors.col(0)), values(0));
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("eigencrust: eigensolver: ", e.what()));
  }
}

// Labels the nodes of a graph whose nodes 0 (outside) and 1 (inside) are the super-nodes (either
// may have no edges): each connected component that holds a super-node is solved; its nodes are
// inside when their sign is the inside super-node's (or the opposite of the outside one's).
// Returns per node 1 inside, 0 outside, −1 unsolved; `eigenvalue` of the largest component.
absl::StatusOr<std::vector<int8_t>> LabelBySpectrum(int n, const std::vector<Edge>& edges,
                                                    double* eigenvalue, size_t* solved) {
  std::vector<int8_t> label(n, -1);
  label[0] = 0;
  label[1] = 1;
  UnionFind<int> uf(n);
  for (const Edge& e : edges) uf.Union(e.a, e.b);
  // Components of the super-nodes (one or two).
  std::vector<int> roots = {uf.Find(0)};
  if (uf.Find(1) != roots[0]) roots.push_back(uf.Find(1));
  size_t largest = 0;
  *solved = 0;
  for (int root : roots) {
    std::vector<int> local(n, -1), nodes;
    for (int i = 0; i < n; ++i) {
      if (uf.Find(i) == root) {
        local[i] = static_cast<int>(nodes.size());
        nodes.push_back(i);
      }
    }
    if (nodes.size() < 2) continue;  // a super-node alone
    std::vector<Edge> le;
    for (const Edge& e : edges) {
      if (local[e.a] >= 0 && local[e.b] >= 0) le.push_back({local[e.a], local[e.b], e.w});
    }
    absl::StatusOr<std::pair<Eigen::VectorXd, double>> sol =
        SmallestSplittingEigenvector(static_cast<int>(nodes.size()), le);
    if (!sol.ok()) return sol.status();
    const Eigen::VectorXd& x = sol->first;
    double ref = 0;
    if (local[1] >= 0) ref += x[local[1]];
    if (local[0] >= 0) ref -= x[local[0]];
    for (size_t i = 0; i < nodes.size(); ++i) {
      if (nodes[i] <= 1) continue;
      label[nodes[i]] = x[static_cast<Eigen::Index>(i)] * ref > 0 ? 1 : 0;
    }
    *solved += nodes.size();
    if (nodes.size() > largest) {
      largest = nodes.size();
      *eigenvalue = sol->second;
    }
  }
  return label;
}

// Edges of a contracted graph: parallel edges add up, self-loops vanish.
void AddEdge(absl::flat_hash_map<uint64_t, double>& edges, int a, int b, double w) {
  if (a == b) return;
  edges[PairKey(a, b)] += w;
}
std::vector<Edge> EdgeList(const absl::flat_hash_map<uint64_t, double>& map) {
  std::vector<Edge> out;
  out.reserve(map.size());
  for (const auto& [key, w] : map) {
    if (w == 0) continue;
    out.push_back({static_cast<int>(key >> 32), static_cast<int>(key & 0xFFFFFFFFu), w});
  }
  // Deterministic order (hash maps iterate in an unspecified order).
  std::sort(out.begin(), out.end(),
            [](const Edge& x, const Edge& y) { return std::tie(x.a, x.b) < std::tie(y.a, y.b); });
  return out;
}

}  // namespace

absl::Status EigencrustOptions::Validate() const {
  auto bad = [](const char* name, double v) {
    return absl::InvalidArgumentError(absl::StrCat("eigencrust: bad ", name, " = ", v));
  };
  if (!std::isfinite(smoothing_distance_m) || smoothing_distance_m < 0) {
    return bad("smoothing_distance_m", smoothing_distance_m);
  }
  if (!std::isfinite(smoothing_across_spacings) || smoothing_across_spacings < 0) {
    return bad("smoothing_across_spacings", smoothing_across_spacings);
  }
  if (!std::isfinite(smoothing_max_angle_deg) || smoothing_max_angle_deg < 0 ||
      smoothing_max_angle_deg > 180) {
    return bad("smoothing_max_angle_deg", smoothing_max_angle_deg);
  }
  if (!std::isfinite(box_margin_m) || box_margin_m <= 0) return bad("box_margin_m", box_margin_m);
  if (min_sight_lines < 1) return bad("min_sight_lines", min_sight_lines);
  if (!std::isfinite(sight_middle_fraction) || sight_middle_fraction <= 0 ||
      sight_middle_fraction > 1) {
    return bad("sight_middle_fraction", sight_middle_fraction);
  }
  if (min_union_triangles < 0) return bad("min_union_triangles", min_union_triangles);
  return absl::OkStatus();
}

absl::StatusOr<WallSampleSet> SmoothWallSamples(const WallSampleSet& samples,
                                                const EigencrustOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = samples.Validate(); !s.ok()) return s;
  WallSampleSet out = samples;
  const double along = options.smoothing_distance_m;
  const double across = options.smoothing_across_spacings * samples.spacing_m;
  const double cos_max = std::cos(options.smoothing_max_angle_deg * M_PI / 180.0);
  const double cell = std::max({along, across, 1e-3});
  auto cell_of = [&](const Vector2d& p) {
    return std::pair(static_cast<int>(std::floor(p.x() / cell)),
                     static_cast<int>(std::floor(p.y() / cell)));
  };
  auto bucket_key = [](int cx, int cy) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(cx)) << 32) | static_cast<uint32_t>(cy);
  };
  // Buckets of the original positions (the smoothing reads those, not the moved ones).
  absl::flat_hash_map<uint64_t, std::vector<int>> buckets;
  for (size_t i = 0; i < samples.samples.size(); ++i) {
    const auto [cx, cy] = cell_of(samples.samples[i].position);
    buckets[bucket_key(cx, cy)].push_back(static_cast<int>(i));
  }
  for (size_t i = 0; i < samples.samples.size(); ++i) {
    const WallSample& s = samples.samples[i];
    if (s.normal.squaredNorm() == 0) continue;  // no direction to smooth along
    const Vector2d t(-s.normal.y(), s.normal.x());
    const auto [cx, cy] = cell_of(s.position);
    Vector2d sum = Vector2d::Zero();
    int n = 0;
    // The neighbourhood (|d·n| ≤ along, |d·t| ≤ across) reaches √2 cells from s.
    for (int dx = -2; dx <= 2; ++dx) {
      for (int dy = -2; dy <= 2; ++dy) {
        const auto it = buckets.find(bucket_key(cx + dx, cy + dy));
        if (it == buckets.end()) continue;
        for (int j : it->second) {
          const WallSample& q = samples.samples[j];
          const Vector2d d = q.position - s.position;
          if (std::abs(d.dot(s.normal)) > along || std::abs(d.dot(t)) > across) continue;
          if (q.normal.dot(s.normal) < cos_max) continue;
          sum += q.position;
          ++n;
        }
      }
    }
    if (n > 0) out.samples[i].position = sum / n;
  }
  return out;
}

bool EigencrustLabeling::InsideAt(const Eigen::Vector2d& p, int* hint) const {
  const int f = Locate(p, hint != nullptr ? *hint : -1);
  if (f < 0) return false;
  if (hint != nullptr) *hint = f;
  return inside[f] != 0;
}

int EigencrustLabeling::Locate(const Eigen::Vector2d& p, int hint) const {
  Mesh m{&vertices, &triangles, &neighbours};
  return m.Locate(p, hint);
}

absl::StatusOr<EigencrustLabeling> LabelEigencrust(const WallSampleSet& samples,
                                                   const EigencrustOptions& options,
                                                   EigencrustReport* report) {
  using Clock = std::chrono::steady_clock;
  Clock::time_point t0 = Clock::now();
  auto lap = [&t0](double& seconds) {
    const Clock::time_point now = Clock::now();
    seconds = std::chrono::duration<double>(now - t0).count();
    t0 = now;
  };
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = samples.Validate(); !s.ok()) return s;
  EigencrustReport rep;
  EigencrustLabeling out;

  // Distinct positions in (x, y) order, as LabelRooms numbers them; a repeated position keeps
  // the sum of its samples' normals (normalised; zero if they cancel) and the union of poses.
  std::vector<uint32_t> order(samples.samples.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    const Vector2d &p = samples.samples[a].position, &q = samples.samples[b].position;
    return std::tie(p.x(), p.y()) < std::tie(q.x(), q.y());
  });
  std::vector<std::vector<uint32_t>> vposes;
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    Vector2d normal = Vector2d::Zero();
    std::vector<uint32_t> poses;
    while (j < order.size() &&
           samples.samples[order[j]].position == samples.samples[order[i]].position) {
      const WallSample& s = samples.samples[order[j]];
      normal += s.normal;
      poses.insert(poses.end(), s.poses.begin(), s.poses.end());
      ++j;
    }
    std::sort(poses.begin(), poses.end());
    poses.erase(std::unique(poses.begin(), poses.end()), poses.end());
    const double nn = normal.norm();
    out.vertices.push_back(samples.samples[order[i]].position);
    out.normals.push_back(nn > 1e-9 ? Vector2d(normal / nn) : Vector2d::Zero());
    vposes.push_back(std::move(poses));
    i = j;
  }
  const int ns = static_cast<int>(out.vertices.size());
  out.samples = out.vertices.size();
  rep.samples = out.samples;
  if (ns < 3) {
    return absl::InvalidArgumentError(
        absl::StrCat("eigencrust: need at least 3 distinct wall samples, got ", ns));
  }
  // The box (§3.2.2: "plus four bounding box corners") around samples and poses.
  Eigen::AlignedBox2d box;
  for (const Vector2d& p : out.vertices) box.extend(p);
  for (const Vector2d& p : samples.poses) box.extend(p);
  const double mg = options.box_margin_m;
  for (const Vector2d& c : {Vector2d(box.min().x() - mg, box.min().y() - mg),
                            Vector2d(box.max().x() + mg, box.min().y() - mg),
                            Vector2d(box.max().x() + mg, box.max().y() + mg),
                            Vector2d(box.min().x() - mg, box.max().y() + mg)}) {
    out.vertices.push_back(c);
    out.normals.push_back(Vector2d::Zero());
  }

  {
    absl::StatusOr<floorplan_internal::DelaunayMesh> dt =
        floorplan_internal::DelaunayMesh::Build(out.vertices, "eigencrust");
    if (!dt.ok()) return dt.status();
    out.triangles = dt->triangles();
    out.neighbours = dt->neighbours();
  }
  const int nf = static_cast<int>(out.triangles.size());
  rep.triangles = static_cast<size_t>(nf);
  const Mesh mesh{&out.vertices, &out.triangles, &out.neighbours};

  std::vector<Circle> circle(nf);
  {
    const std::vector<Vector2d> centres = floorplan_internal::Circumcentres(out.vertices, out.triangles);
    for (int f = 0; f < nf; ++f) {
      circle[f].c = centres[f];
      circle[f].r = (out.vertices[out.triangles[f][0]] - circle[f].c).norm();
    }
  }

  lap(rep.seconds_triangulation);

  // ---- Known labels (§3.2.2).
  std::vector<char> known_out(nf, 0), known_in(nf, 0);
  for (int f = 0; f < nf; ++f) {
    for (int v : out.triangles[f]) known_out[f] |= v >= ns ? 1 : 0;
  }
  const size_t np = samples.poses.size();
  std::vector<int> pose_face(np, -1);
  {
    int hint = 0;
    for (size_t i = 0; i < np; ++i) {
      pose_face[i] = mesh.Locate(samples.poses[i], hint);
      if (pose_face[i] >= 0) {
        hint = pose_face[i];
        known_in[pose_face[i]] = 1;  // "all triangles that contain a pose position"
      }
    }
  }
  // Scanner-to-sample segments: count the triangles the middle part of each crosses.
  {
    std::vector<std::vector<int>> seen_from(np);
    for (int v = 0; v < ns; ++v) {
      for (uint32_t p : vposes[v]) seen_from[p].push_back(v);
    }
    std::vector<uint16_t> count(nf, 0);
    const double lo = 0.5 * (1 - options.sight_middle_fraction);
    const double hi = 0.5 * (1 + options.sight_middle_fraction);
    for (size_t p = 0; p < np; ++p) {
      if (pose_face[p] < 0) continue;
      const Vector2d& q = samples.poses[p];
      for (int v : seen_from[p]) {
        const Vector2d d = out.vertices[v] - q;
        if (d.squaredNorm() == 0) continue;
        ++rep.sight_lines;
        const Vector2d a = q + lo * d, b = q + hi * d;
        mesh.Walk(
            pose_face[p], q, b,
            [&](int f) {
              if (count[f] < std::numeric_limits<uint16_t>::max()) ++count[f];
            },
            &a);
      }
    }
    for (int f = 0; f < nf; ++f) {
      if (count[f] >= options.min_sight_lines) known_in[f] = 1;
    }
  }
  // The path between consecutive poses that both saw samples.
  {
    std::vector<char> contributed(np, 0);
    for (int v = 0; v < ns; ++v) {
      for (uint32_t p : vposes[v]) contributed[p] = 1;
    }
    size_t next_break = 0;
    for (size_t i = 1; i < np; ++i) {
      while (next_break < samples.path_breaks.size() && samples.path_breaks[next_break] < i) {
        ++next_break;
      }
      if (next_break < samples.path_breaks.size() && samples.path_breaks[next_break] == i) continue;
      if (!contributed[i - 1] || !contributed[i] || pose_face[i - 1] < 0) continue;
      mesh.Walk(pose_face[i - 1], samples.poses[i - 1], samples.poses[i],
                [&](int f) { known_in[f] = 1; });
    }
  }
  for (int f = 0; f < nf; ++f) {
    if (known_in[f] && known_out[f]) {
      ++rep.conflicts;
      known_in[f] = 0;
    }
    rep.known_inside += known_in[f] ? 1 : 0;
    rep.known_outside += known_out[f] ? 1 : 0;
  }

  lap(rep.seconds_known);

  // ---- Poles (Amenta et al.): u = the incident triangle with the farthest circumcentre (the
  // circumradius is the distance from the sample), v = the farthest on the other side of s.
  std::vector<int> pole_u(ns, -1), pole_v(ns, -1);
  for (int f = 0; f < nf; ++f) {
    for (int v : out.triangles[f]) {
      if (v < ns && (pole_u[v] < 0 || circle[f].r > circle[pole_u[v]].r)) pole_u[v] = f;
    }
  }
  for (int f = 0; f < nf; ++f) {
    for (int v : out.triangles[f]) {
      if (v >= ns || pole_u[v] == f) continue;
      const Vector2d& s = out.vertices[v];
      if ((circle[f].c - s).dot(circle[pole_u[v]].c - s) >= 0) continue;
      if (pole_v[v] < 0 || circle[f].r > circle[pole_v[v]].r) pole_v[v] = f;
    }
  }
  std::vector<char> is_pole(nf, 0);
  for (int v = 0; v < ns; ++v) {
    if (pole_u[v] >= 0) is_pole[pole_u[v]] = 1;
    if (pole_v[v] >= 0) is_pole[pole_v[v]] = 1;
  }
  for (char c : is_pole) rep.poles += c ? 1 : 0;

  // ---- The pole graph G, then G' with the known poles contracted (nodes 0 out, 1 in).
  absl::flat_hash_map<uint64_t, double> negative, positive;
  for (int v = 0; v < ns; ++v) {
    const int u = pole_u[v], w = pole_v[v];
    if (u < 0 || w < 0) continue;
    const Vector2d d = (circle[u].c - circle[w].c).normalized();
    const double weight = NegativeWeight(circle[u], circle[w], out.normals[v], out.normals[v], d);
    auto [it, inserted] = negative.try_emplace(PairKey(u, w), weight);
    if (!inserted) it->second = std::min(it->second, weight);  // the stronger one
  }
  for (int f = 0; f < nf; ++f) {
    for (int i = 0; i < 3; ++i) {
      const int g = out.neighbours[f][i];
      if (g < f) continue;  // each Delaunay edge once (g < 0: hull edge)
      const int s1 = out.triangles[f][(i + 1) % 3], s2 = out.triangles[f][(i + 2) % 3];
      if (s1 >= ns || s2 >= ns) continue;
      for (int p : {pole_u[s1], pole_v[s1]}) {
        for (int q : {pole_u[s2], pole_v[s2]}) {
          if (p < 0 || q < 0 || p == q) continue;
          const uint64_t key = PairKey(p, q);
          if (negative.contains(key)) continue;
          positive.try_emplace(key, PositiveWeight(circle[p], circle[q]));
        }
      }
    }
  }
  rep.negative_edges = negative.size();
  rep.positive_edges = positive.size();
  std::vector<int> pole_node(nf, -1);
  int n_pole_nodes = 2;
  for (int f = 0; f < nf; ++f) {
    if (!is_pole[f]) continue;
    pole_node[f] = known_out[f] ? 0 : known_in[f] ? 1 : n_pole_nodes++;
  }
  std::vector<int8_t> pole_label;
  {
    absl::flat_hash_map<uint64_t, double> contracted;
    for (const auto* map : {&negative, &positive}) {
      for (const auto& [key, w] : *map) {
        AddEdge(contracted, pole_node[static_cast<int>(key >> 32)],
                pole_node[static_cast<int>(key & 0xFFFFFFFFu)], w);
      }
    }
    absl::StatusOr<std::vector<int8_t>> labels = LabelBySpectrum(
        n_pole_nodes, EdgeList(contracted), &rep.pole_eigenvalue, &rep.pole_nodes_solved);
    if (!labels.ok()) return labels.status();
    pole_label = *std::move(labels);
  }

  lap(rep.seconds_poles);

  // ---- The non-pole graph H: labelled poles and known triangles contracted into the two
  // super-nodes; every other triangle a node.
  std::vector<int> node(nf, -1);
  int n_nodes = 2;
  for (int f = 0; f < nf; ++f) {
    if (known_out[f]) {
      node[f] = 0;
    } else if (known_in[f]) {
      node[f] = 1;
    } else if (is_pole[f] && pole_label[pole_node[f]] >= 0) {
      node[f] = pole_label[pole_node[f]];
    } else {
      node[f] = n_nodes++;
    }
  }
  rep.nonpole_nodes = static_cast<size_t>(n_nodes - 2);
  std::vector<int8_t> label(nf, 0);
  {
    absl::flat_hash_map<uint64_t, double> edges;
    for (int f = 0; f < nf; ++f) {
      for (int i = 0; i < 3; ++i) {
        const int g = out.neighbours[f][i];
        if (g < f) continue;
        const int a = node[f], b = node[g];
        if (a == b) continue;
        if (a <= 1 && b <= 1) {  // between the two super-nodes: eq 3.1 across the shared edge
          const int s1 = out.triangles[f][(i + 1) % 3], s2 = out.triangles[f][(i + 2) % 3];
          const Vector2d e = out.vertices[s2] - out.vertices[s1];
          const Vector2d d = Vector2d(-e.y(), e.x()).normalized();
          AddEdge(edges, a, b,
                  NegativeWeight(circle[f], circle[g], out.normals[s1], out.normals[s2], d));
        } else {
          AddEdge(edges, a, b, PositiveWeight(circle[f], circle[g]));
        }
      }
    }
    size_t solved = 0;
    absl::StatusOr<std::vector<int8_t>> labels =
        LabelBySpectrum(n_nodes, EdgeList(edges), &rep.nonpole_eigenvalue, &solved);
    if (!labels.ok()) return labels.status();
    for (int f = 0; f < nf; ++f) label[f] = (*labels)[node[f]] == 1 ? 1 : 0;
  }
  for (int8_t l : label) rep.inside_before_cleanup += l ? 1 : 0;

  lap(rep.seconds_nonpoles);

  // ---- §3.2.3 clean-up.
  auto label_of = [&](int g) { return g < 0 ? 0 : label[g]; };  // beyond the box: outside
  if (options.min_union_triangles > 0) {
    for (int pass_label : {1, 0}) {  // inside unions first, then outside ones
      UnionFind<int> uf(nf);
      for (int f = 0; f < nf; ++f) {
        for (int g : out.neighbours[f]) {
          if (g > f && label[g] == label[f]) uf.Union(f, g);
        }
      }
      std::vector<int> size(nf, 0);
      for (int f = 0; f < nf; ++f) ++size[uf.Find(f)];
      for (int f = 0; f < nf; ++f) {
        if (label[f] == pass_label && size[uf.Find(f)] < options.min_union_triangles) {
          label[f] = static_cast<int8_t>(1 - pass_label);
          ++rep.flipped_unions;
        }
      }
    }
  }
  if (options.remove_protrusions) {
    for (int pass_label : {1, 0}) {
      std::vector<int> flip;
      for (int f = 0; f < nf; ++f) {
        if (label[f] != pass_label) continue;
        int same = 0, same_edge = -1, shortest = 0;
        double shortest_len = std::numeric_limits<double>::infinity();
        for (int i = 0; i < 3; ++i) {
          const double len = (out.vertices[out.triangles[f][(i + 1) % 3]] -
                              out.vertices[out.triangles[f][(i + 2) % 3]])
                                 .squaredNorm();
          if (len < shortest_len) {
            shortest_len = len;
            shortest = i;
          }
          if (label_of(out.neighbours[f][i]) == pass_label) {
            ++same;
            same_edge = i;
          }
        }
        if (same == 1 && same_edge == shortest) flip.push_back(f);
      }
      for (int f : flip) label[f] = static_cast<int8_t>(1 - pass_label);
      rep.flipped_protrusions += flip.size();
    }
  }

  out.inside.assign(label.begin(), label.end());
  for (int f = 0; f < nf; ++f) {
    if (!label[f]) continue;
    ++rep.inside;
    for (int i = 0; i < 3; ++i) {
      if (label_of(out.neighbours[f][i]) == 0) {
        out.boundary.push_back({out.triangles[f][(i + 1) % 3], out.triangles[f][(i + 2) % 3]});
      }
    }
  }
  rep.boundary_edges = out.boundary.size();
  lap(rep.seconds_cleanup);
  if (report != nullptr) *report = rep;
  return out;
}

}  // namespace carvemap
