#include "services/floorplan/export/floorplan_export.h"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "services/floorplan/model/extrusion.h"
#include "services/floorplan/model/floorplan_simplify.h"
#include "services/floorplan/test_plans.h"
#include "services/mesh/mesh_checks.h"

namespace carvemap {
namespace {

// 6 × 4 m: room 0 (x < 3) around a 1 m column at (1..2, 1..2), area 11; room 1 (x ≥ 3, y < 2),
// area 6; room 2 in two pieces, (3..4, 2..4) and (5..6, 2..4), area 4, with (4..5, 2..4) outside.
FloorPlan SamplePlan() {
  FloorPlan plan = GridPlan(
      6, 4, 1.0,
      [](int i, int j) {
        if (i < 3) return i == 1 && j == 1 ? -1 : 0;
        if (j < 2) return 1;
        return i == 4 ? -1 : 2;
      },
      3);
  for (int r = 0; r < 3; ++r) {
    plan.rooms[r].floor_z = 0.25 * r;
    plan.rooms[r].ceiling_z = 2.5 + 0.25 * r;
  }
  plan.rooms[0].seed_triangle = 0;  // a triangle in the corner cell
  plan.rooms[1].seed_triangle = 0;  // not one of room 1's: the largest of its own is used
  return plan;
}

double ClosedRingArea(const nlohmann::json& ring) {
  double twice = 0;
  for (size_t i = 0; i + 1 < ring.size(); ++i) {
    twice += ring[i][0].get<double>() * ring[i + 1][1].get<double>() -
             ring[i + 1][0].get<double>() * ring[i][1].get<double>();
  }
  return 0.5 * twice;
}

// Checks a Polygon's rings (RFC 7946) and returns its area.
double CheckPolygon(const nlohmann::json& rings) {
  EXPECT_GE(rings.size(), 1u);
  double area = 0;
  for (size_t k = 0; k < rings.size(); ++k) {
    const nlohmann::json& ring = rings[k];
    EXPECT_GE(ring.size(), 4u);
    EXPECT_EQ(ring.front(), ring.back()) << "ring not closed";
    const double a = ClosedRingArea(ring);
    if (k == 0) {
      EXPECT_GT(a, 0) << "exterior ring not CCW";
    } else {
      EXPECT_LT(a, 0) << "hole not CW";
    }
    area += a;
  }
  return area;
}

bool InsideRings(const nlohmann::json& rings, double x, double y) {
  bool inside = false;
  for (const nlohmann::json& ring : rings) {
    for (size_t i = 0, j = ring.size() - 2; i + 1 < ring.size(); j = i++) {
      const double xi = ring[i][0], yi = ring[i][1], xj = ring[j][0], yj = ring[j][1];
      if ((yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi) inside = !inside;
    }
  }
  return inside;
}

// Tags open and close in order (<?...?> and <.../> aside); false on the first mismatch.
bool BalancedTags(const std::string& xml) {
  std::vector<std::string> open;
  for (size_t at = xml.find('<'); at != std::string::npos; at = xml.find('<', at + 1)) {
    const size_t end = xml.find('>', at);
    if (end == std::string::npos) return false;
    const std::string tag = xml.substr(at + 1, end - at - 1);
    if (tag.empty() || tag[0] == '?' || tag[0] == '!') continue;
    if (tag[0] == '/') {
      if (open.empty() || open.back() != tag.substr(1)) return false;
      open.pop_back();
    } else if (tag.back() != '/') {
      open.push_back(tag.substr(0, tag.find_first_of(" \n")));
    }
  }
  return open.empty();
}

size_t Count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

TEST(FloorPlanExportTest, GeoJsonRoundTrip) {
  const FloorPlan plan = SamplePlan();
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  const nlohmann::json parsed = nlohmann::json::parse(FloorPlanGeoJson(plan, *outline).dump());
  EXPECT_EQ(parsed["type"], "FeatureCollection");
  const nlohmann::json& features = parsed["features"];
  const double expected_area[3] = {11, 6, 4};
  int rooms = 0, walls = 0;
  for (const nlohmann::json& f : features) {
    EXPECT_EQ(f["type"], "Feature");
    const nlohmann::json& g = f["geometry"];
    const nlohmann::json& p = f["properties"];
    EXPECT_EQ(p["level"], 0);
    if (g["type"] == "LineString") {
      ++walls;
      EXPECT_EQ(p["kind"], "wall");
      EXPECT_EQ(g["coordinates"].front(), g["coordinates"].back());
      continue;
    }
    const int r = p["room"];
    ASSERT_EQ(r, rooms) << "rooms in order, one feature each";
    ++rooms;
    EXPECT_DOUBLE_EQ(p["floor_z"].get<double>(), 0.25 * r);
    EXPECT_DOUBLE_EQ(p["ceiling_z"].get<double>(), 2.5 + 0.25 * r);
    double area = 0;
    if (r == 2) {
      ASSERT_EQ(g["type"], "MultiPolygon");
      ASSERT_EQ(g["coordinates"].size(), 2u);
      for (const nlohmann::json& polygon : g["coordinates"]) area += CheckPolygon(polygon);
    } else {
      ASSERT_EQ(g["type"], "Polygon");
      area = CheckPolygon(g["coordinates"]);
      EXPECT_EQ(g["coordinates"].size(), r == 0 ? 2u : 1u);  // room 0 has its column's hole
    }
    EXPECT_NEAR(area, expected_area[r], 1e-12);
    EXPECT_NEAR(p["area_m2"].get<double>(), area, 1e-12);
  }
  EXPECT_EQ(rooms, 3);
  EXPECT_EQ(walls, 2);  // around the plan (room 2's gap is a notch from the top) and the column
}

TEST(FloorPlanExportTest, SvgIsWellFormedWithOnePathAndLabelPerRoom) {
  const FloorPlan plan = SamplePlan();
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  const std::string svg = FloorPlanSvg(plan, *outline);
  const size_t start = svg.find("<svg");
  ASSERT_NE(start, std::string::npos);
  EXPECT_EQ(svg.find('<'), svg.find("<?xml"));
  EXPECT_EQ(svg.substr(svg.size() - 7), "</svg>\n");
  EXPECT_TRUE(BalancedTags(svg));
  EXPECT_EQ(Count(svg, "<path"), 3u);
  EXPECT_EQ(Count(svg, "<polyline"), outline->walls.size());
  EXPECT_EQ(Count(svg, "<text class=\"area\""), 3u);
  for (const char* label : {">11.0 m\u00b2<", ">6.0 m\u00b2<", ">4.0 m\u00b2<"}) {
    EXPECT_NE(svg.find(label), std::string::npos) << label;
  }
  EXPECT_NE(svg.find(">1 m</text>"), std::string::npos);  // the scale bar
  // Each label sits inside its room: map it back (100 px/m, 40 px margin, y flipped, plan
  // bounds 0..6 × 0..4) and test it against the GeoJSON rings.
  const nlohmann::json geo = FloorPlanGeoJson(plan, *outline);
  size_t at = 0;
  for (int r = 0; r < 3; ++r) {
    at = svg.find("<text class=\"area\" x=\"", at);
    ASSERT_NE(at, std::string::npos);
    at += 22;
    const double px = std::stod(svg.substr(at));
    const double py = std::stod(svg.substr(svg.find("y=\"", at) + 3));
    const double x = (px - 40) / 100, y = 4 - (py - 40) / 100;
    const nlohmann::json& g = geo["features"][r]["geometry"];
    bool inside = false;
    if (g["type"] == "Polygon") {
      inside = InsideRings(g["coordinates"], x, y);
    } else {
      for (const nlohmann::json& polygon : g["coordinates"]) inside |= InsideRings(polygon, x, y);
    }
    EXPECT_TRUE(inside) << "room " << r << " label at " << x << ", " << y;
  }
}

TEST(FloorPlanExportTest, WritesFilesAndPly) {
  const FloorPlan plan = SamplePlan();
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  const std::string dir = ::testing::TempDir() + "/level_0";
  ASSERT_TRUE(WriteFloorPlanFiles(dir, plan, *outline).ok());
  std::ifstream geojson(dir + "/floorplan.geojson");
  ASSERT_TRUE(geojson.good());
  EXPECT_EQ(nlohmann::json::parse(geojson), FloorPlanGeoJson(plan, *outline));
  std::ifstream svg_file(dir + "/floorplan.svg");
  std::stringstream svg;
  svg << svg_file.rdbuf();
  EXPECT_EQ(svg.str(), FloorPlanSvg(plan, *outline));
  EXPECT_TRUE(std::filesystem::is_regular_file(dir + "/floorplan.dxf"));  // floorplan_dxf_test
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
  ASSERT_TRUE(mesh.ok());
  ASSERT_TRUE(WriteExtrudedPly(dir + "/extruded.ply", *mesh).ok());
  absl::StatusOr<PlyMesh> back = ReadPly(dir + "/extruded.ply");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->mesh.triangles.size(), mesh->triangles.size());
  EXPECT_TRUE(CheckMesh(back->mesh).watertight()) << CheckMesh(back->mesh).ToString();
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
  }
  // A directory that cannot be made is an error naming it.
  const absl::Status bad = WriteFloorPlanFiles(dir + "/floorplan.svg/x", plan, *outline);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("floorplan.svg/x"), std::string::npos) << bad;
}

TEST(FloorPlanExportTest, WholeStageOnSixtyThousandTrianglesIsFast) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> noise(-0.01, 0.01);
  FloorPlan plan = GridPlan(
      200, 150, 0.05, [](int i, int j) { return (i / 100) + 2 * (j / 75); }, 4);
  for (size_t v = 0; v < plan.vertices.size(); ++v) {
    plan.vertices[v] += Eigen::Vector2d(noise(rng), noise(rng));
    plan.vertex_floor_z[v] = 0.1 * (v % 3) + 0.25 * (plan.vertices[v].x() > 5);
    plan.vertex_ceiling_z[v] = 2.5 + 0.1 * (v % 5) + 0.25 * (plan.vertices[v].y() > 3.75);
  }
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(SimplifyFloorPlan(plan, {.max_error_m = 0.05}).ok());
  const auto simplified = std::chrono::steady_clock::now();
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  ASSERT_TRUE(outline.ok());
  const auto traced = std::chrono::steady_clock::now();
  AssignRoomHeights(plan);
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(plan);
  ASSERT_TRUE(mesh.ok());
  const auto extruded = std::chrono::steady_clock::now();
  const std::string geojson = FloorPlanGeoJson(plan, *outline).dump();
  const std::string svg = FloorPlanSvg(plan, *outline);
  const auto exported = std::chrono::steady_clock::now();
  auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  std::cout << "60k triangles: simplify " << ms(start, simplified) << " ms, trace "
            << ms(simplified, traced) << " ms, heights+extrude " << ms(traced, extruded)
            << " ms, geojson+svg " << ms(extruded, exported) << " ms; " << plan.triangles.size()
            << " triangles left, " << mesh->triangles.size() << " mesh triangles\n";
  EXPECT_TRUE(CheckMesh(*mesh).watertight()) << CheckMesh(*mesh).ToString();
  EXPECT_EQ(outline->rooms.size(), 4u);
  EXPECT_LT(ms(start, exported), 1000.0);
}

}  // namespace
}  // namespace carvemap
