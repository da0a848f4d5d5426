// Writes a building's ground truth as gt/ files (docs/DESIGN.md §4): building.json, surfaces.ply
// (StructureMesh) and objects.ply (ObjectsMesh, with face property `int object` = object id).
#pragma once

#include <string>

#include "absl/status/status.h"
#include "services/building/building.h"

namespace carvemap {

// Writes `gt_dir`/building.json, surfaces.ply and objects.ply, each through "<file>.partial" and
// a rename. Creates `gt_dir` if missing. building.json always has "holes" on every room (an
// empty list when none) and adds the optional "name" (building) and "area_m2" (room) fields.
absl::Status WriteTruth(const Building& building, const std::string& gt_dir);

// The building.json document alone (what WriteTruth writes), as text.
[[nodiscard]] std::string BuildingJson(const Building& building);

}  // namespace carvemap
