#include "services/building/floormap_building.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <tuple>
#include <unordered_map>

#include <Eigen/Eigenvalues>

#include "absl/strings/str_cat.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

constexpr uint8_t kFreeThreshold = 250;  // upstream: < 250 is occupied (SOURCES.md)
constexpr double kSlabT = 0.2;
// Occupied pixels farther than this from free space are inside solid walls or unknown space:
// no ray from a free pixel can reach them, so they are not extruded (keeps prisms few).
constexpr double kVisibleWallDepth_m = 0.3;

// A binary or label image in map layout (row 0 at the top).
struct Grid {
  int width = 0, height = 0;
  std::vector<int> v;
  [[nodiscard]] size_t Index(int row, int col) const { return size_t(row) * width + col; }
};

// A rectangle of pixels [row0, row1] × [col0, col1] (inclusive).
struct PixelRect {
  int row0, row1, col0, col1;
  int label;
};

// Greedy rectangle cover of the non-zero pixels: runs of equal labels along each row, then
// equal runs of consecutive rows merged. Exact (every labelled pixel covered exactly once).
std::vector<PixelRect> MergeRects(const Grid& labels) {
  std::vector<PixelRect> done;
  std::map<std::tuple<int, int, int>, PixelRect> open;  // (col0, col1, label) → rect
  for (int row = 0; row <= labels.height; ++row) {
    std::map<std::tuple<int, int, int>, PixelRect> next;
    if (row < labels.height) {
      for (int col = 0; col < labels.width;) {
        const int l = labels.v[labels.Index(row, col)];
        if (l == 0) {
          ++col;
          continue;
        }
        int end = col;
        while (end + 1 < labels.width && labels.v[labels.Index(row, end + 1)] == l) ++end;
        const auto key = std::make_tuple(col, end, l);
        if (auto it = open.find(key); it != open.end()) {
          it->second.row1 = row;
          next.emplace(key, it->second);
          open.erase(it);
        } else {
          next.emplace(key, PixelRect{row, row, col, end, l});
        }
        col = end + 1;
      }
    }
    for (auto& [key, rect] : open) done.push_back(rect);
    open = std::move(next);
  }
  return done;
}

// Connected components of the pixels where `mask` is non-zero; labels 1..n, 0 elsewhere.
Grid Components(const Grid& mask, bool eight_connected, int* count) {
  Grid labels{mask.width, mask.height, std::vector<int>(mask.v.size(), 0)};
  int n = 0;
  std::vector<std::pair<int, int>> stack;
  for (int r0 = 0; r0 < mask.height; ++r0) {
    for (int c0 = 0; c0 < mask.width; ++c0) {
      if (!mask.v[mask.Index(r0, c0)] || labels.v[mask.Index(r0, c0)]) continue;
      ++n;
      labels.v[mask.Index(r0, c0)] = n;
      stack.emplace_back(r0, c0);
      while (!stack.empty()) {
        const auto [r, c] = stack.back();
        stack.pop_back();
        for (int dr = -1; dr <= 1; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            if ((dr == 0 && dc == 0) || (!eight_connected && dr != 0 && dc != 0)) continue;
            const int rr = r + dr, cc = c + dc;
            if (rr < 0 || cc < 0 || rr >= mask.height || cc >= mask.width) continue;
            const size_t j = mask.Index(rr, cc);
            if (mask.v[j] && !labels.v[j]) {
              labels.v[j] = n;
              stack.emplace_back(rr, cc);
            }
          }
        }
      }
    }
  }
  *count = n;
  return labels;
}

absl::StatusOr<Grid> ReadOccupancy(const std::string& path, const Grid* same_size_as) {
  absl::StatusOr<Image<uint8_t>> img = ReadPngGray8(path);
  if (!img.ok()) {
    return absl::Status(img.status().code(),
                        absl::StrCat("floor map ", path, ": ", img.status().message()));
  }
  if (same_size_as && (img->width != same_size_as->width || img->height != same_size_as->height)) {
    return absl::InvalidArgumentError(absl::StrCat("floor map ", path, ": ", img->width, "x",
                                                   img->height, " does not match the map's ",
                                                   same_size_as->width, "x", same_size_as->height));
  }
  Grid g{img->width, img->height, std::vector<int>(img->pixels.size())};
  for (size_t i = 0; i < g.v.size(); ++i) g.v[i] = img->pixels[i] < kFreeThreshold;
  return g;
}

// Pixel-edge corners as integers: X = column edge 0..W, Y = H − row edge (y up), so world
// x = X·res, y = Y·res (docs/DESIGN.md §4: pixel (row, col) covers x ∈ [col, col+1]·res,
// y ∈ [H−1−row, H−row]·res).
struct Corner {
  int x, y;
  bool operator==(const Corner&) const = default;
};

struct CornerHash {
  size_t operator()(const Corner& c) const {
    return std::hash<long long>()((long long)c.x << 32 | unsigned(c.y));
  }
};

// Boundary rings of the pixels of `labels` equal to `label`, region on the left (outer ring
// CCW, holes CW), collinear corners removed. At a corner where the region's pixels touch only
// diagonally the trace turns right, keeping them one ring as 8-connectivity does.
std::vector<std::vector<Corner>> TraceRings(const Grid& labels, int label, int r0, int r1, int c0,
                                            int c1) {
  const int H = labels.height;
  const auto in = [&](int r, int c) {
    return r >= 0 && c >= 0 && r < H && c < labels.width && labels.v[labels.Index(r, c)] == label;
  };
  struct Edge {
    Corner a, b;
    bool used = false;
  };
  std::vector<Edge> edges;
  for (int r = r0; r <= r1; ++r) {
    for (int c = c0; c <= c1; ++c) {
      if (!in(r, c)) continue;
      const int yb = H - 1 - r, yt = H - r;
      if (!in(r + 1, c)) edges.push_back({{c, yb}, {c + 1, yb}});
      if (!in(r, c + 1)) edges.push_back({{c + 1, yb}, {c + 1, yt}});
      if (!in(r - 1, c)) edges.push_back({{c + 1, yt}, {c, yt}});
      if (!in(r, c - 1)) edges.push_back({{c, yt}, {c, yb}});
    }
  }
  std::unordered_multimap<Corner, size_t, CornerHash> out_edges;
  for (size_t i = 0; i < edges.size(); ++i) out_edges.emplace(edges[i].a, i);
  std::vector<std::vector<Corner>> rings;
  for (size_t start = 0; start < edges.size(); ++start) {
    if (edges[start].used) continue;
    std::vector<Corner> path;
    size_t e = start;
    while (!edges[e].used) {
      edges[e].used = true;
      path.push_back(edges[e].a);
      const Corner d{edges[e].b.x - edges[e].a.x, edges[e].b.y - edges[e].a.y};
      auto [lo, hi] = out_edges.equal_range(edges[e].b);
      size_t next = e;
      for (auto it = lo; it != hi; ++it) {
        const Edge& cand = edges[it->second];
        if (cand.used && it->second != start) continue;
        const int ex = cand.b.x - cand.a.x, ey = cand.b.y - cand.a.y;
        const bool right_turn = d.x * ey - d.y * ex < 0;
        if (next == e || right_turn) next = it->second;
      }
      if (next == e) break;  // cannot happen for a closed boundary
      e = next;
    }
    // Drop corners where the direction does not change.
    std::vector<Corner> ring;
    const size_t n = path.size();
    for (size_t i = 0; i < n; ++i) {
      const Corner& p = path[(i + n - 1) % n];
      const Corner& q = path[i];
      const Corner& s = path[(i + 1) % n];
      if ((q.x - p.x) * (s.y - q.y) - (q.y - p.y) * (s.x - q.x) != 0) ring.push_back(q);
    }
    rings.push_back(std::move(ring));
  }
  return rings;
}

long long TwiceArea(const std::vector<Corner>& ring) {
  long long a = 0;
  for (size_t i = 0; i < ring.size(); ++i) {
    const Corner& p = ring[i];
    const Corner& q = ring[(i + 1) % ring.size()];
    a += (long long)p.x * q.y - (long long)q.x * p.y;
  }
  return a;
}

std::vector<Vector2d> ToWorld(const std::vector<Corner>& ring, double res) {
  std::vector<Vector2d> out;
  out.reserve(ring.size());
  for (const Corner& c : ring) out.emplace_back(c.x * res, c.y * res);
  return out;
}

Prism PixelRectPrism(const PixelRect& r, int H, double res, double z0, double z1) {
  const double x0 = r.col0 * res, x1 = (r.col1 + 1) * res;
  const double y0 = (H - 1 - r.row1) * res, y1 = (H - r.row0) * res;
  Prism p;
  p.footprint = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  p.z0 = z0;
  p.z1 = z1;
  return p;
}

std::vector<float> DistanceToNonZero(const Grid& g) {
  std::vector<uint8_t> blocked(g.v.size());
  for (size_t i = 0; i < g.v.size(); ++i) blocked[i] = g.v[i] != 0;
  return DistanceToBlocked(blocked, g.width, g.height);  // row-major, same layout
}

// Rooms: kept regions (≥ min pixels) of the rooms mask, relabelled 1..n largest first.
Grid RoomLabels(const Grid& free_mask, int min_pixels, int* n_rooms) {
  int n = 0;
  Grid comp = Components(free_mask, /*eight_connected=*/true, &n);
  std::vector<long> count(n + 1, 0);
  for (int l : comp.v) ++count[l];
  std::vector<int> order;
  for (int l = 1; l <= n; ++l) {
    if (count[l] >= min_pixels) order.push_back(l);
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return count[a] > count[b]; });
  std::vector<int> relabel(n + 1, 0);
  for (size_t i = 0; i < order.size(); ++i) relabel[order[i]] = int(i) + 1;
  for (int& l : comp.v) l = relabel[l];
  *n_rooms = static_cast<int>(order.size());
  return comp;
}

// Walkable pixels at one clearance, their 4-connected components, and which rooms the best
// component reaches.
struct NavChoice {
  double clearance_m = 0;
  Grid walkable;
  Grid components;
  int main_component = 0;
  std::vector<bool> reached;  // per room label − 1
  int n_reached = 0;
};

NavChoice EvaluateClearance(const Grid& occupied, const std::vector<float>& dist, const Grid& rooms,
                            int n_rooms, double res, double clearance) {
  NavChoice c;
  c.clearance_m = clearance;
  c.walkable = Grid{occupied.width, occupied.height, std::vector<int>(occupied.v.size(), 0)};
  for (size_t i = 0; i < occupied.v.size(); ++i) {
    c.walkable.v[i] = !occupied.v[i] && dist[i] * res >= clearance - 1e-9;
  }
  int n = 0;
  c.components = Components(c.walkable, /*eight_connected=*/false, &n);
  // rooms touched per component
  std::vector<std::vector<bool>> touches(n + 1, std::vector<bool>(n_rooms, false));
  for (size_t i = 0; i < rooms.v.size(); ++i) {
    if (rooms.v[i] && c.components.v[i]) touches[c.components.v[i]][rooms.v[i] - 1] = true;
  }
  int best = 0, best_count = -1;
  for (int k = 1; k <= n; ++k) {
    const int cnt = static_cast<int>(std::count(touches[k].begin(), touches[k].end(), true));
    if (cnt > best_count) best = k, best_count = cnt;
  }
  c.main_component = best;
  c.reached = best ? touches[best] : std::vector<bool>(n_rooms, false);
  c.n_reached = std::max(best_count, 0);
  return c;
}

// Doors from the ground truth: the lines drawn across doorways are pixels free in the map but
// occupied in the segmentation (SOURCES.md). Each 8-connected line touching two rooms is a door
// between them; its segment runs along the line's principal axis, pixel edge to pixel edge.
std::vector<DoorTruth> DoorsFromSeparators(const Grid& plain, const Grid& gt_occupied,
                                           const Grid& rooms, double res) {
  const int W = plain.width, H = plain.height;
  Grid sep{W, H, std::vector<int>(plain.v.size(), 0)};
  for (size_t i = 0; i < sep.v.size(); ++i) sep.v[i] = !plain.v[i] && gt_occupied.v[i];
  int n = 0;
  const Grid comp = Components(sep, /*eight_connected=*/true, &n);
  std::vector<std::vector<std::pair<int, int>>> pixels(n + 1);
  std::vector<std::map<int, int>> contacts(n + 1);  // room label → touching pixel count
  for (int r = 0; r < H; ++r) {
    for (int c = 0; c < W; ++c) {
      const int k = comp.v[comp.Index(r, c)];
      if (!k) continue;
      pixels[k].emplace_back(r, c);
      const int nr[4] = {r + 1, r - 1, r, r}, nc[4] = {c, c, c + 1, c - 1};
      for (int j = 0; j < 4; ++j) {
        if (nr[j] < 0 || nc[j] < 0 || nr[j] >= H || nc[j] >= W) continue;
        if (const int room = rooms.v[rooms.Index(nr[j], nc[j])]) ++contacts[k][room];
      }
    }
  }
  std::vector<DoorTruth> doors;
  for (int k = 1; k <= n; ++k) {
    if (contacts[k].size() < 2 || pixels[k].size() < 3) continue;
    std::vector<std::pair<int, int>> by_count;  // (count, room)
    for (const auto& [room, cnt] : contacts[k]) by_count.emplace_back(cnt, room);
    std::sort(by_count.rbegin(), by_count.rend());
    // Principal axis of the pixel centres.
    Vector2d mean = Vector2d::Zero();
    std::vector<Vector2d> pts;
    for (const auto& [r, c] : pixels[k]) pts.emplace_back((c + 0.5) * res, (H - 1 - r + 0.5) * res);
    for (const auto& p : pts) mean += p;
    mean /= double(pts.size());
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const auto& p : pts) cov += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    const Vector2d axis = eig.eigenvectors().col(1);
    double lo = 1e30, hi = -1e30;
    for (const auto& p : pts) {
      lo = std::min(lo, (p - mean).dot(axis));
      hi = std::max(hi, (p - mean).dot(axis));
    }
    // A pixel's half extent along the axis (a pixel is a square of side res).
    const double half = 0.5 * res * (std::abs(axis.x()) + std::abs(axis.y()));
    DoorTruth d;
    d.id = static_cast<int>(doors.size());
    d.level = 0;
    d.room_a = std::min(by_count[0].second, by_count[1].second) - 1;
    d.room_b = std::max(by_count[0].second, by_count[1].second) - 1;
    d.p0 = mean + (lo - half) * axis;
    d.p1 = mean + (hi + half) * axis;
    d.width = (d.p1 - d.p0).norm();
    doors.push_back(d);
  }
  return doors;
}

}  // namespace

absl::Status FloormapOptions::Validate() const {
  if (map_path.empty()) return absl::InvalidArgumentError("floor map: map_path is empty");
  if (!(resolution_m > 0) || !(ceiling_height_m > 0) || !(furniture_height_m > 0) ||
      furniture_height_m >= ceiling_height_m) {
    return absl::InvalidArgumentError(
        "floor map: resolution, ceiling and furniture heights must be > 0 (furniture below "
        "the ceiling)");
  }
  if (!(min_clearance_m > 0) || min_clearance_m > clearance_m) {
    return absl::InvalidArgumentError("floor map: need 0 < min_clearance_m <= clearance_m");
  }
  return absl::OkStatus();
}

FloormapOptions FloormapOptionsFor(const std::string& dir, const std::string& name) {
  FloormapOptions o;
  o.map_path = absl::StrCat(dir, "/", name, ".png");
  o.furniture_map_path = absl::StrCat(dir, "/", name, "_furnitures.png");
  o.rooms_map_path = absl::StrCat(dir, "/", name, "_gt_segmentation.png");
  return o;
}

absl::StatusOr<Building> MakeFloormapBuilding(const FloormapOptions& options,
                                              FloormapReport* report) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<Grid> plain = ReadOccupancy(options.map_path, nullptr);
  if (!plain.ok()) return plain.status();
  const int W = plain->width, H = plain->height;
  const double res = options.resolution_m, ceil = options.ceiling_height_m;
  Grid furnished = *plain;
  if (!options.furniture_map_path.empty()) {
    absl::StatusOr<Grid> f = ReadOccupancy(options.furniture_map_path, &*plain);
    if (!f.ok()) return f.status();
    for (size_t i = 0; i < furnished.v.size(); ++i) furnished.v[i] = plain->v[i] || f->v[i];
  }
  Grid room_free{W, H, std::vector<int>(plain->v.size())};
  std::optional<Grid> gt_occupied;
  if (!options.rooms_map_path.empty()) {
    absl::StatusOr<Grid> gt = ReadOccupancy(options.rooms_map_path, &*plain);
    if (!gt.ok()) return gt.status();
    for (size_t i = 0; i < gt->v.size(); ++i) room_free.v[i] = !gt->v[i];
    gt_occupied = *std::move(gt);
  } else {
    for (size_t i = 0; i < plain->v.size(); ++i) room_free.v[i] = !plain->v[i];
  }

  Building b;
  b.name = options.map_path.substr(options.map_path.find_last_of('/') + 1);
  if (b.name.size() > 4 && b.name.ends_with(".png")) b.name.resize(b.name.size() - 4);
  b.levels.push_back({0, 0.0, ceil});
  FloormapReport rep;

  // Walls: visible occupied pixels, rectangle-merged, floor to ceiling.
  {
    Grid free_px{W, H, std::vector<int>(plain->v.size())};
    for (size_t i = 0; i < plain->v.size(); ++i) free_px.v[i] = !plain->v[i];
    const std::vector<float> to_free = DistanceToNonZero(free_px);
    Grid walls{W, H, std::vector<int>(plain->v.size(), 0)};
    for (size_t i = 0; i < walls.v.size(); ++i) {
      walls.v[i] = plain->v[i] && to_free[i] * res <= kVisibleWallDepth_m;
    }
    for (const PixelRect& r : MergeRects(walls)) {
      b.structure.push_back(PixelRectPrism(r, H, res, 0.0, ceil));
    }
    rep.wall_prisms = static_cast<int>(b.structure.size());
  }
  // Floor and ceiling slabs over the whole map.
  const PixelRect all{0, H - 1, 0, W - 1, 1};
  b.structure.push_back(PixelRectPrism(all, H, res, -kSlabT, 0.0));
  b.structure.push_back(PixelRectPrism(all, H, res, ceil, ceil + kSlabT));

  // Furniture: occupied only in the furnished map; one object per 8-connected component.
  {
    Grid mask{W, H, std::vector<int>(plain->v.size())};
    for (size_t i = 0; i < mask.v.size(); ++i) mask.v[i] = furnished.v[i] && !plain->v[i];
    int n = 0;
    const Grid comp = Components(mask, /*eight_connected=*/true, &n);
    b.objects.resize(n);
    for (int k = 0; k < n; ++k) {
      b.objects[k].id = k;
      b.objects[k].kind = "furniture";
      b.objects[k].level = 0;
    }
    for (const PixelRect& r : MergeRects(comp)) {
      b.objects[r.label - 1].parts.push_back(
          PixelRectPrism(r, H, res, 0.0, options.furniture_height_m));
    }
    rep.furniture_objects = n;
  }

  // Rooms, traced exactly from their pixel regions.
  int n_rooms = 0;
  const Grid rooms = RoomLabels(room_free, options.min_room_pixels, &n_rooms);
  {
    std::vector<std::array<int, 4>> bbox(n_rooms, {H, -1, W, -1});  // r0 r1 c0 c1
    for (int r = 0; r < H; ++r) {
      for (int c = 0; c < W; ++c) {
        const int l = rooms.v[rooms.Index(r, c)];
        if (!l) continue;
        auto& bb = bbox[l - 1];
        bb = {std::min(bb[0], r), std::max(bb[1], r), std::min(bb[2], c), std::max(bb[3], c)};
      }
    }
    for (int k = 0; k < n_rooms; ++k) {
      RoomTruth room;
      room.id = k;
      room.level = 0;
      room.floor_z = 0;
      room.ceiling_z = ceil;
      const auto& bb = bbox[k];
      for (auto& ring : TraceRings(rooms, k + 1, bb[0], bb[1], bb[2], bb[3])) {
        if (TwiceArea(ring) > 0) {
          room.polygon = ToWorld(ring, res);
        } else {
          room.holes.push_back(ToWorld(ring, res));
        }
      }
      b.rooms.push_back(std::move(room));
    }
  }

  if (gt_occupied) b.doors = DoorsFromSeparators(*plain, *gt_occupied, rooms, res);

  // Nav grid: the furnished map's free pixels with clearance, relaxed if rooms are cut off.
  const std::vector<float> dist = DistanceToNonZero(furnished);
  NavChoice choice;
  for (double c = options.clearance_m; c >= options.min_clearance_m - 1e-9; c -= 0.025) {
    NavChoice trial = EvaluateClearance(furnished, dist, rooms, n_rooms, res, c);
    if (trial.n_reached > choice.n_reached || choice.walkable.v.empty()) choice = std::move(trial);
    if (choice.n_reached == n_rooms) break;
  }
  rep.clearance_used_m = choice.clearance_m;
  NavGrid nav;
  nav.origin = Vector2d::Zero();
  nav.resolution_m = res;
  nav.width = W;
  nav.height = H;
  nav.free.assign(size_t(W) * H, 0);
  for (int r = 0; r < H; ++r) {
    for (int c = 0; c < W; ++c) {
      nav.free[size_t(H - 1 - r) * W + c] = choice.walkable.v[plain->Index(r, c)] != 0;
    }
  }
  b.nav.push_back(std::move(nav));

  // Visit points: the most open pixel of each room in the main walkable component.
  std::vector<long> best(n_rooms, -1);
  for (size_t i = 0; i < rooms.v.size(); ++i) {
    const int l = rooms.v[i];
    if (!l || choice.components.v[i] != choice.main_component || !choice.main_component) continue;
    if (best[l - 1] < 0 || dist[i] > dist[best[l - 1]]) best[l - 1] = long(i);
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (int k = 0; k < n_rooms; ++k) {
    if (best[k] < 0) {
      b.rooms[k].entered = false;
      rep.unentered_rooms.push_back(k);
      b.visit_points.emplace_back(nan, nan);
      continue;
    }
    const int r = int(best[k] / W), c = int(best[k] % W);
    b.visit_points.emplace_back((c + 0.5) * res, (H - 1 - r + 0.5) * res);
  }
  if (report) *report = rep;
  return b;
}

}  // namespace carvemap
