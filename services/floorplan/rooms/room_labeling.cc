#include "services/floorplan/rooms/room_labeling.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <queue>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/union_find.h"
#include "services/floorplan/orient_2d.h"
#include "services/floorplan/rooms/delaunay_mesh.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

using floorplan_internal::DelaunayMesh;
using floorplan_internal::Orient;

// The finite faces of the Delaunay triangulation as flat arrays (faster to walk than handles).
// fv: CCW vertex ids; fn[f][i]: the face across the edge opposite fv[f][i], −1 outside the hull.
struct Mesh {
  std::vector<Vector2d> pts;
  std::vector<std::array<int, 3>> fv;
  std::vector<std::array<int, 3>> fn;
  std::vector<int> vface;                       // one incident face per vertex
  std::vector<std::pair<int, int>> hull_edges;  // (face, index of the opposite vertex)

  int IndexIn(int f, int v) const { return fv[f][0] == v ? 0 : (fv[f][1] == v ? 1 : 2); }

  // Calls fn(face) for the faces around v until it returns true; returns whether it did.
  template <typename Fn>
  bool AnyFaceAround(int v, Fn&& fn) const {
    const int f0 = vface[v];
    if (f0 < 0) return false;
    int f = f0;
    do {  // counter-clockwise
      if (fn(f)) return true;
      f = fn_ccw(f, v);
    } while (f >= 0 && f != f0);
    if (f == f0) return false;
    for (f = fn_cw(f0, v); f >= 0; f = fn_cw(f, v)) {  // the rest, clockwise from f0
      if (fn(f)) return true;
    }
    return false;
  }
  int fn_ccw(int f, int v) const { return fn[f][(IndexIn(f, v) + 1) % 3]; }
  int fn_cw(int f, int v) const { return fn[f][(IndexIn(f, v) + 2) % 3]; }
};

// Where a walk starts: at a vertex, inside a face, on an edge (face, opposite index), or nowhere.
using Start = floorplan_internal::PointLocation;

bool InClosedFace(const Mesh& m, int f, const Vector2d& b) {
  const auto& v = m.fv[f];
  return Orient(m.pts[v[0]], m.pts[v[1]], b) >= 0 && Orient(m.pts[v[1]], m.pts[v[2]], b) >= 0 &&
         Orient(m.pts[v[2]], m.pts[v[0]], b) >= 0;
}

// §3.3.1: calls on_face(f) for every face whose interior the segment (a, b) crosses, in order
// from `start` (which must be where a is). Crossings are exclusive of triangle edges: running
// along an edge or touching a vertex carves nothing. Stops at b or where the segment leaves the
// convex hull (a hull is convex, so it never re-enters).
template <typename OnFace>
void Walk(const Mesh& m, const Vector2d& a, const Vector2d& b, Start start, OnFace&& on_face) {
  if (a == b) return;
  Start::Kind kind = start.kind;
  int cur = start.id;
  if (kind == Start::kEdge) {
    const auto& v = m.fv[cur];
    const int x = v[(start.edge + 1) % 3], y = v[(start.edge + 2) % 3];
    const int side = Orient(m.pts[x], m.pts[y], b);
    if (side > 0) {
      kind = Start::kFace;
    } else if (side < 0) {
      cur = m.fn[cur][start.edge];
      if (cur < 0) return;
      kind = Start::kFace;
    } else {  // along the edge, towards one of its ends
      const int w = (m.pts[x] - a).dot(b - a) > 0 ? x : y;
      if ((b - a).squaredNorm() < (m.pts[w] - a).squaredNorm()) return;
      kind = Start::kVertex;
      cur = w;
    }
  }
  // Bounded: every step moves forward along the segment through a new face or vertex.
  for (size_t steps = 0, limit = 2 * (m.fv.size() + m.pts.size()) + 8;
       kind != Start::kNone && steps < limit; ++steps) {
    if (kind == Start::kVertex) {
      const int v = cur;
      const Vector2d& pv = m.pts[v];
      if (pv == b) return;
      int next_face = -1, along = -1;
      m.AnyFaceAround(v, [&](int f) {
        const int i = m.IndexIn(f, v);
        const int x = m.fv[f][(i + 1) % 3], y = m.fv[f][(i + 2) % 3];
        const int ox = Orient(pv, m.pts[x], b);
        if (ox > 0) {
          const int oy = Orient(pv, m.pts[y], b);
          if (oy < 0) {
            next_face = f;
            return true;
          }
          if (oy == 0 && (m.pts[y] - pv).dot(b - pv) > 0) {
            along = y;
            return true;
          }
        } else if (ox == 0 && (m.pts[x] - pv).dot(b - pv) > 0) {
          along = x;
          return true;
        }
        return false;
      });
      if (next_face >= 0) {
        kind = Start::kFace;
        cur = next_face;
      } else if (along >= 0) {
        if ((b - pv).squaredNorm() < (m.pts[along] - pv).squaredNorm()) return;
        cur = along;
      } else {
        return;  // v is on the hull and the segment leaves it here
      }
      continue;
    }
    // Face state: the segment crosses the interior of `cur`.
    const int f = cur;
    on_face(f);
    const auto& v = m.fv[f];
    const int o[3] = {Orient(a, b, m.pts[v[0]]), Orient(a, b, m.pts[v[1]]),
                      Orient(a, b, m.pts[v[2]])};
    int exit = -1;
    for (int i = 0; i < 3; ++i) {
      if (o[(i + 1) % 3] < 0 && o[(i + 2) % 3] > 0) exit = i;
    }
    if (exit >= 0) {
      if (Orient(m.pts[v[(exit + 1) % 3]], m.pts[v[(exit + 2) % 3]], b) >= 0) return;  // b in f
      cur = m.fn[f][exit];
      if (cur < 0) return;
      continue;
    }
    // No edge exit: the segment leaves through the vertex on it (ahead of it).
    if (InClosedFace(m, f, b)) return;
    int on_line = -1;
    for (int i = 0; i < 3; ++i) {
      if (o[i] == 0) on_line = v[i];
    }
    if (on_line < 0) return;  // cannot happen with exact predicates
    kind = Start::kVertex;
    cur = on_line;
  }
}

// Where segment (a, b), a outside the hull, enters it; kNone if it misses the hull.
Start HullEntry(const Mesh& m, const Vector2d& a, const Vector2d& b) {
  for (const auto& [f, i] : m.hull_edges) {
    const int x = m.fv[f][(i + 1) % 3], y = m.fv[f][(i + 2) % 3];
    const Vector2d &px = m.pts[x], &py = m.pts[y];
    if (Orient(px, py, a) >= 0 || Orient(px, py, b) <= 0) continue;
    const int ox = Orient(a, b, px), oy = Orient(a, b, py);
    if (ox > 0 && oy < 0) return {Start::kEdge, f, i};
    if (ox == 0) return {Start::kVertex, x, -1};
    if (oy == 0) return {Start::kVertex, y, -1};
  }
  return {};
}

// §3.3.1 carving of every line of sight from one scanner position s strictly inside face f0, in
// one sweep instead of one walk per segment: angular windows (open, < 180°, bounded by rays
// through vertices) are pushed from face to face, a face is carved when a live target (a sample
// seen from s) lies strictly inside its window, and a window splits at its face's far vertex.
// Each face is visited once per window, not once per segment: in a corridor a 20 m line of
// sight crosses ~800 sliver triangles, and a pose sees ~1000 samples.
// Occlusion: when a face's far vertex V is met, every live target in the window whose segment
// passes within r of V before reaching its sample is truncated there (it stops carving); (s, V)
// itself is carved by V's own ray when s sees V (the per-segment walk carves it explicitly). Window
// splits use exact orientation predicates; target membership uses pseudo-angles (only membership of
// near-collinear targets can differ). Returns the number of truncated segments.
struct FanScratch {
  std::vector<std::pair<double, int>> targets;  // (angle from s, vertex), ascending
  std::vector<double> angle;                    // targets' angles
  std::vector<int> next_alive;                  // union-find: first live target at or after i
  std::vector<double> vangle;                   // per-vertex angle cache, valid where
  std::vector<uint32_t> vstamp;                 //   vstamp == stamp
  uint32_t stamp = 0;
  // A window: the face it enters, the face it comes from, the vertices bounding it (lo → hi
  // counter-clockwise) and its targets as a range [ia, ib) of the doubled target list
  // (index i ≥ n is target i − n turned once more around: angles stay ascending).
  struct Item {
    int face, from, lo, hi, ia, ib;
    double alpha;  // lo's angle in the doubled list's coordinates
  };
  std::vector<Item> stack;
};

// A pseudo-angle of direction (x, y) in [−2, 2): monotone in the true angle (atan2 mapped from
// [−π, π) to [−2, 2)), with no trigonometry. Period 4.
double PseudoAngle(double x, double y) {
  const double sum = std::abs(x) + std::abs(y);
  if (sum == 0) return 0;
  const double p = y / sum;
  if (x >= 0) return p;
  return y > 0 ? 2 - p : -2 - p;
}

size_t CarveFan(const Mesh& m, const Vector2d& s, int f0, const std::vector<int>& seen,
                double occ_r, FanScratch& w, std::vector<char>& interior) {
  const int n = static_cast<int>(seen.size());
  if (n == 0) return 0;
  constexpr double kTwoPi = 4;  // pseudo-angles (PseudoAngle): a full turn is 4, half a turn 2
  constexpr double kPi = 2;
  if (w.vstamp.size() != m.pts.size()) {
    w.vstamp.assign(m.pts.size(), 0);
    w.vangle.resize(m.pts.size());
    w.stamp = 0;
  }
  ++w.stamp;
  auto angle_of = [&](int v) {
    if (w.vstamp[v] != w.stamp) {
      const Vector2d d = m.pts[v] - s;
      w.vangle[v] = PseudoAngle(d.x(), d.y());
      w.vstamp[v] = w.stamp;
    }
    return w.vangle[v];
  };
  w.targets.clear();
  for (int v : seen) w.targets.emplace_back(angle_of(v), v);
  std::sort(w.targets.begin(), w.targets.end());
  w.angle.resize(n);
  for (int i = 0; i < n; ++i) w.angle[i] = w.targets[i].first;
  w.next_alive.resize(n + 1);
  std::iota(w.next_alive.begin(), w.next_alive.end(), 0);
  auto find = [&](int i) {
    while (w.next_alive[i] != i) {
      w.next_alive[i] = w.next_alive[w.next_alive[i]];
      i = w.next_alive[i];
    }
    return i;
  };
  auto ang_u = [&](int i) { return i < n ? w.angle[i] : w.angle[i - n] + kTwoPi; };
  auto lower = [&](int ia, int ib, double x) {  // first index in [ia, ib) with angle ≥ x
    while (ia < ib) {
      const int mid = (ia + ib) / 2;
      if (ang_u(mid) < x)
        ia = mid + 1;
      else
        ib = mid;
    }
    return ia;
  };
  auto upper = [&](int ia, int ib, double x) {  // first index in [ia, ib) with angle > x
    while (ia < ib) {
      const int mid = (ia + ib) / 2;
      if (ang_u(mid) <= x)
        ia = mid + 1;
      else
        ib = mid;
    }
    return ia;
  };
  auto first_live = [&](int ia, int ib) {  // in the doubled list (same coordinates); −1 if none
    int shift = 0;
    if (ia >= n) {
      ia -= n;
      ib -= n;
      shift = n;
    }
    if (ia >= ib) return -1;
    int k = find(ia);
    if (ib <= n) return k < ib ? k + shift : -1;
    if (k < n) return k + shift;
    k = find(0);
    return k < ib - n ? k + n + shift : -1;
  };
  size_t truncated = 0;
  const double r2 = occ_r * occ_r;
  // Truncates the live targets of the window whose segment passes V's ball before its end.
  auto occlude = [&](int v, int ia, int ib, double alpha) {
    const Vector2d e = m.pts[v] - s;
    const double dv2 = e.squaredNorm();
    if (dv2 <= r2 || ia >= ib) return;  // a sample at the scanner: no meaningful direction
    // The cone of directions meeting V's ball: e turned by ±asin(r/|e|).
    const double sn = occ_r / std::sqrt(dv2), cs = std::sqrt(1 - sn * sn);
    const double g0 = angle_of(v);
    auto turn = [&](double a) {  // a − g0 wrapped to (−2, 2]
      while (a - g0 > kPi) a -= kTwoPi;
      while (a - g0 <= -kPi) a += kTwoPi;
      return a - g0;
    };
    const double minus = turn(PseudoAngle(cs * e.x() + sn * e.y(), cs * e.y() - sn * e.x()));
    const double plus = turn(PseudoAngle(cs * e.x() - sn * e.y(), cs * e.y() + sn * e.x()));
    double g = g0;  // within half a turn of the window's start (the window spans < half a turn)
    while (g < alpha - kPi) g += kTwoPi;
    while (g >= alpha + kPi) g -= kTwoPi;
    const int a = upper(ia, ib, g + minus), b = lower(ia, ib, g + plus);
    for (int i = first_live(a, b); i >= 0; i = first_live(i + 1, b)) {
      const int t_index = i < n ? i : i - n;
      const int p = w.targets[t_index].second;
      if (p == v) continue;
      const Vector2d d = m.pts[p] - s;
      const double t = e.dot(d) / d.squaredNorm();
      if (t < 0 || t >= 1 || (e - t * d).squaredNorm() > r2) continue;
      w.next_alive[t_index] = t_index + 1;
      ++truncated;
    }
  };
  interior[f0] = 1;
  w.stack.clear();
  {
    const auto& v = m.fv[f0];
    for (int k = 0; k < 3; ++k) {
      const int lo_v = v[(k + 1) % 3], hi_v = v[(k + 2) % 3];
      const double lo = angle_of(lo_v), hi = angle_of(hi_v);
      const int ia = upper(0, n, lo);
      const int ib = lo < hi ? lower(0, n, hi) : n + lower(0, n, hi);
      for (int j = 0; j < 3; ++j) occlude(v[j], ia, ib, lo);
      if (m.fn[f0][k] >= 0 && first_live(ia, ib) >= 0) {
        w.stack.push_back({m.fn[f0][k], f0, lo_v, hi_v, ia, ib, lo});
      }
    }
  }
  for (size_t visits = 0, limit = 4 * m.fv.size() + 16; !w.stack.empty() && visits < limit;
       ++visits) {
    const FanScratch::Item it = w.stack.back();
    w.stack.pop_back();
    if (first_live(it.ia, it.ib) < 0) continue;  // truncated since it was pushed
    const int f = it.face;
    interior[f] = 1;
    const auto& v = m.fv[f];
    const int e = m.fn[f][0] == it.from ? 0 : (m.fn[f][1] == it.from ? 1 : 2);
    const int apex = v[e];
    occlude(apex, it.ia, it.ib, it.alpha);
    const Vector2d& pa = m.pts[apex];
    const bool after_lo = Orient(s, m.pts[it.lo], pa) > 0;
    const bool before_hi = Orient(s, pa, m.pts[it.hi]) > 0;
    const int to_lo_side = m.fn[f][(e + 1) % 3];  // across edge (Y, apex): the window's lo side
    const int to_hi_side = m.fn[f][(e + 2) % 3];  // across edge (apex, X)
    auto push = [&](int face, int lo, int hi, int ia, int ib, double alpha) {
      if (face >= 0 && first_live(ia, ib) >= 0) {
        w.stack.push_back({face, f, lo, hi, ia, ib, alpha});
      }
    };
    if (after_lo && before_hi) {
      double g = angle_of(apex);  // counter-clockwise of α by less than 180°
      while (g <= it.alpha) g += kTwoPi;
      while (g > it.alpha + kTwoPi) g -= kTwoPi;
      push(to_lo_side, it.lo, apex, it.ia, lower(it.ia, it.ib, g), it.alpha);
      push(to_hi_side, apex, it.hi, upper(it.ia, it.ib, g), it.ib, g);
    } else if (!after_lo) {
      push(to_hi_side, it.lo, it.hi, it.ia, it.ib, it.alpha);
    } else {
      push(to_lo_side, it.lo, it.hi, it.ia, it.ib, it.alpha);
    }
  }
  return truncated;
}

// A circumcircle and the key that orders circles (§3.3.2 "largest radius"), ties broken by the
// triangle's centroid so the order depends on geometry only, never on input order.
struct Circle {
  double cx = 0, cy = 0, r = 0;
  double gx = 0, gy = 0;
};
bool Larger(const Circle& a, const Circle& b) {
  return std::tie(a.r, a.gx, a.gy) > std::tie(b.r, b.gx, b.gy);
}
// Whether two circles overlap by more than min_overlap × the smaller radius (see FindSeeds).
bool Overlap(const Circle& a, const Circle& b, double min_overlap) {
  const double dx = a.cx - b.cx, dy = a.cy - b.cy;
  const double rr = a.r + b.r - min_overlap * std::min(a.r, b.r);
  return dx * dx + dy * dy < rr * rr;
}

// §3.3.2 room seeds: interior faces whose circumcircle is the largest of every interior
// circumcircle it intersects. "Intersects" means overlapping by more than min_overlap × the
// smaller radius (extension): a large room's circle bulges a few cm through a doorway (the
// sagitta of the door's chord) and would otherwise suppress the seed of the room behind the door
// whose own largest circle touches the wall there — two rooms would share one seed and merge.
// Circles of one space overlap deeply. Circles go into a grid per radius octave (cell = twice the
// octave's largest radius), so a query looks at ≤ 5×5 cells per octave at or above its own and
// exits at the first larger overlapping circle: about linear, not O(n²).
std::vector<int> FindSeeds(const Mesh& m, const std::vector<Circle>& circles,
                           const std::vector<char>& interior, double min_overlap) {
  std::vector<int> faces;
  double rmin = std::numeric_limits<double>::infinity();
  for (size_t f = 0; f < interior.size(); ++f) {
    if (interior[f]) {
      faces.push_back(static_cast<int>(f));
      rmin = std::min(rmin, circles[f].r);
    }
  }
  if (faces.empty()) return {};
  rmin = std::max(rmin, 1e-9);
  auto level_of = [&](double r) {
    return std::clamp(static_cast<int>(std::floor(std::log2(r / rmin))), 0, 60);
  };
  auto cell_size = [&](int level) { return std::ldexp(rmin, level + 1); };
  auto key = [](int level, int64_t ix, int64_t iy) {
    return (static_cast<uint64_t>(level) << 58) ^ (static_cast<uint64_t>(ix & 0x1FFFFFFF) << 29) ^
           static_cast<uint64_t>(iy & 0x1FFFFFFF);
  };
  absl::flat_hash_map<uint64_t, std::vector<int>> grid;
  int max_level = 0;
  for (int f : faces) {
    const Circle& c = circles[f];
    const int level = level_of(c.r);
    max_level = std::max(max_level, level);
    const double cs = cell_size(level);
    grid[key(level, static_cast<int64_t>(std::floor(c.cx / cs)),
             static_cast<int64_t>(std::floor(c.cy / cs)))]
        .push_back(f);
  }
  std::vector<int> seeds;
  for (int f : faces) {
    const Circle& c = circles[f];
    bool beaten = false;
    // Adjacent circles always meet (they share an edge's ends) and most overlap deeply: most
    // faces stop here.
    for (int n : m.fn[f]) {
      if (n >= 0 && interior[n] && Larger(circles[n], c) && Overlap(circles[n], c, min_overlap)) {
        beaten = true;
      }
    }
    for (int level = level_of(c.r); !beaten && level <= max_level; ++level) {
      const double cs = cell_size(level);
      const double reach = c.r + cs;  // every circle of this octave has r < cs
      const int64_t x0 = static_cast<int64_t>(std::floor((c.cx - reach) / cs));
      const int64_t x1 = static_cast<int64_t>(std::floor((c.cx + reach) / cs));
      const int64_t y0 = static_cast<int64_t>(std::floor((c.cy - reach) / cs));
      const int64_t y1 = static_cast<int64_t>(std::floor((c.cy + reach) / cs));
      for (int64_t ix = x0; !beaten && ix <= x1; ++ix) {
        for (int64_t iy = y0; !beaten && iy <= y1; ++iy) {
          const auto it = grid.find(key(level, ix, iy));
          if (it == grid.end()) continue;
          for (int g : it->second) {
            if (Larger(circles[g], c) && Overlap(circles[g], c, min_overlap)) {
              beaten = true;
              break;
            }
          }
        }
      }
    }
    if (!beaten) seeds.push_back(f);
  }
  return seeds;
}

double FaceArea(const Mesh& m, int f) {
  const Vector2d &a = m.pts[m.fv[f][0]], &b = m.pts[m.fv[f][1]], &c = m.pts[m.fv[f][2]];
  return 0.5 * std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
}

// Thin walls (extension of §3.3.1–§3.3.2): a wall one sample thick (a one-pixel wall of a grid
// map, a partition whose two faces lie within d_s) is scanned from both sides, so the triangles
// on both sides are interior and meet along the chain of its samples, d_s apart. The dissertation's
// rooms assume walls with an exterior inside them; here an edge between two interior triangles
// that is no longer than wall_edge_m (a couple of sample spacings: far narrower than any door,
// and no line of sight passes it, §3.3.1's occlusion check) is a wall: the partition does not
// cross it and it is no part of a border between rooms.
bool IsThinWall(double edge_length_m, double wall_edge_m) { return edge_length_m <= wall_edge_m; }

// §3.3.2 greedy partition: flood fill from the seeds, longest shared edge first. Returns the
// label (index into seeds) per face, −1 for exterior. Edges no longer than wall_edge_m are thin
// walls (IsThinWall) and are not crossed. An interior component without a seed (when a larger
// circle of another component overlaps all of its circles, or a thin wall cuts it off) gets its
// largest circle as an extra seed, appended to `seeds`, so every interior face is labelled.
std::vector<int> Partition(const Mesh& m, const std::vector<Circle>& circles,
                           const std::vector<char>& interior, std::vector<int>& seeds,
                           double wall_edge_m) {
  struct Item {
    double len, mx, my;  // the edge: longest first; its midpoint breaks ties (unique per edge)
    int face, label;
    bool operator<(const Item& o) const {
      return std::tie(len, mx, my) < std::tie(o.len, o.mx, o.my);
    }
  };
  std::vector<int> label(m.fv.size(), -1);
  std::priority_queue<Item> queue;
  auto push_edges = [&](int f) {
    for (int i = 0; i < 3; ++i) {
      const int n = m.fn[f][i];
      if (n < 0 || !interior[n] || label[n] >= 0) continue;
      const Vector2d& p = m.pts[m.fv[f][(i + 1) % 3]];
      const Vector2d& q = m.pts[m.fv[f][(i + 2) % 3]];
      const double len = (p - q).norm();
      if (IsThinWall(len, wall_edge_m)) continue;
      queue.push({len, 0.5 * (p.x() + q.x()), 0.5 * (p.y() + q.y()), n, label[f]});
    }
  };
  auto fill = [&]() {
    while (!queue.empty()) {
      const Item it = queue.top();
      queue.pop();
      if (label[it.face] >= 0) continue;
      label[it.face] = it.label;
      push_edges(it.face);
    }
  };
  for (size_t k = 0; k < seeds.size(); ++k) label[seeds[k]] = static_cast<int>(k);
  for (int s : seeds) push_edges(s);
  fill();
  std::vector<int> orphans;
  for (size_t f = 0; f < m.fv.size(); ++f) {
    if (interior[f] && label[f] < 0) orphans.push_back(static_cast<int>(f));
  }
  std::sort(orphans.begin(), orphans.end(),
            [&](int a, int b) { return Larger(circles[a], circles[b]); });
  for (int f : orphans) {
    if (label[f] >= 0) continue;
    label[f] = static_cast<int>(seeds.size());
    seeds.push_back(f);
    push_edges(f);
    fill();
  }
  return label;
}

// The sample positions bucketed by cell, to look at the walls around a point.
class SampleGrid {
 public:
  SampleGrid(const std::vector<Vector2d>& pts, double cell) : cell_(cell) {
    for (const Vector2d& p : pts) cells_[Key(p)].push_back(p);
  }
  // Calls fn(sample) for the samples within r of q.
  template <typename Fn>
  void ForEachWithin(const Vector2d& q, double r, Fn&& fn) const {
    const int64_t x0 = Floor(q.x() - r), x1 = Floor(q.x() + r);
    const int64_t y0 = Floor(q.y() - r), y1 = Floor(q.y() + r);
    for (int64_t x = x0; x <= x1; ++x) {
      for (int64_t y = y0; y <= y1; ++y) {
        const auto it = cells_.find(Pack(x, y));
        if (it == cells_.end()) continue;
        for (const Vector2d& p : it->second) {
          if ((p - q).squaredNorm() <= r * r) fn(p);
        }
      }
    }
  }

 private:
  [[nodiscard]] int64_t Floor(double x) const {
    return static_cast<int64_t>(std::floor(x / cell_));
  }
  [[nodiscard]] static uint64_t Pack(int64_t x, int64_t y) {
    return (static_cast<uint64_t>(x) << 32) ^ static_cast<uint32_t>(y);
  }
  [[nodiscard]] uint64_t Key(const Vector2d& p) const { return Pack(Floor(p.x()), Floor(p.y())); }
  double cell_;
  absl::flat_hash_map<uint64_t, std::vector<Vector2d>> cells_;
};

// How much of the view from p the walls around it take: the angle, seen from p, spanned by the
// samples between `inner` and wall_end_radius_m from it (SplitOpenSides). A wall's or a
// partition's end, its faces running away from p, spans ~0–60°; a corner the free space goes
// around 90°; a point on a wall's face, away from its end, ~180°. 360° with fewer than three
// such samples (a lone sample is no wall).
double WallEndSpanDeg(const SampleGrid& grid, const Vector2d& p, const RoomLabelingOptions& options,
                      double inner) {
  std::vector<double> angles;
  grid.ForEachWithin(p, options.wall_end_radius_m, [&](const Vector2d& q) {
    const Vector2d d = q - p;
    if (d.squaredNorm() >= inner * inner) angles.push_back(std::atan2(d.y(), d.x()));
  });
  if (angles.size() < 3) return 360;
  std::sort(angles.begin(), angles.end());
  double largest_gap = angles.front() + 2 * M_PI - angles.back();
  for (size_t i = 1; i < angles.size(); ++i) {
    largest_gap = std::max(largest_gap, angles[i] - angles[i - 1]);
  }
  return (2 * M_PI - largest_gap) * 180 / M_PI;
}

// What the §3.3.2 merge test looks at for a pair of adjacent rooms. Their shared edges (thin
// walls left out) form pieces: chains of edges joined at vertices; each piece is one opening.
//  - length: the longest piece. The dissertation speaks of "a border" between two rooms; summing
//    all shared edges instead would merge two rooms joined by two ordinary doors.
//  - narrowing: the largest, over pieces no longer than max_door_width_m, of the piece's length
//    over the local free-space diameter: twice the largest circumradius (§3.3.2: the local
//    feature size) among the faces on either side reached from the piece through edges whose
//    midpoint lies within context × its length of a midpoint of the piece.
struct RoomBorder {
  double length = 0;
  double narrowing = 0;
};

// Key (lower label << 32 | higher label).
absl::flat_hash_map<uint64_t, RoomBorder> RoomBorders(const Mesh& m,
                                                      const std::vector<Circle>& circles,
                                                      const std::vector<int>& label,
                                                      double wall_edge_m, double max_door_width_m,
                                                      double context) {
  struct SharedEdge {
    uint64_t pair;
    int u, v;     // its ends
    int side[2];  // the faces of the lower and the higher label
    double length;
  };
  const int nf = static_cast<int>(m.fv.size());
  std::vector<SharedEdge> shared;
  for (int f = 0; f < nf; ++f) {
    if (label[f] < 0) continue;
    for (int i = 0; i < 3; ++i) {
      const int n = m.fn[f][i];
      if (n < f || label[n] < 0 || label[n] == label[f]) continue;  // n < f includes n < 0
      const int u = m.fv[f][(i + 1) % 3], v = m.fv[f][(i + 2) % 3];
      const double len = (m.pts[u] - m.pts[v]).norm();
      if (IsThinWall(len, wall_edge_m)) continue;
      const bool f_lower = label[f] < label[n];
      const uint64_t lo = static_cast<uint64_t>(std::min(label[f], label[n]));
      const uint64_t hi = static_cast<uint64_t>(std::max(label[f], label[n]));
      shared.push_back({(lo << 32) | hi, u, v, {f_lower ? f : n, f_lower ? n : f}, len});
    }
  }
  // Pieces: union-find over the shared edges of a pair that meet at a vertex.
  UnionFind<int> joined(shared.size());
  {
    absl::flat_hash_map<std::pair<uint64_t, int>, int> at;
    for (size_t e = 0; e < shared.size(); ++e) {
      for (int w : {shared[e].u, shared[e].v}) {
        const auto [it, inserted] = at.try_emplace({shared[e].pair, w}, static_cast<int>(e));
        if (!inserted) joined.Union(static_cast<int>(e), it->second);
      }
    }
  }
  // Pieces in order of their first edge (deterministic).
  std::vector<std::vector<int>> pieces;
  {
    std::vector<int> piece_of(shared.size(), -1);
    for (size_t e = 0; e < shared.size(); ++e) {
      int& p = piece_of[joined.Find(static_cast<int>(e))];
      if (p < 0) {
        p = static_cast<int>(pieces.size());
        pieces.emplace_back();
      }
      pieces[p].push_back(static_cast<int>(e));
    }
  }
  absl::flat_hash_map<uint64_t, RoomBorder> borders;
  std::vector<uint32_t> stamp_of(nf, 0);
  uint32_t stamp = 0;
  std::vector<Vector2d> mids;
  std::vector<int> stack;
  for (const std::vector<int>& piece : pieces) {
    double len = 0;
    for (int e : piece) len += shared[e].length;
    RoomBorder& border = borders[shared[piece[0]].pair];
    border.length = std::max(border.length, len);
    if (len > max_door_width_m) continue;  // too wide for a door anyway: no local size needed
    mids.clear();
    for (int e : piece) mids.push_back(0.5 * (m.pts[shared[e].u] + m.pts[shared[e].v]));
    const double reach2 = context * context * len * len;
    double rmax = 0;
    for (int side = 0; side < 2; ++side) {
      ++stamp;
      stack.clear();
      for (int e : piece) {
        const int f = shared[e].side[side];
        if (stamp_of[f] != stamp) {
          stamp_of[f] = stamp;
          stack.push_back(f);
        }
      }
      const int room = label[stack.front()];
      while (!stack.empty()) {
        const int f = stack.back();
        stack.pop_back();
        rmax = std::max(rmax, circles[f].r);
        for (int i = 0; i < 3; ++i) {
          const int n = m.fn[f][i];
          if (n < 0 || label[n] != room || stamp_of[n] == stamp) continue;
          const Vector2d& p = m.pts[m.fv[f][(i + 1) % 3]];
          const Vector2d& q = m.pts[m.fv[f][(i + 2) % 3]];
          if (IsThinWall((p - q).norm(), wall_edge_m)) continue;
          const Vector2d mid = 0.5 * (p + q);
          bool near = false;
          for (const Vector2d& c : mids) {
            if ((mid - c).squaredNorm() <= reach2) {
              near = true;
              break;
            }
          }
          if (!near) continue;
          stamp_of[n] = stamp;
          stack.push_back(n);
        }
      }
    }
    // rmax > 0: every face has a positive circumradius.
    border.narrowing = std::max(border.narrowing, len / (2 * rmax));
  }
  return borders;
}

// The distinct positions of the samples, sorted, so that vertex ids (and everything after) do
// not depend on the input order. A duplicated position is one vertex with the union of the
// samples' poses and the median floor / ceiling (the medians keep floor < ceiling).
struct SampleVertices {
  std::vector<Vector2d> pts;
  std::vector<std::vector<uint32_t>> poses;  // per vertex, the poses that see it
  std::vector<double> floor_z, ceiling_z;
};

SampleVertices DistinctSamples(const WallSampleSet& samples) {
  std::vector<uint32_t> order(samples.samples.size());
  std::iota(order.begin(), order.end(), 0u);
  auto pos_less = [&](uint32_t a, uint32_t b) {
    const Vector2d &p = samples.samples[a].position, &q = samples.samples[b].position;
    return std::tie(p.x(), p.y()) < std::tie(q.x(), q.y());
  };
  std::sort(order.begin(), order.end(), pos_less);
  SampleVertices v;
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    std::vector<double> fl, ce;
    std::vector<uint32_t> poses;
    while (j < order.size() &&
           samples.samples[order[j]].position == samples.samples[order[i]].position) {
      const WallSample& s = samples.samples[order[j]];
      fl.push_back(s.floor_z);
      ce.push_back(s.ceiling_z);
      poses.insert(poses.end(), s.poses.begin(), s.poses.end());
      ++j;
    }
    auto median = [](std::vector<double>& v) {
      std::sort(v.begin(), v.end());
      const size_t n = v.size();
      return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    };
    std::sort(poses.begin(), poses.end());
    poses.erase(std::unique(poses.begin(), poses.end()), poses.end());
    v.pts.push_back(samples.samples[order[i]].position);
    v.floor_z.push_back(median(fl));
    v.ceiling_z.push_back(median(ce));
    v.poses.push_back(std::move(poses));
    i = j;
  }
  return v;
}

// The triangulation's finite faces as flat arrays, with one face per vertex and the hull edges.
void FlatFaces(const DelaunayMesh& dt, Mesh& m) {
  m.fv = dt.triangles();
  m.fn = dt.neighbours();
  const int nf = static_cast<int>(m.fv.size());
  m.vface.assign(m.pts.size(), -1);
  for (int f = 0; f < nf; ++f) {
    for (int i = 0; i < 3; ++i) {
      const int v = m.fv[f][i];
      if (m.vface[v] < 0) m.vface[v] = f;
      if (m.fn[f][i] < 0) m.hull_edges.emplace_back(f, i);
    }
  }
}

// §3.3.1: the interior (triangles crossed by the lines of sight from the poses to the samples
// they saw, each cut short at the first sample in its way, and by the path from pose to pose),
// or, with `interior_test`, the triangles it accepts; and (§3.3.2) the triangles the path
// entered. Both are per face of `m`.
void CarveInterior(const Mesh& m, const DelaunayMesh& dt, const WallSampleSet& samples,
                   const std::vector<std::vector<uint32_t>>& vertex_poses,
                   const InteriorTest& interior_test, double occ_r, std::vector<char>& interior,
                   std::vector<char>& entered, RoomLabelingReport& rep) {
  const int nf = static_cast<int>(m.fv.size());
  const size_t np = samples.poses.size();
  std::vector<Start> pose_at(np);
  {
    int hint = -1;
    for (size_t i = 0; i < np; ++i) pose_at[i] = dt.Locate(samples.poses[i], &hint);
  }
  // §3.3.2: a room is entered if the path crosses one of its triangles or a pose lies in one.
  for (const Start& s : pose_at) {
    if (s.kind == Start::kFace) entered[s.id] = 1;
    if (s.kind == Start::kEdge) {
      entered[s.id] = 1;
      if (const int n = m.fn[s.id][s.edge]; n >= 0) entered[n] = 1;
    }
  }
  std::vector<int> crossed;
  auto mark = [&](int f) { interior[f] = 1; };
  // One line of sight by a walk: for poses on an edge, a vertex or outside the hull.
  auto carve_sight = [&](int vid, const Vector2d& s) {
    const Vector2d& p = m.pts[vid];
    // Walk back from the sample to the scanner (the walk starts at a known vertex, no point
    // location), collecting crossed faces and the first occluding sample seen from s: a vertex
    // of a crossed face whose ball meets (s, p) before p. Vertices not on a crossed face are
    // not tested: with samples at spacing d_s the ball of any sample within d_s/2 of the
    // segment is (almost always) reached by a face the segment crosses.
    const Vector2d d = p - s;
    const double len2 = d.squaredNorm();
    if (len2 == 0) return;
    int occluder = -1;
    double best = 2;
    crossed.clear();
    Walk(m, p, s, {Start::kVertex, vid, -1}, [&](int f) {
      crossed.push_back(f);
      for (int w : m.fv[f]) {
        if (w == vid) continue;
        const Vector2d e = m.pts[w] - s;
        const double t = e.dot(d) / len2;
        if (t < 0 || t >= 1) continue;
        const double dist2 = (e - t * d).squaredNorm();
        if (dist2 > occ_r * occ_r) continue;
        const double entry = t - std::sqrt((occ_r * occ_r - dist2) / len2);
        if (entry < best || (entry == best && w < occluder)) {
          best = entry;
          occluder = w;
        }
      }
    });
    if (occluder < 0) {
      for (int f : crossed) interior[f] = 1;
    } else {
      // §3.3.1: truncate to (s, p'), so a wall scanned from both sides keeps its samples.
      ++rep.truncated_segments;
      Walk(m, m.pts[occluder], s, {Start::kVertex, occluder, -1}, mark);
    }
  };
  if (!interior_test) {
    std::vector<std::vector<int>> seen_from(np);
    for (size_t vid = 0; vid < m.pts.size(); ++vid) {
      for (uint32_t pi : vertex_poses[vid]) seen_from[pi].push_back(static_cast<int>(vid));
    }
    FanScratch scratch;
    for (size_t pi = 0; pi < np; ++pi) {
      const Vector2d& s = samples.poses[pi];
      std::vector<int>& seen = seen_from[pi];
      // A sample at the scanner's own position has no line of sight to carve.
      seen.erase(std::remove_if(seen.begin(), seen.end(), [&](int v) { return m.pts[v] == s; }),
                 seen.end());
      rep.sight_segments += seen.size();
      if (pose_at[pi].kind == Start::kFace) {
        rep.truncated_segments += CarveFan(m, s, pose_at[pi].id, seen, occ_r, scratch, interior);
      } else {
        for (int v : seen) carve_sight(v, s);
      }
      std::vector<int>().swap(seen);
    }
  }
  // Scanner-to-scanner segments (§3.3.1). Not occlusion-checked: the path passes through
  // doorways, whose jambs are samples within d_s/2 of it, and a real walk cannot pass a wall.
  {
    size_t next_break = 0;
    for (size_t i = 1; i < np; ++i) {
      while (next_break < samples.path_breaks.size() && samples.path_breaks[next_break] < i) {
        ++next_break;
      }
      if (next_break < samples.path_breaks.size() && samples.path_breaks[next_break] == i) continue;
      Vector2d a = samples.poses[i - 1], b = samples.poses[i];
      Start start = pose_at[i - 1];
      if (start.kind == Start::kNone) {
        if (pose_at[i].kind != Start::kNone) {
          std::swap(a, b);
          start = pose_at[i];
        } else {
          start = HullEntry(m, a, b);  // both outside: clip to the hull
        }
      }
      if (start.kind == Start::kNone) continue;
      Walk(m, a, b, start, [&](int f) {
        if (!interior_test) interior[f] = 1;
        entered[f] = 1;
      });
    }
  }
  if (interior_test) {  // the interior decided elsewhere (§3.2's Eigencrust labelling)
    for (int f = 0; f < nf; ++f) {
      interior[f] = interior_test(m.pts[m.fv[f][0]], m.pts[m.fv[f][1]], m.pts[m.fv[f][2]]) ? 1 : 0;
    }
  }
}

// The faces' circumcircles and centroids (§3.3.2).
std::vector<Circle> Circumcircles(const Mesh& m) {
  const int nf = static_cast<int>(m.fv.size());
  std::vector<Circle> circles(nf);
  const std::vector<Vector2d> centres = floorplan_internal::Circumcentres(m.pts, m.fv);
  for (int f = 0; f < nf; ++f) {
    const Vector2d &a = m.pts[m.fv[f][0]], &b = m.pts[m.fv[f][1]], &c = m.pts[m.fv[f][2]];
    Circle& k = circles[f];
    k.cx = centres[f].x();
    k.cy = centres[f].y();
    k.r = std::hypot(a.x() - k.cx, a.y() - k.cy);
    k.gx = (a.x() + b.x() + c.x()) / 3;
    k.gy = (a.y() + b.y() + c.y()) / 3;
  }
  return circles;
}

// §3.3.2 refinement, into `seeds` and `label` (per face, the room's index in `seeds`, −1 outside).
// Each round partitions, then (1) drops, for every pair of rooms sharing a border that is no door
// (RoomBorders: longer than max_door_width_m, or not narrowing the free space), the seed with the
// smaller circle — all such seeds at once: "no door between them" is transitive ("same room"),
// and the largest seed of each group of rooms so joined is never dropped, so no room is lost and
// hallways merge in few rounds; (2) only when no seed was dropped, removes the rooms the path
// never entered and recomputes the seeds. Merging first keeps a room the path entered only
// partly (an L-shaped room with two seeds) from losing its unvisited half.
absl::Status RefineRooms(const Mesh& m, const std::vector<Circle>& circles,
                         const std::vector<char>& entered, size_t poses, double wall_edge_m,
                         const RoomLabelingOptions& options, std::vector<char>& interior,
                         std::vector<int>& seeds, std::vector<int>& label,
                         RoomLabelingReport& rep) {
  const int nf = static_cast<int>(m.fv.size());
  const size_t np = poses;
  seeds = FindSeeds(m, circles, interior, options.seed_min_overlap);
  rep.initial_seeds = seeds.size();
  std::vector<int> part_seeds;  // the seeds of `label` (the last partition)
  rep.converged = false;
  while (rep.rounds < options.max_rounds) {
    ++rep.rounds;
    label = Partition(m, circles, interior, seeds, wall_edge_m);
    part_seeds = seeds;
    const size_t k = seeds.size();
    std::vector<char> drop(k, 0), wide(k, 0);  // wide: dropped for max_door_width_m
    bool dropped = false;
    for (const auto& [pair, border] : RoomBorders(m, circles, label, wall_edge_m,
                                                  options.max_door_width_m, options.door_context)) {
      const bool too_wide = border.length > options.max_door_width_m;
      const bool no_narrowing =
          options.door_narrowing > 0 && border.narrowing > options.door_narrowing;
      if (!too_wide && !no_narrowing) continue;
      const int a = static_cast<int>(pair >> 32), b = static_cast<int>(pair & 0xFFFFFFFFu);
      const int lose = Larger(circles[seeds[a]], circles[seeds[b]]) ? b : a;
      drop[lose] = 1;
      wide[lose] |= too_wide ? 1 : 0;
      dropped = true;
    }
    if (dropped) {
      std::vector<int> kept;
      for (size_t i = 0; i < k; ++i) {
        if (drop[i]) {
          ++rep.merged_seeds;
          rep.narrow_merged_seeds += wide[i] ? 0 : 1;
        } else {
          kept.push_back(seeds[i]);
        }
      }
      seeds = std::move(kept);
      continue;
    }
    if (options.remove_unentered_rooms) {
      std::vector<char> room_entered(k, 0);
      for (int f = 0; f < nf; ++f) {
        if (label[f] >= 0 && entered[f]) room_entered[label[f]] = 1;
      }
      size_t removed = 0;
      for (size_t i = 0; i < k; ++i) removed += room_entered[i] ? 0 : 1;
      if (removed > 0) {
        if (removed == k) {
          return absl::FailedPreconditionError(absl::StrCat("room labeling: the path (", np,
                                                            " poses) enters none of the ", k,
                                                            " rooms, so all would be removed"));
        }
        rep.removed_rooms += removed;
        for (int f = 0; f < nf; ++f) {
          if (label[f] >= 0 && !room_entered[label[f]]) {
            interior[f] = 0;
            rep.removed_area_m2 += FaceArea(m, f);
          }
        }
        seeds = FindSeeds(m, circles, interior, options.seed_min_overlap);
        continue;
      }
    }
    rep.converged = true;
    break;
  }
  seeds = std::move(part_seeds);
  return absl::OkStatus();
}

// Extension of §3.3.2, open sides (RoomLabelingOptions::open_side_max_m): the seeds miss a bay
// or a room open onto a corridor over its width, as the largest circle sits in the opening.
// Once the rooms have converged, a room is cut between two of its wall ends (WallEndSpanDeg),
// one a tip, through its own triangles only, when the smaller side is a room of its own: big
// and deep enough, entered, and a dead end. Shortest cuts first; each gives the smaller side a
// new label, seeded at its largest circle.
void SplitOpenSides(const Mesh& m, const std::vector<Circle>& circles,
                    const std::vector<char>& entered, double spacing_m, double wall_edge_m,
                    const RoomLabelingOptions& options, std::vector<int>& seeds,
                    std::vector<int>& label, RoomLabelingReport& rep) {
  if (options.open_side_max_m <= 0 || options.open_side_min_area_m2 <= 0) return;
  const int nf = static_cast<int>(m.fv.size());
  const int nv = static_cast<int>(m.pts.size());
  const SampleGrid walls(m.pts, std::max(0.1, options.wall_end_radius_m / 4));
  const double inner = 4 * spacing_m;
  // Per room, its wall ends: vertices of its faces that touch a face outside every room and
  // span at most wall_end_span_deg.
  std::vector<std::vector<int>> ends_of(seeds.size());
  std::vector<double> span(nv, -1);  // −1: not asked yet
  for (int f = 0; f < nf; ++f) {
    const int l = label[f];
    if (l < 0) continue;
    for (int i = 0; i < 3; ++i) {
      const int v = m.fv[f][i];
      bool on_wall = false;
      m.AnyFaceAround(v, [&](int g) { return on_wall = label[g] < 0; });
      if (!on_wall) continue;
      if (span[v] < 0) span[v] = WallEndSpanDeg(walls, m.pts[v], options, inner);
      if (span[v] <= options.wall_end_span_deg) ends_of[l].push_back(v);
    }
  }
  struct Cut {
    double length;
    int room, a, b;
  };
  std::vector<Cut> cuts;
  for (size_t l = 0; l < ends_of.size(); ++l) {
    std::vector<int>& e = ends_of[l];
    std::sort(e.begin(), e.end());
    e.erase(std::unique(e.begin(), e.end()), e.end());
    for (size_t i = 0; i < e.size(); ++i) {
      for (size_t j = i + 1; j < e.size(); ++j) {
        const double d = (m.pts[e[i]] - m.pts[e[j]]).norm();
        // One end at least is a wall's tip, not a corner: two corners are as likely a
        // corridor's end, or furniture standing in a room.
        const double tip = std::min(span[e[i]], span[e[j]]);
        if (d > wall_edge_m && d <= options.open_side_max_m && tip <= options.wall_tip_span_deg) {
          cuts.push_back({d, static_cast<int>(l), e[i], e[j]});
        }
      }
    }
  }
  std::sort(cuts.begin(), cuts.end(), [](const Cut& x, const Cut& y) {
    return std::tie(x.length, x.room, x.a, x.b) < std::tie(y.length, y.room, y.a, y.b);
  });
  absl::flat_hash_map<uint64_t, char> blocked;  // face pairs the cut separates
  auto pair_key = [](int f, int g) {
    return static_cast<uint64_t>(std::min(f, g)) << 32 | static_cast<uint32_t>(std::max(f, g));
  };
  std::vector<int> crossed, side(nf, -1), stack;
  for (const Cut& c : cuts) {
    // The segment through the room's own faces, from face to adjacent face.
    crossed.clear();
    bool inside = true;
    Walk(m, m.pts[c.a], m.pts[c.b], Start{Start::kVertex, c.a, -1}, [&](int f) {
      if (label[f] != c.room) inside = false;
      crossed.push_back(f);
    });
    if (!inside || crossed.empty()) continue;
    blocked.clear();
    for (size_t i = 0; i + 1 < crossed.size(); ++i) {
      const int f = crossed[i], g = crossed[i + 1];
      if (m.fn[f][0] != g && m.fn[f][1] != g && m.fn[f][2] != g) {
        inside = false;  // through a vertex: the faces around it would join the sides
        break;
      }
      blocked[pair_key(f, g)] = 1;
    }
    if (!inside) continue;
    // The room's faces on either side: flood fill from the first crossed face, not across the
    // segment; what it does not reach is the other side.
    const int room = c.room;
    auto fill = [&](int start, int mark, std::vector<int>& out) {
      stack.assign(1, start);
      side[start] = mark;
      while (!stack.empty()) {
        const int f = stack.back();
        stack.pop_back();
        out.push_back(f);
        for (int i = 0; i < 3; ++i) {
          const int n = m.fn[f][i];
          if (n < 0 || label[n] != room || side[n] == mark) continue;
          if (blocked.contains(pair_key(f, n))) continue;
          side[n] = mark;
          stack.push_back(n);
        }
      }
    };
    std::vector<int> one, all;
    fill(crossed.front(), 1, one);
    for (int f = 0; f < nf; ++f) {
      if (label[f] == room) all.push_back(f);
    }
    std::vector<int> other;
    for (int f : all) {
      if (side[f] != 1) other.push_back(f);
    }
    for (int f : one) side[f] = -1;
    if (other.empty()) continue;  // the segment does not separate the room
    // The other side must be one piece too, or the cut split off more than one part.
    std::vector<int> two;
    fill(other.front(), 2, two);
    for (int f : two) side[f] = -1;
    if (two.size() != other.size()) continue;
    double area_one = 0, area_two = 0;
    for (int f : one) area_one += FaceArea(m, f);
    for (int f : two) area_two += FaceArea(m, f);
    std::vector<int>& small = area_one <= area_two ? one : two;
    const double small_area = std::min(area_one, area_two);
    if (small_area < options.open_side_min_area_m2 ||
        small_area < options.open_side_min_depth * c.length * c.length) {
      continue;
    }
    bool dead_end = true, was_entered = false;
    for (int f : small) {
      was_entered |= entered[f] != 0;
      for (int i = 0; i < 3; ++i) {
        const int n = m.fn[f][i];
        if (n < 0 || label[n] < 0 || label[n] == room) continue;
        const double len = (m.pts[m.fv[f][(i + 1) % 3]] - m.pts[m.fv[f][(i + 2) % 3]]).norm();
        if (!IsThinWall(len, wall_edge_m)) dead_end = false;
      }
    }
    if (!dead_end || !was_entered) continue;
    std::vector<int>& big = &small == &one ? two : one;
    const int fresh = static_cast<int>(seeds.size());
    int seed = small.front();
    for (int f : small) {
      if (Larger(circles[f], circles[seed])) seed = f;
    }
    // The room keeps its seed when it lies on the small side: the small side takes it, the
    // rest gets its largest circle.
    const bool seed_moves = std::find(small.begin(), small.end(), seeds[room]) != small.end();
    for (int f : small) label[f] = fresh;
    seeds.push_back(seed);
    if (seed_moves) {
      int rest = -1;
      for (int f : big) {
        if (rest < 0 || Larger(circles[f], circles[rest])) rest = f;
      }
      seeds[room] = rest;
    }
    ++rep.open_sides_split;
  }
}

// Extension: a room under min_room_area_m2 is no room (a sliver between a wall and furniture
// that the path happens to cross, a pocket cut off by thin walls): once the rooms have
// converged, it joins the room it shares the most edge length with (thin walls included),
// smallest first. One with no neighbour stays.
void MergeSmallRooms(const Mesh& m, const RoomLabelingOptions& options, std::vector<int>& seeds,
                     std::vector<int>& label, RoomLabelingReport& rep) {
  const int nf = static_cast<int>(m.fv.size());
  if (options.min_room_area_m2 <= 0) return;
  const size_t k0 = seeds.size();
  std::vector<std::vector<int>> faces_of(k0);
  std::vector<double> room_area(k0, 0);
  for (int f = 0; f < nf; ++f) {
    if (label[f] < 0) continue;
    faces_of[label[f]].push_back(f);
    room_area[label[f]] += FaceArea(m, f);
  }
  std::vector<int> order(k0);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return room_area[a] < room_area[b]; });
  absl::flat_hash_map<int, double> shared_with;
  bool merged = false;
  for (int l : order) {
    if (room_area[l] >= options.min_room_area_m2) break;
    shared_with.clear();
    for (int f : faces_of[l]) {
      for (int i = 0; i < 3; ++i) {
        const int n = m.fn[f][i];
        if (n < 0 || label[n] < 0 || label[n] == l) continue;
        shared_with[label[n]] += (m.pts[m.fv[f][(i + 1) % 3]] - m.pts[m.fv[f][(i + 2) % 3]]).norm();
      }
    }
    int into = -1;
    double best = 0;
    for (const auto& [t, len] : shared_with) {
      if (len > best || (len == best && t < into)) {
        best = len;
        into = t;
      }
    }
    if (into < 0) continue;
    for (int f : faces_of[l]) label[f] = into;
    faces_of[into].insert(faces_of[into].end(), faces_of[l].begin(), faces_of[l].end());
    faces_of[l].clear();
    room_area[into] += room_area[l];
    room_area[l] = 0;
    ++rep.small_merged_rooms;
    merged = true;
  }
  if (merged) {  // compact the labels
    std::vector<int> new_label(k0, -1);
    std::vector<int> kept;
    for (size_t l = 0; l < k0; ++l) {
      if (faces_of[l].empty()) continue;
      new_label[l] = static_cast<int>(kept.size());
      kept.push_back(seeds[l]);
    }
    for (int f = 0; f < nf; ++f) {
      if (label[f] >= 0) label[f] = new_label[label[f]];
    }
    seeds = std::move(kept);
  }
}

// The plan: every vertex; interior triangles in face order (CCW, as CGAL keeps them); rooms
// largest area first, ties by the seed's circle.
FloorPlan PlanOf(const Mesh& m, std::vector<double> floor_z, std::vector<double> ceiling_z,
                 const std::vector<Circle>& circles, const std::vector<int>& seeds,
                 const std::vector<int>& label) {
  const int nf = static_cast<int>(m.fv.size());
  FloorPlan plan;
  plan.vertices = m.pts;
  plan.vertex_floor_z = std::move(floor_z);
  plan.vertex_ceiling_z = std::move(ceiling_z);
  const size_t k = seeds.size();
  std::vector<double> area(k, 0);
  std::vector<int> out_index(nf, -1);
  for (int f = 0; f < nf; ++f) {
    if (label[f] < 0) continue;
    const Vector2d &a = m.pts[m.fv[f][0]], &b = m.pts[m.fv[f][1]], &c = m.pts[m.fv[f][2]];
    area[label[f]] += 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
    out_index[f] = static_cast<int>(plan.triangles.size());
    plan.triangles.push_back({static_cast<uint32_t>(m.fv[f][0]), static_cast<uint32_t>(m.fv[f][1]),
                              static_cast<uint32_t>(m.fv[f][2])});
  }
  std::vector<int> room_order(k);
  std::iota(room_order.begin(), room_order.end(), 0);
  std::sort(room_order.begin(), room_order.end(), [&](int a, int b) {
    if (area[a] != area[b]) return area[a] > area[b];
    return Larger(circles[seeds[a]], circles[seeds[b]]);
  });
  std::vector<int> room_of_label(k, -1);
  for (size_t r = 0; r < k; ++r) {
    const int l = room_order[r];
    room_of_label[l] = static_cast<int>(r);
    FloorPlanRoom room;
    room.seed_triangle = out_index[seeds[l]];
    room.seed_radius_m = circles[seeds[l]].r;
    room.area_m2 = area[l];
    plan.rooms.push_back(room);
  }
  plan.triangle_room.reserve(plan.triangles.size());
  for (int f = 0; f < nf; ++f) {
    if (label[f] >= 0) plan.triangle_room.push_back(room_of_label[label[f]]);
  }
  return plan;
}

}  // namespace

absl::Status RoomLabelingOptions::Validate() const {
  if (!std::isfinite(occlusion_diameter_m) || occlusion_diameter_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: occlusion_diameter_m must be finite and ≥ 0, got ", occlusion_diameter_m));
  }
  if (!std::isfinite(max_door_width_m) || max_door_width_m <= 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: max_door_width_m must be finite and > 0, got ", max_door_width_m));
  }
  if (!std::isfinite(door_narrowing) || door_narrowing < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: door_narrowing must be finite and ≥ 0, got ", door_narrowing));
  }
  if (!std::isfinite(door_context) || door_context <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: door_context must be finite and > 0, got ", door_context));
  }
  if (!std::isfinite(open_side_max_m) || open_side_max_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: open_side_max_m must be finite and ≥ 0, got ", open_side_max_m));
  }
  if (!std::isfinite(open_side_min_depth) || open_side_min_depth < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: open_side_min_depth must be finite and ≥ 0, got ", open_side_min_depth));
  }
  if (!std::isfinite(open_side_min_area_m2) || open_side_min_area_m2 < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: open_side_min_area_m2 must be finite and ≥ 0, got ",
                     open_side_min_area_m2));
  }
  if (!std::isfinite(wall_end_radius_m) || wall_end_radius_m <= 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: wall_end_radius_m must be finite and > 0, got ", wall_end_radius_m));
  }
  if (!(wall_end_span_deg > 0 && wall_end_span_deg < 360)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: wall_end_span_deg must be in (0, 360), got ", wall_end_span_deg));
  }
  if (!(wall_tip_span_deg > 0 && wall_tip_span_deg <= wall_end_span_deg)) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: wall_tip_span_deg must be in (0, wall_end_span_deg], got ",
                     wall_tip_span_deg));
  }
  if (!std::isfinite(thin_wall_spacings) || thin_wall_spacings < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: thin_wall_spacings must be finite and ≥ 0, got ", thin_wall_spacings));
  }
  if (!std::isfinite(seed_min_overlap) || seed_min_overlap < 0 || seed_min_overlap > 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: seed_min_overlap must be in [0, 2], got ", seed_min_overlap));
  }
  if (!std::isfinite(min_room_area_m2) || min_room_area_m2 < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "room labeling: min_room_area_m2 must be finite and ≥ 0, got ", min_room_area_m2));
  }
  if (max_rounds < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: max_rounds must be ≥ 1, got ", max_rounds));
  }
  return absl::OkStatus();
}

absl::StatusOr<FloorPlan> LabelRooms(const WallSampleSet& samples,
                                     const RoomLabelingOptions& options,
                                     RoomLabelingReport* report) {
  return LabelRoomsOfInterior(samples, nullptr, options, report);
}

absl::StatusOr<FloorPlan> LabelRoomsOfInterior(const WallSampleSet& samples,
                                               const InteriorTest& interior_test,
                                               const RoomLabelingOptions& options,
                                               RoomLabelingReport* report) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = samples.Validate(); !s.ok()) return s;
  RoomLabelingReport rep;
  SampleVertices vertices = DistinctSamples(samples);
  Mesh m;
  m.pts = std::move(vertices.pts);
  rep.samples = m.pts.size();
  if (m.pts.size() < 3) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: need at least 3 distinct wall samples, got ", m.pts.size()));
  }
  absl::StatusOr<DelaunayMesh> dt = DelaunayMesh::Build(m.pts, "room labeling");
  if (!dt.ok()) return dt.status();
  if (dt->dimension() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("room labeling: the ", m.pts.size(), " distinct wall samples are collinear"));
  }
  FlatFaces(*dt, m);
  const int nf = static_cast<int>(m.fv.size());
  rep.triangles = static_cast<size_t>(nf);

  std::vector<char> interior(nf, 0), entered(nf, 0);
  const double occ_r =
      0.5 * (options.occlusion_diameter_m > 0 ? options.occlusion_diameter_m : samples.spacing_m);
  CarveInterior(m, *dt, samples, vertices.poses, interior_test, occ_r, interior, entered, rep);
  for (char c : interior) rep.interior_triangles += c ? 1 : 0;
  if (rep.interior_triangles == 0) {
    return absl::FailedPreconditionError(absl::StrCat(
        "room labeling: no interior triangle: ", rep.sight_segments, " sight segments from ",
        samples.poses.size(), " poses carved none of the ", nf, " triangles"));
  }

  const std::vector<Circle> circles = Circumcircles(m);
  const double wall_edge_m = options.thin_wall_spacings * samples.spacing_m;
  std::vector<int> seeds, label;
  if (absl::Status s = RefineRooms(m, circles, entered, samples.poses.size(), wall_edge_m, options,
                                   interior, seeds, label, rep);
      !s.ok()) {
    return s;
  }
  SplitOpenSides(m, circles, entered, samples.spacing_m, wall_edge_m, options, seeds, label, rep);
  MergeSmallRooms(m, options, seeds, label, rep);
  FloorPlan plan =
      PlanOf(m, std::move(vertices.floor_z), std::move(vertices.ceiling_z), circles, seeds, label);
  if (report != nullptr) *report = rep;
  return plan;
}

}  // namespace carvemap
