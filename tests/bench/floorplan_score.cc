// Scores a floor plan the 3D route wrote (OUT/level_<k>/floorplan.geojson, docs/DESIGN.md §7)
// against a real map's ground-truth rooms (tests/data/floormaps/*_gt_segmentation.png,
// SOURCES.md), with the same metrics as the 2D route's evaluation
// (services/floorplan/eval/room_scoring.h: room F1 at IoU > 0.5, one-to-one; Bormann et al.'s
// overlap recall / precision). Used by tests/bench/floorplan_3d_eval.sh.
//
//   floorplan_score --geojson OUT/level_0/floorplan.geojson --gt MAP_gt_segmentation.png
//                   [--resolution 0.05] [--origin-x 0] [--origin-y 0]
//                   [--affine a11,a12,b1,a21,a22,b2] [--entered-scan SCAN.h5] [--rooms]
//
// Frames: `carvemap simulate --floormap` extrudes pixel (row, col) of an H-row map to
// x = col·res, y = (H−1−row)·res (docs/DESIGN.md §4, lower-left origin), the frame
// RasterizeFloorPlan uses with origin (0, 0); the plan's polygons are in the world frame of the
// scan, so a map simulated with defaults needs no offset.
//
// --affine maps the plan (and the scan's path) into the map's frame first: [x_map, y_map] =
// A·[x, y] + b, the 2×3 matrix [A | b] row by row (a real log's frame is not the map's: the
// registration the CARMEN logs come with, tests/data/SOURCES.md). --entered-scan scores against the
// truth rooms its /path enters only (room_scoring.h KeepEnteredRooms): a survey that skipped rooms
// is judged on the rooms it could know.
//
// Prints one line of key=value pairs (truth_rooms, predicted_rooms, matched, precision, recall,
// f1, bormann_recall, bormann_precision, plan_rooms = room features in the file,
// all_truth_rooms = the map's rooms before --entered-scan); with --rooms, then one line per scored
// truth room (room_scoring.h TruthRoomScore), to see which rooms a plan misses and by how much.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "CLI/CLI.hpp"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "nlohmann/json.hpp"
#include "services/floorplan/eval/room_scoring.h"
#include "storage/png_io.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

using Ring = std::vector<Eigen::Vector2d>;
// One polygon: outer ring then holes (GeoJSON order).
using Polygon = std::vector<Ring>;

struct PlanRoom {
  int label = 0;
  std::vector<Polygon> polygons;
};

absl::StatusOr<Ring> ParseRing(const nlohmann::json& j, const std::string& where) {
  if (!j.is_array()) return absl::InvalidArgumentError(where + ": a ring is not an array");
  Ring ring;
  for (const nlohmann::json& p : j) {
    if (!p.is_array() || p.size() < 2 || !p[0].is_number() || !p[1].is_number()) {
      return absl::InvalidArgumentError(where + ": a position is not [x, y]");
    }
    ring.emplace_back(p[0].get<double>(), p[1].get<double>());
    if (!ring.back().allFinite()) {
      return absl::InvalidArgumentError(where + ": a position is not finite");
    }
  }
  return ring;
}

absl::StatusOr<Polygon> ParsePolygon(const nlohmann::json& j, const std::string& where) {
  if (!j.is_array()) return absl::InvalidArgumentError(where + ": a polygon is not an array");
  Polygon polygon;
  for (const nlohmann::json& r : j) {
    absl::StatusOr<Ring> ring = ParseRing(r, where);
    if (!ring.ok()) return ring.status();
    polygon.push_back(*std::move(ring));
  }
  return polygon;
}

// The room features (Polygon / MultiPolygon with a "room" property) of a floorplan.geojson;
// walls (LineStrings) are skipped.
absl::StatusOr<std::vector<PlanRoom>> ReadPlanRooms(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  nlohmann::json doc = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return absl::InvalidArgumentError(path + ": not valid JSON");
  if (!doc.contains("features") || !doc["features"].is_array()) {
    return absl::InvalidArgumentError(path + ": no \"features\" array (not a FeatureCollection)");
  }
  std::vector<PlanRoom> rooms;
  int index = 0;
  for (const nlohmann::json& f : doc["features"]) {
    const std::string where = absl::StrCat(path, ": feature ", index++);
    if (!f.is_object() || !f.contains("geometry") || !f["geometry"].is_object()) {
      return absl::InvalidArgumentError(where + ": no geometry object");
    }
    const nlohmann::json& g = f["geometry"];
    const std::string type = g.value("type", "");
    if (type != "Polygon" && type != "MultiPolygon") continue;
    if (!g.contains("coordinates")) return absl::InvalidArgumentError(where + ": no coordinates");
    PlanRoom room;
    room.label = static_cast<int>(rooms.size());
    if (type == "Polygon") {
      absl::StatusOr<Polygon> p = ParsePolygon(g["coordinates"], where);
      if (!p.ok()) return p.status();
      room.polygons.push_back(*std::move(p));
    } else {
      if (!g["coordinates"].is_array()) {
        return absl::InvalidArgumentError(where + ": MultiPolygon coordinates not an array");
      }
      for (const nlohmann::json& pj : g["coordinates"]) {
        absl::StatusOr<Polygon> p = ParsePolygon(pj, where);
        if (!p.ok()) return p.status();
        room.polygons.push_back(*std::move(p));
      }
    }
    rooms.push_back(std::move(room));
  }
  return rooms;
}

// Labels every pixel whose centre is inside the polygon (even-odd over its outer ring and its
// holes), pixel centres as in RasterizeFloorPlan. Hand-written: the plan's rooms come back as
// polygons here, not as the triangulation RasterizeFloorPlan takes, and a scanline fill of a
// few hundred rings is a few lines (no library call needed for pixel-centre point-in-polygon).
// Crossings are half-open in y (an edge holds y0 ≤ y < y1) so a centre on a shared vertex
// counts once.
void FillPolygon(const Polygon& polygon, int label, double res, double ox, double oy,
                 LabelImage& image) {
  double ymin = INFINITY, ymax = -INFINITY;
  for (const Ring& ring : polygon)
    for (const Eigen::Vector2d& p : ring) ymin = std::min(ymin, p.y()), ymax = std::max(ymax, p.y());
  if (!(ymin <= ymax)) return;
  const int H = image.height, W = image.width;
  // Row of centre y: y = oy + (H − 1 − row + 0.5)·res.
  const int row_lo = std::max(0, static_cast<int>(std::floor(H - 1 + 0.5 - (ymax - oy) / res)));
  const int row_hi = std::min(H - 1, static_cast<int>(std::ceil(H - 1 + 0.5 - (ymin - oy) / res)));
  std::vector<double> xs;
  for (int row = row_lo; row <= row_hi; ++row) {
    const double y = oy + (H - 1 - row + 0.5) * res;
    xs.clear();
    for (const Ring& ring : polygon) {
      const size_t n = ring.size();
      for (size_t i = 0; i < n; ++i) {
        const Eigen::Vector2d& a = ring[i];
        const Eigen::Vector2d& b = ring[(i + 1) % n];
        if ((a.y() <= y) == (b.y() <= y)) continue;  // not crossing, or horizontal
        xs.push_back(a.x() + (y - a.y()) * (b.x() - a.x()) / (b.y() - a.y()));
      }
    }
    std::sort(xs.begin(), xs.end());
    for (size_t k = 0; k + 1 < xs.size(); k += 2) {
      // Columns whose centre x = ox + (col + 0.5)·res lies in [xs[k], xs[k+1]).
      const int c0 = std::max(0, static_cast<int>(std::ceil((xs[k] - ox) / res - 0.5)));
      const int c1 = std::min(W - 1, static_cast<int>(std::ceil((xs[k + 1] - ox) / res - 0.5)) - 1);
      for (int col = c0; col <= c1; ++col) image.labels[size_t(row) * W + col] = label;
    }
  }
}

int Main(int argc, char** argv) {
  CLI::App app{"Score a floorplan.geojson against a ground-truth room segmentation PNG"};
  std::string geojson, gt_path;
  double res = 0.05, ox = 0, oy = 0;
  std::vector<double> affine;
  std::string entered_scan;
  app.add_option("--geojson", geojson, "level_<k>/floorplan.geojson")->required();
  app.add_option("--gt", gt_path, "*_gt_segmentation.png")->required();
  app.add_option("--resolution", res, "Metres per pixel of the map")->check(CLI::PositiveNumber);
  app.add_option("--origin-x", ox, "x of the map's lower-left corner, m");
  app.add_option("--origin-y", oy, "y of the map's lower-left corner, m");
  app.add_option("--affine", affine,
                 "Plan frame ➜ map frame, [A | b] row by row: a11,a12,b1,a21,a22,b2")
      ->delimiter(',')
      ->expected(6);
  app.add_option("--entered-scan", entered_scan,
                 "Score only the truth rooms this scan.h5's /path enters")
      ->check(CLI::ExistingFile);
  bool per_room = false;
  app.add_flag("--rooms", per_room,
               "Also list each scored truth room: its centre and area in the map's frame, and "
               "the predicted room of highest IoU with it");
  CLI11_PARSE(app, argc, argv);

  absl::StatusOr<Image<uint8_t>> gt = ReadPngGray8(gt_path);
  if (!gt.ok()) {
    std::fprintf(stderr, "floorplan_score: %s\n", std::string(gt.status().message()).c_str());
    return 1;
  }
  absl::StatusOr<std::vector<PlanRoom>> rooms = ReadPlanRooms(geojson);
  if (!rooms.ok()) {
    std::fprintf(stderr, "floorplan_score: %s\n", std::string(rooms.status().message()).c_str());
    return 1;
  }
  Eigen::Matrix2d A = Eigen::Matrix2d::Identity();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  if (!affine.empty()) {
    A << affine[0], affine[1], affine[3], affine[4];
    b << affine[2], affine[5];
  }
  for (PlanRoom& room : *rooms)
    for (Polygon& polygon : room.polygons)
      for (Ring& ring : polygon)
        for (Eigen::Vector2d& p : ring) p = A * p + b;
  LabelImage truth = LabelsFromSegmentation(*gt);
  const int all_truth_rooms = ScoreRooms(truth, truth)->truth_rooms;
  if (!entered_scan.empty()) {
    ScanReader::OpenOptions open;
    open.path_rows = ScanReader::PathRows::kNone;  // PathPositions reads the poses in blocks
    absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(entered_scan, open);
    if (!reader.ok()) {
      std::fprintf(stderr, "floorplan_score: %s\n", std::string(reader.status().message()).c_str());
      return 1;
    }
    absl::StatusOr<std::vector<Eigen::Vector3d>> path = (*reader)->PathPositions();
    if (!path.ok()) {
      std::fprintf(stderr, "floorplan_score: %s\n", std::string(path.status().message()).c_str());
      return 1;
    }
    std::vector<Eigen::Vector2d> walk;
    for (const Eigen::Vector3d& p : *path) walk.push_back(A * p.head<2>() + b);
    truth = KeepEnteredRooms(truth, walk, res, ox, oy);
  }
  LabelImage predicted{gt->width, gt->height,
                       std::vector<int32_t>(size_t(gt->width) * gt->height, -1)};
  for (const PlanRoom& room : *rooms)
    for (const Polygon& polygon : room.polygons)
      FillPolygon(polygon, room.label, res, ox, oy, predicted);
  absl::StatusOr<RoomScores> s = ScoreRooms(truth, predicted);
  if (!s.ok()) {
    std::fprintf(stderr, "floorplan_score: %s\n", std::string(s.status().message()).c_str());
    return 1;
  }
  std::printf(
      "truth_rooms=%d predicted_rooms=%d matched=%d precision=%.3f recall=%.3f f1=%.3f "
      "bormann_recall=%.3f bormann_precision=%.3f plan_rooms=%zu all_truth_rooms=%d\n",
      s->truth_rooms, s->predicted_rooms, s->matched, s->precision, s->recall, s->f1,
      s->bormann_recall, s->bormann_precision, rooms->size(), all_truth_rooms);
  if (per_room) {
    // Centres in the map's frame (pixel centres as in RasterizeFloorPlan).
    std::map<int32_t, Eigen::Vector3d> sums;  // x, y, pixels
    for (int row = 0; row < truth.height; ++row) {
      for (int col = 0; col < truth.width; ++col) {
        const int32_t t = truth.labels[size_t(row) * truth.width + col];
        if (t >= 0) {
          sums[t] +=
              Eigen::Vector3d(ox + (col + 0.5) * res, oy + (truth.height - 1 - row + 0.5) * res, 1);
        }
      }
    }
    const double px_m2 = res * res;
    for (const TruthRoomScore& r : s->per_truth) {
      const Eigen::Vector3d& c = sums[r.label];
      std::printf(
          "truth_room=%d centre=%.2f,%.2f area_m2=%.1f best_predicted=%d iou=%.3f "
          "predicted_area_m2=%.1f%s\n",
          r.label, c.x() / c.z(), c.y() / c.z(), double(r.pixels) * px_m2, r.best_predicted,
          r.best_iou, double(r.best_predicted_pixels) * px_m2, r.best_iou > 0.5 ? " matched" : "");
    }
  }
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
