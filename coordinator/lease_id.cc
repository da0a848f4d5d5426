#include "coordinator/lease_id.h"

#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace carvemap {

absl::StatusOr<LeaseId> LeaseId::Parse(absl::string_view text) {
  const auto bad = [&] {
    return absl::InvalidArgumentError(absl::StrCat("malformed lease id \"", text, "\""));
  };
  const size_t gen_slash = text.rfind('/');
  if (gen_slash == absl::string_view::npos || gen_slash == 0) return bad();
  const size_t key_slash = text.rfind('/', gen_slash - 1);
  if (key_slash == absl::string_view::npos || key_slash == 0) return bad();
  LeaseId id;
  id.job_id = std::string(text.substr(0, key_slash));
  const std::vector<absl::string_view> xyz =
      absl::StrSplit(text.substr(key_slash + 1, gen_slash - key_slash - 1), ',');
  if (xyz.size() != 3 || !absl::SimpleAtoi(xyz[0], &id.chunk.x) ||
      !absl::SimpleAtoi(xyz[1], &id.chunk.y) || !absl::SimpleAtoi(xyz[2], &id.chunk.z) ||
      !absl::SimpleAtoi(text.substr(gen_slash + 1), &id.generation) || id.generation < 1) {
    return bad();
  }
  return id;
}

std::string LeaseId::ToString() const {
  return absl::StrCat(job_id, "/", chunk.x, ",", chunk.y, ",", chunk.z, "/", generation);
}

}  // namespace carvemap
