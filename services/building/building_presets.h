// Procedural preset buildings with exact truth (docs/DESIGN.md §4): "room" (one furnished room),
// "office" (one level, 16 rooms on a hallway, one room never entered, a window, columns, a
// curved wall), "office2" (two levels joined by stairs, 30 rooms) and "office4" (four levels of
// three wings, stairs between each level and the next, 180 rooms, 5,440 m² of floor: a
// large building). The layout of a preset is fixed; `seed` only jitters furniture placement.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "services/building/building.h"

namespace carvemap {

// The preset names MakePresetBuilding accepts.
[[nodiscard]] std::vector<std::string_view> PresetBuildingNames();

// Builds preset `name` (NotFound for an unknown name). rooms[0] is where the walk starts (the
// hallway in "office"/"office2", the south wing's on level 0 in "office4"); nav grids are 0.1 m
// with 0.25 m clearance.
absl::StatusOr<Building> MakePresetBuilding(std::string_view name, uint64_t seed);

}  // namespace carvemap
