// A walk as a text file (`carvemap floorplan --path PATH.csv`): one scanner position
// per line, "x,y" or "x y" in metres (more columns, e.g. z or time, are ignored). Blank lines
// and lines starting with '#' are skipped; a first line that is not numbers is a header.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"

namespace carvemap {

// Errors name the file and line: NotFound / Unavailable when it cannot be read,
// InvalidArgument for a line that is not two finite numbers, or a file with no positions.
absl::StatusOr<std::vector<Eigen::Vector2d>> ReadPathCsv(const std::string& path);

}  // namespace carvemap
