#include "storage/path_csv.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// Parses the first two numbers of a line split on commas, spaces or tabs; false if the line
// does not start with two finite numbers.
bool ParseXY(const std::string& line, Eigen::Vector2d& xy) {
  const char* p = line.c_str();
  for (int k = 0; k < 2; ++k) {
    while (*p == ' ' || *p == '\t' || (k > 0 && *p == ',')) ++p;
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(p, &end);
    if (end == p || errno != 0 || !std::isfinite(v)) return false;
    if (*end != '\0' && *end != ',' && *end != ' ' && *end != '\t' && *end != '\r') return false;
    xy[k] = v;
    p = end;
  }
  return true;
}

}  // namespace

absl::StatusOr<std::vector<Eigen::Vector2d>> ReadPathCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    return absl::NotFoundError(absl::StrCat(path, ": cannot open the path file"));
  }
  std::vector<Eigen::Vector2d> out;
  std::string line;
  int line_no = 0;
  bool seen_data_or_header = false;
  while (std::getline(in, line)) {
    ++line_no;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    Eigen::Vector2d xy;
    if (ParseXY(line.substr(first), xy)) {
      out.push_back(xy);
    } else if (seen_data_or_header) {
      return absl::InvalidArgumentError(absl::StrCat(
          path, ":", line_no, ": expected \"x,y\" (two finite numbers in metres), got \"",
          line.substr(0, 60), "\""));
    }
    seen_data_or_header = true;  // only the first non-blank line may be a header
  }
  if (in.bad()) return absl::UnavailableError(absl::StrCat(path, ": read error"));
  if (out.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": no positions (\"x,y\" per line)"));
  }
  return out;
}

}  // namespace carvemap
