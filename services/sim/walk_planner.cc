#include "services/sim/walk_planner.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <random>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.14159265358979323846;

Eigen::Vector2i CellOf(const NavGrid& g, const Eigen::Vector2d& p) {
  return Eigen::Vector2i(static_cast<int>(std::floor((p.x() - g.origin.x()) / g.resolution_m)),
                         static_cast<int>(std::floor((p.y() - g.origin.y()) / g.resolution_m)));
}

Eigen::Vector2d CellCenter(const NavGrid& g, const Eigen::Vector2i& c) {
  return g.origin + (c.cast<double>() + Eigen::Vector2d(0.5, 0.5)) * g.resolution_m;
}

// The nearest free cell to p within max_dist_m (a visit point or a stair landing may sit a
// little inside the clearance margin of the grid); nullopt if none.
std::optional<Eigen::Vector2i> SnapToFree(const NavGrid& g, const Eigen::Vector2d& p,
                                          double max_dist_m) {
  const Eigen::Vector2i c = CellOf(g, p);
  if (g.IsFree(c.x(), c.y())) return c;
  const int r = static_cast<int>(std::ceil(max_dist_m / g.resolution_m));
  std::optional<Eigen::Vector2i> best;
  double best_d = kInf;
  for (int dy = -r; dy <= r; ++dy) {
    for (int dx = -r; dx <= r; ++dx) {
      const Eigen::Vector2i q = c + Eigen::Vector2i(dx, dy);
      if (!g.IsFree(q.x(), q.y())) continue;
      const double d = (CellCenter(g, q) - p).norm();
      if (d <= max_dist_m && d < best_d) {
        best_d = d;
        best = q;
      }
    }
  }
  return best;
}

size_t Index(const NavGrid& g, const Eigen::Vector2i& c) {
  return static_cast<size_t>(c.y()) * g.width + c.x();
}

// 8 neighbours with their step length in cells; diagonals need both orthogonal cells free so
// the path never squeezes between two blocked corners.
template <typename F>
void ForNeighbours(const NavGrid& g, const Eigen::Vector2i& c, F&& f) {
  static constexpr int kDx[8] = {1, -1, 0, 0, 1, 1, -1, -1};
  static constexpr int kDy[8] = {0, 0, 1, -1, 1, -1, 1, -1};
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector2i n(c.x() + kDx[k], c.y() + kDy[k]);
    if (!g.IsFree(n.x(), n.y())) continue;
    if (k >= 4 && (!g.IsFree(c.x() + kDx[k], c.y()) || !g.IsFree(c.x(), c.y() + kDy[k]))) {
      continue;
    }
    f(n, k >= 4 ? std::sqrt(2.0) : 1.0);
  }
}

struct QueueEntry {
  double key;
  size_t index;
  bool operator>(const QueueEntry& o) const {
    return key != o.key ? key > o.key : index > o.index;  // deterministic ties
  }
};

// Greedy string pulling: from each kept point, jump to the farthest following point that is
// still in line of sight, so the walk goes straight instead of staircasing along cells.
std::vector<Eigen::Vector2d> Shortcut(const NavGrid& g, const std::vector<Eigen::Vector2d>& pts) {
  if (pts.size() <= 2) return pts;
  std::vector<Eigen::Vector2d> out{pts.front()};
  size_t i = 0;
  while (i + 1 < pts.size()) {
    size_t j = i + 1;
    while (j + 1 < pts.size() && LineOfSight(g, pts[i], pts[j + 1])) ++j;
    out.push_back(pts[j]);
    i = j;
  }
  return out;
}

}  // namespace

absl::Status WalkOptions::Validate() const {
  if (!(speed_mps > 0.05 && speed_mps < 5)) {
    return absl::InvalidArgumentError("walk: speed_mps must be in (0.05, 5)");
  }
  if (!(speed_variation >= 0 && speed_variation < 0.5)) {
    return absl::InvalidArgumentError("walk: speed_variation must be in [0, 0.5)");
  }
  if (!(accel_mps2 > 0)) return absl::InvalidArgumentError("walk: accel_mps2 must be > 0");
  if (!(max_yaw_rate_dps > 1)) return absl::InvalidArgumentError("walk: max_yaw_rate_dps must be > 1");
  if (!(sample_rate_hz >= 10)) return absl::InvalidArgumentError("walk: sample_rate_hz must be >= 10");
  if (!(system_height_m > 0)) return absl::InvalidArgumentError("walk: system_height_m must be > 0");
  if (laps < 1 || laps > 1000) return absl::InvalidArgumentError("walk: laps must be in [1, 1000]");
  return absl::OkStatus();
}

bool LineOfSight(const NavGrid& g, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const double len = (b - a).norm();
  const int n = std::max(1, static_cast<int>(std::ceil(len / (0.25 * g.resolution_m))));
  for (int i = 0; i <= n; ++i) {
    const Eigen::Vector2i c = CellOf(g, a + (b - a) * (static_cast<double>(i) / n));
    if (!g.IsFree(c.x(), c.y())) return false;
  }
  return true;
}

std::vector<double> GridDistances(const NavGrid& g, const Eigen::Vector2i& start) {
  std::vector<double> dist(static_cast<size_t>(g.width) * g.height, kInf);
  if (!g.IsFree(start.x(), start.y())) return dist;
  std::priority_queue<QueueEntry, std::vector<QueueEntry>, std::greater<>> open;
  dist[Index(g, start)] = 0;
  open.push({0, Index(g, start)});
  while (!open.empty()) {
    const QueueEntry e = open.top();
    open.pop();
    if (e.key > dist[e.index]) continue;
    const Eigen::Vector2i c(static_cast<int>(e.index % g.width),
                            static_cast<int>(e.index / g.width));
    ForNeighbours(g, c, [&](const Eigen::Vector2i& n, double step) {
      const double d = e.key + step * g.resolution_m;
      const size_t ni = Index(g, n);
      if (d < dist[ni]) {
        dist[ni] = d;
        open.push({d, ni});
      }
    });
  }
  return dist;
}

std::vector<Eigen::Vector2i> GridAStar(const NavGrid& g, const Eigen::Vector2i& start,
                                       const Eigen::Vector2i& goal) {
  if (!g.IsFree(start.x(), start.y()) || !g.IsFree(goal.x(), goal.y())) return {};
  const size_t n = static_cast<size_t>(g.width) * g.height;
  std::vector<double> cost(n, kInf);
  std::vector<int64_t> parent(n, -1);
  auto heuristic = [&](const Eigen::Vector2i& c) {  // octile distance: admissible
    const double dx = std::abs(c.x() - goal.x()), dy = std::abs(c.y() - goal.y());
    return std::max(dx, dy) + (std::sqrt(2.0) - 1.0) * std::min(dx, dy);
  };
  std::priority_queue<QueueEntry, std::vector<QueueEntry>, std::greater<>> open;
  cost[Index(g, start)] = 0;
  open.push({heuristic(start), Index(g, start)});
  const size_t goal_index = Index(g, goal);
  while (!open.empty()) {
    const QueueEntry e = open.top();
    open.pop();
    if (e.index == goal_index) break;
    const Eigen::Vector2i c(static_cast<int>(e.index % g.width),
                            static_cast<int>(e.index / g.width));
    if (e.key - heuristic(c) > cost[e.index] + 1e-9) continue;  // stale entry
    ForNeighbours(g, c, [&](const Eigen::Vector2i& nb, double step) {
      const double d = cost[e.index] + step;
      const size_t ni = Index(g, nb);
      if (d < cost[ni]) {
        cost[ni] = d;
        parent[ni] = static_cast<int64_t>(e.index);
        open.push({d + heuristic(nb), ni});
      }
    });
  }
  if (cost[goal_index] == kInf) return {};
  std::vector<Eigen::Vector2i> path;
  for (int64_t i = static_cast<int64_t>(goal_index); i >= 0; i = parent[i]) {
    path.emplace_back(static_cast<int>(i % g.width), static_cast<int>(i / g.width));
  }
  std::reverse(path.begin(), path.end());
  return path;
}

namespace {

class RouteBuilder {
 public:
  RouteBuilder(const Building& b, const WalkOptions& o) : b_(b), o_(o) {}

  absl::StatusOr<WalkRoute> Build() {
    if (b_.levels.empty() || b_.nav.size() != b_.levels.size()) {
      return absl::InvalidArgumentError(absl::StrCat("walk: building '", b_.name, "' has ",
                                                     b_.levels.size(), " levels but ",
                                                     b_.nav.size(), " nav grids"));
    }
    if (b_.visit_points.size() != b_.rooms.size()) {
      return absl::InvalidArgumentError("walk: visit_points and rooms differ in size");
    }
    std::vector<int> entered;
    for (size_t r = 0; r < b_.rooms.size(); ++r) {
      if (b_.rooms[r].entered && b_.visit_points[r].allFinite()) entered.push_back(int(r));
    }
    if (entered.empty()) return absl::InvalidArgumentError("walk: no entered room to visit");
    for (int r : entered) {
      const int l = b_.rooms[r].level;
      if (l < 0 || l >= static_cast<int>(b_.levels.size())) {
        return absl::InvalidArgumentError(absl::StrCat("walk: room ", b_.rooms[r].id,
                                                       " is on level ", l, " which does not exist"));
      }
    }
    // Start in rooms[0] as the survey does (or the first entered room if rooms[0] is not).
    const int start_room = entered.front();
    const int start_level = b_.rooms[start_room].level;
    int top_level = start_level;
    for (int r : entered) top_level = std::max(top_level, b_.rooms[r].level);
    for (int r : entered) {
      if (b_.rooms[r].level < start_level) {
        return absl::InvalidArgumentError(absl::StrCat(
            "walk: room ", b_.rooms[r].id, " is below the start level ", start_level));
      }
    }
    auto start = Snap(start_level, b_.visit_points[start_room], "the start visit point");
    if (!start.ok()) return start.status();
    level_ = start_level;
    cur_ = *start;
    Emit(CellCenter(Nav(), cur_));

    std::vector<bool> done(b_.rooms.size(), false);
    for (int level = start_level; level <= top_level; ++level) {
      if (level > start_level) {
        if (absl::Status s = TakeStairs(level - 1, level); !s.ok()) return s;
      }
      while (true) {
        const std::vector<double> dist = GridDistances(Nav(), cur_);
        int best = -1;
        double best_d = kInf;
        Eigen::Vector2i best_cell;
        for (int r : entered) {
          if (done[r] || b_.rooms[r].level != level) continue;
          auto cell = Snap(level, b_.visit_points[r], "");
          if (!cell.ok()) return cell.status();
          const double d = dist[Index(Nav(), *cell)];
          if (d == kInf) {
            return absl::NotFoundError(absl::StrCat(
                "walk: visit point (", b_.visit_points[r].x(), ", ", b_.visit_points[r].y(),
                ") of room ", b_.rooms[r].id, " on level ", level,
                " cannot be reached on the nav grid"));
          }
          if (d < best_d) {
            best_d = d;
            best = r;
            best_cell = *cell;
          }
        }
        if (best < 0) break;
        if (absl::Status s = WalkTo(best_cell); !s.ok()) return s;
        if (!Tour(best, best_cell)) Loop(CellCenter(Nav(), best_cell));
        done[best] = true;
        route_.rooms_visited.push_back(best);
      }
    }
    for (int level = top_level; level > start_level; --level) {
      if (absl::Status s = TakeStairs(level, level - 1); !s.ok()) return s;
    }
    if (absl::Status s = WalkTo(*start); !s.ok()) return s;
    return std::move(route_);
  }

 private:
  const NavGrid& Nav() const { return b_.nav[level_]; }

  absl::StatusOr<Eigen::Vector2i> Snap(int level, const Eigen::Vector2d& p,
                                       const std::string& what) const {
    auto c = SnapToFree(b_.nav[level], p, 0.75);
    if (!c) {
      return absl::NotFoundError(absl::StrCat("walk: ", what.empty() ? "a visit point" : what,
                                              " (", p.x(), ", ", p.y(), ") on level ", level,
                                              " is not within 0.75 m of a walkable cell"));
    }
    return *c;
  }

  void Emit(const Eigen::Vector2d& xy) {
    route_.points.push_back(
        RoutePoint{Eigen::Vector3d(xy.x(), xy.y(), b_.levels[level_].floor_z), level_});
  }

  absl::Status WalkTo(const Eigen::Vector2i& goal) {
    const std::vector<Eigen::Vector2i> cells = GridAStar(Nav(), cur_, goal);
    if (cells.empty()) {
      const Eigen::Vector2d p = CellCenter(Nav(), goal);
      return absl::NotFoundError(absl::StrCat("walk: no path on level ", level_, " to (", p.x(),
                                              ", ", p.y(), ")"));
    }
    std::vector<Eigen::Vector2d> pts;
    for (const Eigen::Vector2i& c : cells) pts.push_back(CellCenter(Nav(), c));
    pts = Shortcut(Nav(), pts);
    for (size_t i = 1; i < pts.size(); ++i) Emit(pts[i]);
    cur_ = goal;
    return absl::OkStatus();
  }

  // A walk around the room: through its four extreme walkable cells (towards its corners) in
  // counter-clockwise order and back to the visit point, so every wall is seen from several
  // sides and furniture in the middle is circled. False if the room has no usable outline.
  bool Tour(int room, const Eigen::Vector2i& vp_cell) {
    const RoomTruth& rt = b_.rooms[room];
    if (rt.polygon.size() < 3) return false;
    const NavGrid& g = Nav();
    const std::vector<double> dist = GridDistances(g, vp_cell);
    const Eigen::Vector2d dirs[4] = {{1, 1}, {-1, 1}, {-1, -1}, {1, -1}};  // CCW order
    std::vector<Eigen::Vector2i> corners;
    for (const Eigen::Vector2d& d : dirs) {
      double best = -1e300;
      Eigen::Vector2i best_cell(-1, -1);
      for (int iy = 0; iy < g.height; ++iy) {
        for (int ix = 0; ix < g.width; ++ix) {
          const Eigen::Vector2i c(ix, iy);
          if (dist[Index(g, c)] == kInf) continue;
          const Eigen::Vector2d p = CellCenter(g, c);
          if (!InsidePolygon(rt.polygon, p)) continue;
          const double score = d.dot(p);
          if (score > best) {
            best = score;
            best_cell = c;
          }
        }
      }
      if (best_cell.x() < 0) return false;
      corners.push_back(best_cell);
    }
    // Start with the corner nearest the visit point, so the tour does not double back.
    size_t first = 0;
    for (size_t i = 1; i < 4; ++i) {
      if (dist[Index(g, corners[i])] < dist[Index(g, corners[first])]) first = i;
    }
    double extent = 0;
    for (size_t i = 0; i < 4; ++i) {
      extent = std::max(extent, (CellCenter(g, corners[i]) - CellCenter(g, vp_cell)).norm());
    }
    if (extent < 0.5) return false;  // a tiny room: a loop does better
    for (size_t i = 0; i < 4; ++i) {
      if (!WalkTo(corners[(first + i) % 4]).ok()) return false;
    }
    return WalkTo(vp_cell).ok();
  }

  static bool InsidePolygon(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
    bool inside = false;
    for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
      if ((poly[i].y() > p.y()) != (poly[j].y() > p.y()) &&
          p.x() < (poly[j].x() - poly[i].x()) * (p.y() - poly[i].y()) /
                          (poly[j].y() - poly[i].y()) +
                      poly[i].x()) {
        inside = !inside;
      }
    }
    return inside;
  }

  // A loop through the visit point so the room's walls pass through every scanner's view:
  // the largest circle (of a few sizes, directions and both senses) that stays on walkable
  // cells, preferring the one that continues the arrival direction (no sharp turn).
  void Loop(const Eigen::Vector2d& vp) {
    Eigen::Vector2d arrival = Eigen::Vector2d::Zero();
    for (size_t i = route_.points.size(); i-- > 0;) {
      const Eigen::Vector2d d = vp - route_.points[i].floor_point.head<2>();
      if (d.norm() > 0.05) {
        arrival = d.normalized();
        break;
      }
    }
    constexpr int kSteps = 16;
    for (double scale : {1.0, 0.7, 0.45, 0.3}) {
      const double r = o_.room_loop_radius_m * scale;
      std::vector<Eigen::Vector2d> best;
      double best_score = -1e9;
      // The circle touches the visit point, or lies up to 1 m beyond it (furniture in the
      // middle of a room): then the walker steps out to it, loops, and leaves from there.
      for (double extra : {0.0, 0.5, 1.0}) {
        for (int k = 0; k < 8; ++k) {
          for (int sense : {1, -1}) {
            const double a0 = k * kPi / 4;
            const Eigen::Vector2d dir(std::cos(a0), std::sin(a0));
            const Eigen::Vector2d entry = vp + extra * dir;
            const Eigen::Vector2d centre = vp + (r + extra) * dir;
            const double th = a0 + kPi;
            const Eigen::Vector2d tangent = sense * Eigen::Vector2d(-std::sin(th), std::cos(th));
            const double score = arrival.dot(extra > 0 ? dir : tangent) - extra;
            if (score <= best_score) continue;
            std::vector<Eigen::Vector2d> ring;
            if (extra > 0) ring.push_back(entry);
            for (int i = 1; i <= kSteps; ++i) {
              const double a = th + sense * 2 * kPi * i / kSteps;
              ring.push_back(centre + r * Eigen::Vector2d(std::cos(a), std::sin(a)));
            }
            bool ok = true;
            Eigen::Vector2d prev = vp;
            for (const Eigen::Vector2d& p : ring) {
              ok = ok && LineOfSight(Nav(), prev, p);
              prev = p;
            }
            if (!ok) continue;
            best_score = score;
            best = std::move(ring);
          }
        }
      }
      if (!best.empty()) {
        for (const Eigen::Vector2d& p : best) Emit(p);
        cur_ = CellOf(Nav(), best.back());
        return;
      }
    }
  }

  absl::Status TakeStairs(int from, int to) {
    const StairTruth* stair = nullptr;
    bool reversed = false;
    for (const StairTruth& s : b_.stairs) {
      if (s.from_level == std::min(from, to) && s.to_level == std::max(from, to) &&
          s.centerline.size() >= 2) {
        stair = &s;
        reversed = from > to;
        break;
      }
    }
    if (!stair) {
      return absl::NotFoundError(
          absl::StrCat("walk: no stairs between levels ", from, " and ", to));
    }
    std::vector<Eigen::Vector3d> line = stair->centerline;
    if (reversed) std::reverse(line.begin(), line.end());
    auto entry = Snap(from, line.front().head<2>(), "the stairs' landing");
    if (!entry.ok()) return entry.status();
    if (absl::Status s = WalkTo(*entry); !s.ok()) return s;
    for (const Eigen::Vector3d& p : line) {
      route_.points.push_back(RoutePoint{p, p.z() > 0.5 * (b_.levels[from].floor_z +
                                                               b_.levels[to].floor_z)
                                                ? std::max(from, to)
                                                : std::min(from, to)});
    }
    level_ = to;
    auto exit = Snap(to, line.back().head<2>(), "the stairs' landing");
    if (!exit.ok()) return exit.status();
    cur_ = *exit;
    Emit(CellCenter(Nav(), cur_));
    return absl::OkStatus();
  }

  const Building& b_;
  const WalkOptions& o_;
  WalkRoute route_;
  int level_ = 0;
  Eigen::Vector2i cur_;
};

struct Knot {
  double t, s, yaw;
  Eigen::Vector3d p;
};

}  // namespace

absl::StatusOr<WalkRoute> PlanRoute(const Building& building, const WalkOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  return RouteBuilder(building, options).Build();
}

absl::StatusOr<std::vector<TimedPose>> TimeParametrize(const WalkRoute& route,
                                                       const WalkOptions& o) {
  if (absl::Status s = o.Validate(); !s.ok()) return s;
  // 1. Polyline without repeats, split into pieces of at most 0.6 m so the corner cutting
  // below moves a corner by at most ~0.15 m (the nav grid's clearance absorbs it).
  std::vector<Eigen::Vector3d> poly;
  for (const RoutePoint& rp : route.points) {
    if (poly.empty() || (rp.floor_point - poly.back()).norm() > 1e-3) {
      if (!poly.empty()) {
        const Eigen::Vector3d a = poly.back();
        const int n = static_cast<int>(std::ceil((rp.floor_point - a).norm() / 0.6));
        for (int i = 1; i < n; ++i) poly.push_back(a + (rp.floor_point - a) * (double(i) / n));
      }
      poly.push_back(rp.floor_point);
    }
  }
  if (poly.size() < 2) return absl::InvalidArgumentError("walk: route has fewer than 2 points");
  // 2. Chaikin corner cutting, twice: a walker rounds corners.
  for (int iter = 0; iter < 2; ++iter) {
    std::vector<Eigen::Vector3d> next{poly.front()};
    for (size_t i = 0; i + 1 < poly.size(); ++i) {
      next.push_back(0.75 * poly[i] + 0.25 * poly[i + 1]);
      next.push_back(0.25 * poly[i] + 0.75 * poly[i + 1]);
    }
    next.push_back(poly.back());
    poly = std::move(next);
  }
  // 3. Resample at fixed arc length.
  constexpr double kDs = 0.02;
  std::vector<Eigen::Vector3d> pts{poly.front()};
  double carry = 0;
  for (size_t i = 0; i + 1 < poly.size(); ++i) {
    const Eigen::Vector3d a = poly[i], b = poly[i + 1];
    const double len = (b - a).norm();
    double u = kDs - carry;
    while (u <= len) {
      pts.push_back(a + (b - a) * (u / len));
      u += kDs;
    }
    carry = len - (u - kDs);
  }
  if ((pts.back() - poly.back()).norm() > 1e-6) pts.push_back(poly.back());
  const size_t n = pts.size();
  // 4. Heading follows the horizontal walking direction (kept on stairs' vertical-only bits).
  std::vector<double> yaw(n, 0.0);
  double last = 0;
  bool have = false;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d = pts[std::min(i + 1, n - 1)] - pts[i > 0 ? i - 1 : 0];
    if (d.head<2>().norm() > 1e-6) {
      double a = std::atan2(d.y(), d.x());
      if (have) a = last + std::remainder(a - last, 2 * kPi);
      last = a;
      if (!have) std::fill(yaw.begin(), yaw.begin() + i, a);
      have = true;
    }
    yaw[i] = last;
  }
  // 5. Speed: nominal with a slow variation, capped where the path turns (so the heading can
  // follow at the yaw-rate limit over a window of the path), then limited by acceleration
  // forwards and backwards (start and stop at rest).
  std::mt19937_64 rng(o.seed * 0x9E3779B97F4A7C15ull + 17);
  std::uniform_real_distribution<double> phase(0, 2 * kPi);
  const double speed_phase = phase(rng), gait_phase = phase(rng);
  const double yaw_rate = o.max_yaw_rate_dps * kPi / 180;
  std::vector<double> s(n, 0.0), v(n);
  for (size_t i = 1; i < n; ++i) s[i] = s[i - 1] + (pts[i] - pts[i - 1]).norm();
  constexpr double kTurnWindow = 0.6;  // m
  const size_t half = static_cast<size_t>(0.5 * kTurnWindow / kDs);
  for (size_t i = 0; i < n; ++i) {
    v[i] = o.speed_mps * (1 + o.speed_variation * std::sin(2 * kPi * s[i] / 12.0 + speed_phase));
    const size_t lo = i > half ? i - half : 0, hi = std::min(n - 1, i + half);
    const double turn = std::abs(yaw[hi] - yaw[lo]);
    if (turn > 1e-9) v[i] = std::min(v[i], yaw_rate * (s[hi] - s[lo]) / turn);
  }
  v.front() = v.back() = 0;
  for (size_t i = 1; i < n; ++i) {
    v[i] = std::min(v[i], std::sqrt(v[i - 1] * v[i - 1] + 2 * o.accel_mps2 * (s[i] - s[i - 1])));
  }
  for (size_t i = n - 1; i-- > 0;) {
    v[i] = std::min(v[i], std::sqrt(v[i + 1] * v[i + 1] + 2 * o.accel_mps2 * (s[i + 1] - s[i])));
  }
  std::vector<Knot> knots(n);
  knots[0] = Knot{0, 0, yaw[0], pts[0]};
  for (size_t i = 1; i < n; ++i) {
    const double ds = s[i] - s[i - 1];
    const double dt = ds / std::max(0.5 * (v[i - 1] + v[i]), 0.05);
    knots[i] = Knot{knots[i - 1].t + dt, s[i], yaw[i], pts[i]};
  }
  // The heading looks a little ahead along the path and turns at most at the yaw-rate limit
  // (a walker turns his body before the corner, and cannot spin instantly).
  {
    constexpr double kLookahead_s = 0.15;
    size_t j = 0;
    double h = yaw[0];
    for (size_t i = 0; i < n; ++i) {
      while (j + 1 < n && knots[j + 1].t <= knots[i].t + kLookahead_s) ++j;
      const double dt = i > 0 ? knots[i].t - knots[i - 1].t : 0.0;
      h += std::clamp(yaw[std::max(i, j)] - h, -yaw_rate * dt, yaw_rate * dt);
      knots[i].yaw = h;
    }
  }
  // 6. Sample, adding the gait: a vertical bob per step and roll/pitch sway, tied to the
  // distance walked so standing still does not bob.
  const double duration = knots.back().t;
  const double step_length = o.speed_mps / o.step_frequency_hz;
  const double deg = kPi / 180;
  std::vector<TimedPose> path;
  const size_t samples = static_cast<size_t>(std::floor(duration * o.sample_rate_hz)) + 1;
  path.reserve(samples + 1);
  size_t k = 0;
  for (size_t i = 0; i <= samples; ++i) {
    const double t = i < samples ? i / o.sample_rate_hz : duration;
    if (i == samples && t - path.back().t < 1e-9) break;
    while (k + 2 < n && knots[k + 1].t <= t) ++k;
    const Knot& a = knots[k];
    const Knot& b = knots[std::min(k + 1, n - 1)];
    const double u = b.t > a.t ? std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0) : 0.0;
    const Eigen::Vector3d p = a.p + (b.p - a.p) * u;
    const double dist = a.s + (b.s - a.s) * u;
    const double heading = a.yaw + (b.yaw - a.yaw) * u;
    const double phi = 2 * kPi * dist / step_length + gait_phase;
    const double bob = o.bob_amplitude_m * std::cos(phi);
    const double roll = o.sway_roll_deg * deg * std::sin(0.5 * phi);
    const double pitch = o.sway_pitch_deg * deg * std::sin(phi + 0.25 * kPi);
    TimedPose tp;
    tp.t = t;
    tp.pose.translation = p + Eigen::Vector3d(0, 0, o.system_height_m + bob);
    tp.pose.rotation = (Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()) *
                        Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                        Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                           .normalized();
    path.push_back(tp);
  }
  return path;
}

absl::StatusOr<Walk> PlanWalk(const Building& building, const WalkOptions& options) {
  Walk walk;
  auto route = PlanRoute(building, options);
  if (!route.ok()) return route.status();
  walk.route = *std::move(route);
  // More laps: the same route again from its end, which is its start (PlanRoute), so the one
  // time parametrization turns and paces across the joins as anywhere else.
  WalkRoute laps = walk.route;
  for (int lap = 1; lap < options.laps; ++lap) {
    for (size_t i = 0; i < walk.route.points.size(); ++i) {
      const RoutePoint& p = walk.route.points[i];
      const RoutePoint& last = laps.points.back();
      if (i == 0 && p.level == last.level && (p.floor_point - last.floor_point).norm() < 1e-9) {
        continue;
      }
      laps.points.push_back(p);
    }
  }
  auto path = TimeParametrize(laps, options);
  if (!path.ok()) return path.status();
  walk.path = *std::move(path);
  for (size_t i = 1; i < walk.path.size(); ++i) {
    walk.length_m += (walk.path[i].pose.translation - walk.path[i - 1].pose.translation)
                         .head<2>()
                         .norm();
  }
  return walk;
}

}  // namespace carvemap
