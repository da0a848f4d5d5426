#include "services/floorplan/export/floorplan_export.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <system_error>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "services/floorplan/export/floorplan_dxf.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

nlohmann::json ClosedRing(const std::vector<Eigen::Vector2d>& ring) {
  nlohmann::json coords = nlohmann::json::array();
  for (const Eigen::Vector2d& p : ring) coords.push_back({p.x(), p.y()});
  if (!ring.empty()) coords.push_back({ring.front().x(), ring.front().y()});
  return coords;
}

nlohmann::json PolygonCoordinates(const RoomPolygon& piece) {
  nlohmann::json rings = nlohmann::json::array();
  rings.push_back(ClosedRing(piece.outer));
  for (const auto& hole : piece.holes) rings.push_back(ClosedRing(hole));
  return rings;
}

// Pieces of each room, in outline order.
std::vector<std::vector<const RoomPolygon*>> PiecesByRoom(const FloorPlan& plan,
                                                          const FloorPlanOutline& outline) {
  std::vector<std::vector<const RoomPolygon*>> pieces(plan.rooms.size());
  for (const RoomPolygon& piece : outline.rooms) {
    if (piece.room >= 0 && piece.room < static_cast<int>(pieces.size())) {
      pieces[piece.room].push_back(&piece);
    }
  }
  return pieces;
}

// Colour-blind-friendly light fills (Okabe–Ito hues, lightened), cycled by room index.
constexpr std::array<const char*, 8> kPalette = {"#f4c37a", "#9fd3f0", "#7fd1b5", "#f7ef9a",
                                                 "#86b6dd", "#f0a97f", "#e3b3cf", "#c8c8c8"};

}  // namespace

nlohmann::json FloorPlanGeoJson(const FloorPlan& plan, const FloorPlanOutline& outline) {
  nlohmann::json features = nlohmann::json::array();
  const auto pieces = PiecesByRoom(plan, outline);
  for (size_t r = 0; r < pieces.size(); ++r) {
    if (pieces[r].empty()) continue;
    nlohmann::json geometry;
    double area = 0;
    for (const RoomPolygon* piece : pieces[r]) area += piece->area_m2;
    if (pieces[r].size() == 1) {
      geometry = {{"type", "Polygon"}, {"coordinates", PolygonCoordinates(*pieces[r][0])}};
    } else {
      nlohmann::json polygons = nlohmann::json::array();
      for (const RoomPolygon* piece : pieces[r]) polygons.push_back(PolygonCoordinates(*piece));
      geometry = {{"type", "MultiPolygon"}, {"coordinates", polygons}};
    }
    features.push_back({{"type", "Feature"},
                        {"geometry", geometry},
                        {"properties",
                         {{"room", r},
                          {"level", plan.level},
                          {"floor_z", plan.rooms[r].floor_z},
                          {"ceiling_z", plan.rooms[r].ceiling_z},
                          {"area_m2", area}}}});
  }
  for (const auto& wall : outline.walls) {
    nlohmann::json coords = nlohmann::json::array();
    for (const Eigen::Vector2d& p : wall) coords.push_back({p.x(), p.y()});
    features.push_back({{"type", "Feature"},
                        {"geometry", {{"type", "LineString"}, {"coordinates", coords}}},
                        {"properties", {{"kind", "wall"}, {"level", plan.level}}}});
  }
  return {{"type", "FeatureCollection"}, {"features", features}};
}

std::string FloorPlanSvg(const FloorPlan& plan, const FloorPlanOutline& outline) {
  constexpr double kPxPerM = 100;
  constexpr double kMarginPx = 40;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  auto grow = [&](const std::vector<Eigen::Vector2d>& ring) {
    for (const Eigen::Vector2d& p : ring) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  };
  for (const RoomPolygon& piece : outline.rooms) grow(piece.outer);
  for (const auto& wall : outline.walls) grow(wall);
  if (!(lo.x() <= hi.x())) lo = hi = Eigen::Vector2d::Zero();
  const double width = (hi.x() - lo.x()) * kPxPerM + 2 * kMarginPx;
  const double height = (hi.y() - lo.y()) * kPxPerM + 3 * kMarginPx;  // room for the scale bar
  auto px = [&](const Eigen::Vector2d& p) {
    return absl::StrFormat("%.1f,%.1f", (p.x() - lo.x()) * kPxPerM + kMarginPx,
                           (hi.y() - p.y()) * kPxPerM + kMarginPx);  // y flipped: north up
  };
  std::string svg = absl::StrFormat(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
      "viewBox=\"0 0 %.0f %.0f\">\n",
      width, height, width, height);
  absl::StrAppend(&svg, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n");
  const auto pieces = PiecesByRoom(plan, outline);
  for (size_t r = 0; r < pieces.size(); ++r) {
    if (pieces[r].empty()) continue;
    std::string d;
    auto ring_path = [&](const std::vector<Eigen::Vector2d>& ring) {
      for (size_t i = 0; i < ring.size(); ++i) absl::StrAppend(&d, i ? " L" : "M", px(ring[i]));
      absl::StrAppend(&d, " Z ");
    };
    for (const RoomPolygon* piece : pieces[r]) {
      ring_path(piece->outer);
      for (const auto& hole : piece->holes) ring_path(hole);
    }
    absl::StrAppend(&svg, "<path class=\"room\" data-room=\"", r, "\" fill=\"",
                    kPalette[r % kPalette.size()], "\" fill-rule=\"evenodd\" stroke=\"none\" d=\"",
                    d, "\"/>\n");
  }
  for (const auto& wall : outline.walls) {
    std::string points;
    for (const Eigen::Vector2d& p : wall)
      absl::StrAppend(&points, points.empty() ? "" : " ", px(p));
    absl::StrAppend(&svg,
                    "<polyline class=\"wall\" fill=\"none\" stroke=\"black\" "
                    "stroke-width=\"3\" stroke-linejoin=\"round\" points=\"",
                    points, "\"/>\n");
  }
  for (size_t r = 0; r < pieces.size(); ++r) {
    if (pieces[r].empty()) continue;
    const std::optional<Eigen::Vector2d> c = RoomLabelPoint(plan, static_cast<int>(r));
    if (!c) continue;
    double area = 0;
    for (const RoomPolygon* piece : pieces[r]) area += piece->area_m2;
    const std::string at = px(*c);
    const size_t comma = at.find(',');
    absl::StrAppend(&svg, "<text class=\"area\" x=\"", at.substr(0, comma), "\" y=\"",
                    at.substr(comma + 1),
                    "\" font-family=\"sans-serif\" font-size=\"14\" text-anchor=\"middle\" "
                    "dominant-baseline=\"middle\">",
                    absl::StrFormat("%.1f", area), " m\u00b2</text>\n");
  }
  const double bar_m = hi.x() - lo.x() > 20 ? 5 : 1;
  const double y = height - kMarginPx;
  absl::StrAppend(&svg,
                  absl::StrFormat("<g class=\"scale\"><line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" "
                                  "y2=\"%.1f\" stroke=\"black\" stroke-width=\"3\"/>",
                                  kMarginPx, y, kMarginPx + bar_m * kPxPerM, y),
                  absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" "
                                  "font-size=\"12\" text-anchor=\"middle\">%.0f m</text></g>\n",
                                  kMarginPx + 0.5 * bar_m * kPxPerM, y - 6, bar_m));
  absl::StrAppend(&svg, "</svg>\n");
  return svg;
}

absl::Status WriteFloorPlanFiles(const std::string& dir, const FloorPlan& plan,
                                 const FloorPlanOutline& outline) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return absl::PermissionDeniedError(
        absl::StrCat("floorplan export: cannot create ", dir, ": ", ec.message()));
  }
  const std::string geojson = FloorPlanGeoJson(plan, outline).dump(1);
  if (absl::Status s = WriteFileAtomically(dir + "/floorplan.geojson",
                                           [&](std::ostream& out) { out << geojson << '\n'; });
      !s.ok()) {
    return s;
  }
  const std::string svg = FloorPlanSvg(plan, outline);
  if (absl::Status s =
          WriteFileAtomically(dir + "/floorplan.svg", [&](std::ostream& out) { out << svg; });
      !s.ok()) {
    return s;
  }
  return WriteFloorPlanDxf(dir + "/floorplan.dxf", plan, outline);
}

absl::Status WriteExtrudedPly(const std::string& path, const TriangleMesh& mesh) {
  return WritePly(path, mesh);
}

}  // namespace carvemap
