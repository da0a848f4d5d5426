// mesh/model.glb (docs/DESIGN.md §7): the building, its rooms and its objects as one glTF
// scene, for viewers and the web: under the root, node "building" (the planar mesh, grey),
// node "rooms" with one node per room ("level <k> room <r>", the room's extruded solid,
// translucent, extras {level, room, area_m2, floor_z, ceiling_z}), and node "objects" with one
// node per object ("object <id>", its mesh in one of 12 colours by id, extras {id, level, room,
// volume_m3, aabb}). Objects come one at a time, in id order, as their files are written, so
// the scene is never held (storage/glb_writer.h).
#pragma once

#include <array>
#include <memory>
#include <span>
#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "services/floorplan/floor_plan.h"
#include "services/levels/level_split.h"
#include "services/segment/object_meshes.h"
#include "storage/glb_writer.h"
#include "storage/ply_io.h"

namespace carvemap {

class ModelGlb {
 public:
  // Starts `path` with the building and the rooms of `plans`. Errors: GlbStreamWriter's, and
  // ExtrudeRoom's for a room that cannot be extruded (naming the level).
  [[nodiscard]] static absl::StatusOr<std::unique_ptr<ModelGlb>> Create(
      const std::string& path, const TriangleMesh& building,
      std::span<const std::pair<Level, FloorPlan>> plans);

  // The next object, in id order.
  [[nodiscard]] absl::Status AddObject(const SegmentedObject& object, const TriangleMesh& mesh);
  [[nodiscard]] absl::Status Finish();

 private:
  explicit ModelGlb(std::unique_ptr<GlbStreamWriter> writer) : writer_(std::move(writer)) {}
  std::unique_ptr<GlbStreamWriter> writer_;
  int objects_node_ = -1;
  int first_object_material_ = 0;
};

// Colour `k` of the objects' palette (linear RGB, alpha 1): hues a golden angle apart, so
// objects next in id order (neighbours along x), which take colours k and k + 1, differ.
[[nodiscard]] std::array<float, 4> ObjectColour(int id);

}  // namespace carvemap
