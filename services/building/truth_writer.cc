#include "services/building/truth_writer.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

using nlohmann::json;

json Point(const Eigen::Vector2d& p) { return json::array({p.x(), p.y()}); }

json Ring(const std::vector<Eigen::Vector2d>& ring) {
  json out = json::array();
  for (const auto& p : ring) out.push_back(Point(p));
  return out;
}

json Document(const Building& b) {
  json doc;
  doc["name"] = b.name;
  json levels = json::array();
  for (const LevelTruth& l : b.levels) {
    levels.push_back({{"index", l.index}, {"floor_z", l.floor_z}, {"ceiling_z", l.ceiling_z}});
  }
  json rooms = json::array();
  for (const RoomTruth& r : b.rooms) {
    json holes = json::array();
    for (const auto& h : r.holes) holes.push_back(Ring(h));
    rooms.push_back({{"id", r.id},
                     {"level", r.level},
                     {"polygon", Ring(r.polygon)},
                     {"holes", holes},
                     {"floor_z", r.floor_z},
                     {"ceiling_z", r.ceiling_z},
                     {"entered", r.entered},
                     {"area_m2", RoomArea(r)}});
  }
  json doors = json::array();
  for (const DoorTruth& d : b.doors) {
    doors.push_back({{"id", d.id},
                     {"level", d.level},
                     {"rooms", json::array({d.room_a, d.room_b})},
                     {"segment", json::array({Point(d.p0), Point(d.p1)})},
                     {"width", d.width}});
  }
  json objects = json::array();
  for (const ObjectTruth& o : b.objects) {
    const Eigen::AlignedBox3d box = o.Aabb();
    objects.push_back(
        {{"id", o.id},
         {"kind", o.kind},
         {"level", o.level},
         {"aabb", json::array({json::array({box.min().x(), box.min().y(), box.min().z()}),
                               json::array({box.max().x(), box.max().y(), box.max().z()})})}});
  }
  doc["levels"] = levels;
  doc["rooms"] = rooms;
  doc["doors"] = doors;
  doc["objects"] = objects;
  return doc;
}

absl::Status WriteTextAtomically(const std::string& path, const std::string& text) {
  return WriteFileAtomically(path, [&](std::ostream& out) { out << text; });
}

}  // namespace

std::string BuildingJson(const Building& building) { return Document(building).dump(1) + "\n"; }

absl::Status WriteTruth(const Building& building, const std::string& gt_dir) {
  std::error_code ec;
  std::filesystem::create_directories(gt_dir, ec);
  if (ec) return absl::PermissionDeniedError(absl::StrCat(gt_dir, ": ", ec.message()));
  const std::filesystem::path dir(gt_dir);
  if (absl::Status s =
          WriteTextAtomically((dir / "building.json").string(), BuildingJson(building));
      !s.ok()) {
    return s;
  }
  if (absl::Status s = WritePly((dir / "surfaces.ply").string(), StructureMesh(building));
      !s.ok()) {
    return s;
  }
  std::vector<int> object_of_triangle;
  const TriangleMesh objects = ObjectsMesh(building, &object_of_triangle);
  return WritePly((dir / "objects.ply").string(), objects, &object_of_triangle, "object");
}

}  // namespace carvemap
