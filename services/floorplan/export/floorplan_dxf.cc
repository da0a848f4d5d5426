#include "services/floorplan/export/floorplan_dxf.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <utility>

#include <dxflib/dl_dxf.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "storage/atomic_file.h"

namespace carvemap {

std::vector<std::vector<Eigen::Vector2d>> RoomBorders(const FloorPlan& plan) {
  // Each undirected edge with the rooms of its triangles; an edge of two rooms is a border.
  std::map<std::pair<uint32_t, uint32_t>, int> room_of_edge;
  std::map<uint32_t, std::vector<uint32_t>> next;  // border graph, neighbours sorted below
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    for (int e = 0; e < 3; ++e) {
      uint32_t a = plan.triangles[t][e], b = plan.triangles[t][(e + 1) % 3];
      if (a > b) std::swap(a, b);
      const auto [it, inserted] = room_of_edge.emplace(std::make_pair(a, b), plan.triangle_room[t]);
      if (!inserted && it->second != plan.triangle_room[t]) {
        next[a].push_back(b);
        next[b].push_back(a);
      }
    }
  }
  for (auto& [v, ns] : next) std::sort(ns.begin(), ns.end());
  std::map<std::pair<uint32_t, uint32_t>, bool> used;
  const auto take = [&](uint32_t a, uint32_t b) {
    return !std::exchange(used[{std::min(a, b), std::max(a, b)}], true);
  };
  const auto unused_from = [&](uint32_t v) -> std::optional<uint32_t> {
    for (uint32_t n : next[v]) {
      if (!used[{std::min(v, n), std::max(v, n)}]) return n;
    }
    return std::nullopt;
  };
  std::vector<std::vector<Eigen::Vector2d>> chains;
  // Open chains run between vertices where the borders do not simply pass through (a wall, a
  // meeting of three rooms); then what is left are closed loops (a room inside another).
  for (const bool ends : {true, false}) {
    for (const auto& [v0, ns] : next) {
      if (ends == (ns.size() == 2)) continue;
      while (std::optional<uint32_t> n = unused_from(v0)) {
        std::vector<Eigen::Vector2d> chain = {plan.vertices[v0]};
        uint32_t prev = v0, at = *n;
        take(prev, at);
        while (true) {
          chain.push_back(plan.vertices[at]);
          if (next[at].size() != 2 || at == v0) break;
          const uint32_t to = next[at][0] == prev ? next[at][1] : next[at][0];
          if (!take(at, to)) break;
          prev = std::exchange(at, to);
        }
        chains.push_back(std::move(chain));
      }
    }
  }
  return chains;
}

namespace {

constexpr char kRooms[] = "ROOMS";
constexpr char kWalls[] = "WALLS";
constexpr char kDoors[] = "DOORS";
constexpr char kLabels[] = "LABELS";

void WritePolyline(DL_Dxf& dxf, DL_WriterA& dw, const std::vector<Eigen::Vector2d>& points,
                   bool closed, const char* layer) {
  // A closed ring repeats no point; a loop given closed by repeating its first point drops it.
  size_t n = points.size();
  if (closed && n > 1 && points.front() == points.back()) --n;
  dxf.writePolyline(dw, DL_PolylineData(static_cast<int>(n), 0, 0, closed ? 1 : 0),
                    DL_Attributes(layer, 256, -1, "BYLAYER", 1.0));
  for (size_t i = 0; i < n; ++i) dxf.writeVertex(dw, DL_VertexData(points[i].x(), points[i].y()));
  dxf.writePolylineEnd(dw);
}

// The sections dxflib's documentation lists for a file AutoCAD and other readers accept.
void WriteTables(DL_Dxf& dxf, DL_WriterA& dw) {
  dw.sectionTables();
  dxf.writeVPort(dw);
  dw.tableLinetypes(3);
  dxf.writeLinetype(dw, DL_LinetypeData("BYBLOCK", "BYBLOCK", 0, 0, 0.0));
  dxf.writeLinetype(dw, DL_LinetypeData("BYLAYER", "BYLAYER", 0, 0, 0.0));
  dxf.writeLinetype(dw, DL_LinetypeData("CONTINUOUS", "Continuous", 0, 0, 0.0));
  dw.tableEnd();
  // Layer colours (AutoCAD colour index): rooms blue, walls white/black, doors red, labels green.
  const std::pair<const char*, int> layers[] = {
      {"0", 7}, {kRooms, 5}, {kWalls, 7}, {kDoors, 1}, {kLabels, 3}};
  dw.tableLayers(static_cast<int>(std::size(layers)));
  for (const auto& [name, colour] : layers) {
    dxf.writeLayer(dw, DL_LayerData(name, 0), DL_Attributes("", colour, 100, "CONTINUOUS", 1.0));
  }
  dw.tableEnd();
  dw.tableStyle(1);
  dxf.writeStyle(dw, DL_StyleData("standard", 0, 0.0, 1.0, 0.0, 0, 0.25, "txt", ""));
  dw.tableEnd();
  dxf.writeView(dw);
  dxf.writeUcs(dw);
  dw.tableAppid(1);
  dxf.writeAppid(dw, "ACAD");
  dw.tableEnd();
  dxf.writeDimStyle(dw, 1, 1, 1, 1, 1);
  dxf.writeBlockRecord(dw);
  dw.tableEnd();
  dw.sectionEnd();
  dw.sectionBlocks();
  for (const char* space : {"*Model_Space", "*Paper_Space", "*Paper_Space0"}) {
    dxf.writeBlock(dw, DL_BlockData(space, 0, 0.0, 0.0, 0.0));
    dxf.writeEndBlock(dw, space);
  }
  dw.sectionEnd();
}

}  // namespace

absl::Status WriteFloorPlanDxf(const std::string& path, const FloorPlan& plan,
                               const FloorPlanOutline& outline) {
  const std::string partial = PartialPath(path);
  {
    DL_Dxf dxf;
    // dxflib writes through its own std::ofstream, so a failed write is found below by the
    // file's last group, not by an error code.
    std::unique_ptr<DL_WriterA> dw(dxf.out(partial.c_str(), DL_Codes::AC1015));
    if (dw == nullptr || dw->openFailed()) {
      std::remove(partial.c_str());
      return absl::UnavailableError(absl::StrCat(path, ": cannot create"));
    }
    dxf.writeHeader(*dw);
    dw->dxfString(9, "$INSUNITS");  // drawing units: metres
    dw->dxfInt(70, 6);
    dw->sectionEnd();
    WriteTables(dxf, *dw);
    dw->sectionEntities();
    for (const RoomPolygon& piece : outline.rooms) {
      WritePolyline(dxf, *dw, piece.outer, true, kRooms);
      for (const auto& hole : piece.holes) WritePolyline(dxf, *dw, hole, true, kRooms);
    }
    for (const auto& wall : outline.walls) WritePolyline(dxf, *dw, wall, true, kWalls);
    for (const auto& border : RoomBorders(plan)) {
      const bool closed = border.size() > 2 && border.front() == border.back();
      WritePolyline(dxf, *dw, border, closed, kDoors);
    }
    std::vector<double> area(plan.rooms.size(), 0.0);
    for (const RoomPolygon& piece : outline.rooms) area[piece.room] += piece.area_m2;
    for (size_t r = 0; r < plan.rooms.size(); ++r) {
      const std::optional<Eigen::Vector2d> at = RoomLabelPoint(plan, static_cast<int>(r));
      if (!at || area[r] <= 0) continue;
      // Middle-centred (h 1, v 2) on its point, 25 cm high.
      dxf.writeText(*dw,
                    DL_TextData(at->x(), at->y(), 0, at->x(), at->y(), 0, 0.25, 1.0, 0, 1, 2,
                                absl::StrFormat("room %d, %.1f m2", r, area[r]), "standard", 0.0),
                    DL_Attributes(kLabels, 256, -1, "BYLAYER", 1.0));
    }
    dw->sectionEnd();
    dxf.writeObjects(*dw);
    dxf.writeObjectsEnd(*dw);
    dw->dxfEOF();
    dw->close();
  }
  // A complete file ends with the EOF group; a full disk cuts it short.
  std::ifstream in(partial, std::ios::binary | std::ios::ate);
  const std::streamoff size = in ? std::streamoff(in.tellg()) : -1;
  std::string tail(std::min<std::streamoff>(std::max<std::streamoff>(size, 0), 8), '\0');
  if (size > 0) {
    in.seekg(size - std::streamoff(tail.size()));
    in.read(tail.data(), std::streamsize(tail.size()));
  }
  if (!in || tail.find("EOF") == std::string::npos) {
    std::remove(partial.c_str());
    return absl::DataLossError(absl::StrCat(path, ": the DXF was not written to its end"));
  }
  return CommitPartial(path);
}

}  // namespace carvemap
