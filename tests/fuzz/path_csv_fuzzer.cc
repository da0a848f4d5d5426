// Walks as x,y text (storage/path_csv.h): any bytes give finite positions or an error naming
// the file.
#include <cstddef>
#include <cstdint>

#include "storage/path_csv.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = carvemap::fuzz::WriteInput("path.csv", data, size);
  absl::StatusOr<std::vector<Eigen::Vector2d>> xy = ReadPathCsv(path);
  if (!xy.ok()) {
    fuzz::RequireNamesFile(xy.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(!xy->empty(), "an accepted walk has positions");
  for (const Eigen::Vector2d& p : *xy) fuzz::Require(p.allFinite(), "positions are finite");
  return 0;
}
