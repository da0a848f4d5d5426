#include "services/merge/model_glb.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "services/floorplan/model/extrusion.h"

namespace carvemap {
namespace {

// Materials for objects: a few, reused by id, so a building of thousands of objects has a
// short material list.
constexpr int kObjectColours = 12;

}  // namespace

std::array<float, 4> ObjectColour(int id) {
  // HSV with S = 0.55, V = 0.85, hue stepping by the golden angle.
  const double hue = std::fmod(id * 137.50776405, 360.0) / 60.0;
  const double v = 0.85, c = v * 0.55, x = c * (1 - std::fabs(std::fmod(hue, 2.0) - 1));
  const int sector = static_cast<int>(hue) % 6;
  const double rgb[6][3] = {{c, x, 0}, {x, c, 0}, {0, c, x}, {0, x, c}, {x, 0, c}, {c, 0, x}};
  const double m = v - c;
  return {float(rgb[sector][0] + m), float(rgb[sector][1] + m), float(rgb[sector][2] + m), 1.0f};
}

absl::StatusOr<std::unique_ptr<ModelGlb>> ModelGlb::Create(
    const std::string& path, const TriangleMesh& building,
    std::span<const std::pair<Level, FloorPlan>> plans) {
  absl::StatusOr<std::unique_ptr<GlbStreamWriter>> writer = GlbStreamWriter::Create(path);
  if (!writer.ok()) return writer.status();
  std::unique_ptr<ModelGlb> model(new ModelGlb(*std::move(writer)));
  GlbStreamWriter& w = *model->writer_;
  const int grey = w.AddMaterial("building", {0.78f, 0.78f, 0.76f, 1}, false);
  const int glass = w.AddMaterial("room", {0.25f, 0.5f, 0.9f, 0.18f}, true);
  model->first_object_material_ = grey + 2;
  for (int k = 0; k < kObjectColours; ++k) {
    w.AddMaterial(absl::StrCat("object ", k), ObjectColour(k), false);
  }
  if (absl::Status s = w.AddNode("building", -1, building, grey).status(); !s.ok()) return s;
  absl::StatusOr<int> rooms = w.AddNode("rooms", -1, TriangleMesh{}, -1);
  if (!rooms.ok()) return rooms.status();
  for (const auto& [level, plan] : plans) {
    for (int r = 0; r < static_cast<int>(plan.rooms.size()); ++r) {
      const FloorPlanRoom& room = plan.rooms[r];
      if (!(room.area_m2 > 0)) continue;  // no triangles, nothing to draw
      absl::StatusOr<TriangleMesh> solid = ExtrudeRoom(plan, r);
      if (!solid.ok()) {
        return absl::Status(solid.status().code(),
                            absl::StrCat("level ", level.index, ": ", solid.status().message()));
      }
      const nlohmann::json extras = {{"level", level.index},
                                     {"room", r},
                                     {"area_m2", room.area_m2},
                                     {"floor_z", room.floor_z},
                                     {"ceiling_z", room.ceiling_z}};
      if (absl::Status s = w.AddNode(absl::StrCat("level ", level.index, " room ", r), *rooms,
                                     *solid, glass, extras)
                               .status();
          !s.ok()) {
        return s;
      }
    }
  }
  absl::StatusOr<int> objects = w.AddNode("objects", -1, TriangleMesh{}, -1);
  if (!objects.ok()) return objects.status();
  model->objects_node_ = *objects;
  return model;
}

absl::Status ModelGlb::AddObject(const SegmentedObject& o, const TriangleMesh& mesh) {
  const nlohmann::json extras = {{"id", o.id},
                                 {"level", o.level},
                                 {"room", o.room},
                                 {"volume_m3", o.volume_m3},
                                 {"aabb",
                                  {{o.box.min().x(), o.box.min().y(), o.box.min().z()},
                                   {o.box.max().x(), o.box.max().y(), o.box.max().z()}}}};
  return writer_
      ->AddNode(absl::StrCat("object ", o.id), objects_node_, mesh,
                first_object_material_ + o.id % kObjectColours, extras)
      .status();
}

absl::Status ModelGlb::Finish() { return writer_->Finish(); }

}  // namespace carvemap
