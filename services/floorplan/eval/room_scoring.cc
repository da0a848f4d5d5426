#include "services/floorplan/eval/room_scoring.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>
#include <utility>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// Centre of pixel index k (column, or row counted from the bottom) along one axis: the exact
// expression of the contract, so a centre that lies on an edge compares the same everywhere.
double Centre(double origin, double res, int k) { return origin + (k + 0.5) * res; }

// First index whose centre is ≥ v (the estimate can be off by one in floating point).
int FirstCentreAtLeast(double origin, double res, double v) {
  double e = std::ceil((v - origin) / res - 0.5);
  e = std::clamp(e, -1e9, 1e9);
  int k = static_cast<int>(e);
  while (Centre(origin, res, k - 1) >= v) --k;
  while (Centre(origin, res, k) < v) ++k;
  return k;
}

}  // namespace

LabelImage LabelsFromSegmentation(const Image<uint8_t>& gt, int free_at_least, int min_pixels) {
  LabelImage out;
  out.width = gt.width;
  out.height = gt.height;
  const size_t n = static_cast<size_t>(gt.width) * gt.height;
  out.labels.assign(n, -1);
  if (gt.pixels.size() != n) return out;
  // -2 = visited but not (yet) a room; rooms get their label once their size is known.
  std::vector<int32_t>& lab = out.labels;
  std::vector<size_t> region;
  int32_t next = 0;
  for (size_t start = 0; start < n; ++start) {
    if (lab[start] != -1 || gt.pixels[start] < free_at_least) continue;
    region.clear();
    region.push_back(start);
    lab[start] = -2;
    for (size_t head = 0; head < region.size(); ++head) {
      const int r = static_cast<int>(region[head] / gt.width);
      const int c = static_cast<int>(region[head] % gt.width);
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int rr = r + dr, cc = c + dc;
          if (rr < 0 || cc < 0 || rr >= gt.height || cc >= gt.width) continue;
          const size_t k = static_cast<size_t>(rr) * gt.width + cc;
          if (lab[k] != -1 || gt.pixels[k] < free_at_least) continue;
          lab[k] = -2;
          region.push_back(k);
        }
      }
    }
    const int32_t value = static_cast<int>(region.size()) >= min_pixels ? next++ : -3;
    for (size_t k : region) lab[k] = value;
  }
  for (int32_t& v : lab) {
    if (v < 0) v = -1;
  }
  return out;
}

LabelImage KeepEnteredRooms(const LabelImage& truth, const std::vector<Eigen::Vector2d>& points,
                            double resolution_m, double origin_x_m, double origin_y_m) {
  LabelImage out = truth;
  std::vector<int32_t> entered;
  for (const Eigen::Vector2d& p : points) {
    const double col = std::floor((p.x() - origin_x_m) / resolution_m);
    const double iy = std::floor((p.y() - origin_y_m) / resolution_m);
    if (!(col >= 0 && iy >= 0 && col < truth.width && iy < truth.height)) continue;
    const size_t k = static_cast<size_t>(truth.height - 1 - static_cast<int>(iy)) * truth.width +
                     static_cast<size_t>(col);
    if (k < truth.labels.size() && truth.labels[k] >= 0) entered.push_back(truth.labels[k]);
  }
  std::sort(entered.begin(), entered.end());
  for (int32_t& v : out.labels) {
    if (v >= 0 && !std::binary_search(entered.begin(), entered.end(), v)) v = -1;
  }
  return out;
}

LabelImage RasterizeFloorPlan(const FloorPlan& plan, int width, int height, double resolution_m,
                              double origin_x_m, double origin_y_m) {
  LabelImage out;
  out.width = std::max(width, 0);
  out.height = std::max(height, 0);
  out.labels.assign(static_cast<size_t>(out.width) * out.height, -1);
  if (out.labels.empty() || !(resolution_m > 0)) return out;
  const double res = resolution_m;
  const size_t nv = plan.vertices.size();
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    if (tri[0] >= nv || tri[1] >= nv || tri[2] >= nv) continue;
    const int room = t < plan.triangle_room.size() ? plan.triangle_room[t] : -1;
    // Edges with endpoints in a canonical order (lower y first, then lower x), so an edge shared
    // by two triangles gives bitwise the same x at every scanline; horizontal edges never cross
    // a scanline's half-open [y0, y1) and are dropped.
    struct Edge {
      Eigen::Vector2d p, q;
    };
    Edge edges[3];
    int n_edges = 0;
    double y_lo = INFINITY, y_hi = -INFINITY;
    for (int e = 0; e < 3; ++e) {
      Eigen::Vector2d p = plan.vertices[tri[e]], q = plan.vertices[tri[(e + 1) % 3]];
      y_lo = std::min(y_lo, p.y());
      y_hi = std::max(y_hi, p.y());
      if (p.y() == q.y()) continue;
      if (std::make_pair(q.y(), q.x()) < std::make_pair(p.y(), p.x())) std::swap(p, q);
      edges[n_edges++] = {p, q};
    }
    if (n_edges < 2 || !std::isfinite(y_lo) || !std::isfinite(y_hi)) continue;
    const int j_begin = std::max(0, FirstCentreAtLeast(origin_y_m, res, y_lo));
    const int j_end = std::min(out.height, FirstCentreAtLeast(origin_y_m, res, y_hi));
    for (int j = j_begin; j < j_end; ++j) {
      const double yc = Centre(origin_y_m, res, j);
      double xs[3];
      int n_active = 0;
      for (int e = 0; e < n_edges; ++e) {
        const Edge& ed = edges[e];
        if (yc < ed.p.y() || yc >= ed.q.y()) continue;
        xs[n_active++] = ed.p.x() + (yc - ed.p.y()) * (ed.q.x() - ed.p.x()) / (ed.q.y() - ed.p.y());
      }
      if (n_active != 2) continue;  // degenerate (collinear) triangle
      const double xl = std::min(xs[0], xs[1]), xr = std::max(xs[0], xs[1]);
      const int c_begin = std::max(0, FirstCentreAtLeast(origin_x_m, res, xl));
      const int c_end = std::min(out.width, FirstCentreAtLeast(origin_x_m, res, xr));
      int32_t* row = out.labels.data() + static_cast<size_t>(out.height - 1 - j) * out.width;
      for (int c = c_begin; c < c_end; ++c) row[c] = room;
    }
  }
  return out;
}

absl::StatusOr<RoomScores> ScoreRooms(const LabelImage& truth, const LabelImage& predicted) {
  if (truth.width != predicted.width || truth.height != predicted.height) {
    return absl::InvalidArgumentError(absl::StrCat("room scoring: truth is ", truth.width, "×",
                                                   truth.height, " but prediction is ",
                                                   predicted.width, "×", predicted.height));
  }
  const size_t n = static_cast<size_t>(truth.width) * truth.height;
  if (truth.labels.size() != n || predicted.labels.size() != n) {
    return absl::InvalidArgumentError(
        absl::StrCat("room scoring: ", truth.labels.size(), " truth and ", predicted.labels.size(),
                     " predicted labels for ", truth.width, "×", truth.height, " pixels"));
  }
  std::unordered_map<int32_t, int64_t> truth_area, pred_area;
  std::unordered_map<uint64_t, int64_t> overlap;  // (truth, predicted) → pixels
  for (size_t k = 0; k < n; ++k) {
    const int32_t t = truth.labels[k];
    if (t < 0) continue;  // outside the scoring domain
    ++truth_area[t];
    const int32_t p = predicted.labels[k];
    if (p < 0) continue;
    ++pred_area[p];
    ++overlap[(static_cast<uint64_t>(static_cast<uint32_t>(t)) << 32) | static_cast<uint32_t>(p)];
  }
  // Largest overlap per room on each side, in label order so the means sum deterministically.
  std::map<int32_t, int64_t> best_t, best_p;
  for (const auto& [t, a] : truth_area) best_t[t] = 0;
  for (const auto& [p, a] : pred_area) best_p[p] = 0;
  std::map<int32_t, bool> matched_t;
  std::map<int32_t, TruthRoomScore> per_truth;
  for (const auto& [t, a] : truth_area) per_truth[t] = TruthRoomScore{.label = t, .pixels = a};
  for (const auto& [key, o] : overlap) {
    const int32_t t = static_cast<int32_t>(key >> 32);
    const int32_t p = static_cast<int32_t>(key & 0xffffffffu);
    best_t[t] = std::max(best_t[t], o);
    best_p[p] = std::max(best_p[p], o);
    // IoU > 0.5 needs the overlap to exceed half of each room, and two predicted rooms are
    // disjoint, so at most one can do it for a truth room (and vice versa): the match is one to
    // one without any assignment step.
    const int64_t uni = truth_area[t] + pred_area[p] - o;
    if (2 * o > uni) matched_t[t] = true;
    TruthRoomScore& r = per_truth[t];
    const double iou = double(o) / double(uni);
    // Ties go to the lower predicted label, so the listing does not follow the hash order.
    if (iou > r.best_iou || (iou == r.best_iou && r.best_predicted >= 0 && p < r.best_predicted)) {
      r.best_iou = iou;
      r.best_predicted = p;
      r.best_predicted_pixels = pred_area[p];
    }
  }
  RoomScores s;
  s.truth_rooms = static_cast<int>(truth_area.size());
  s.predicted_rooms = static_cast<int>(pred_area.size());
  s.matched = static_cast<int>(matched_t.size());
  if (s.predicted_rooms > 0) s.precision = double(s.matched) / s.predicted_rooms;
  if (s.truth_rooms > 0) s.recall = double(s.matched) / s.truth_rooms;
  if (s.precision + s.recall > 0) {
    s.f1 = 2 * s.precision * s.recall / (s.precision + s.recall);
  }
  double sum = 0;
  for (const auto& [t, o] : best_t) sum += double(o) / truth_area[t];
  if (!best_t.empty()) s.bormann_recall = sum / best_t.size();
  sum = 0;
  for (const auto& [p, o] : best_p) sum += double(o) / pred_area[p];
  if (!best_p.empty()) s.bormann_precision = sum / best_p.size();
  for (auto& [t, r] : per_truth) s.per_truth.push_back(r);
  return s;
}

}  // namespace carvemap
