#include "services/merge/memory_budget.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "services/mesh/planar_mesh.h"

namespace carvemap {
namespace {

std::string Bytes(uint64_t bytes) {
  return bytes < (uint64_t{1} << 30) ? absl::StrFormat("%.0f MiB", double(bytes) / (1 << 20))
                                     : absl::StrFormat("%.2f GiB", double(bytes) / (1 << 30));
}

std::string Faces(uint64_t n) {
  return n >= 100000 ? absl::StrFormat("%.2f M", double(n) / 1e6) : absl::StrCat(n);
}

}  // namespace

absl::Status CheckPlanarMemory(std::string_view what, uint64_t num_faces, uint64_t held_bytes,
                               uint64_t budget_bytes) {
  const uint64_t need = num_faces * kPlanarBytesPerFace;
  if (budget_bytes == 0 || held_bytes + need <= budget_bytes) return absl::OkStatus();
  return absl::ResourceExhaustedError(
      absl::StrCat(std::string(what), ": ", Faces(num_faces), " boundary faces need about ",
                   Bytes(need), " on top of the ", Bytes(held_bytes),
                   " the merge holds, over its memory budget of ", Bytes(budget_bytes),
                   ". Give the merge more memory (--memory-mb of `carvemap merge` or "
                   "`carvemap merger`, --merge-memory-mb of `carvemap run`; by default 90 % of the "
                   "process's cgroup memory limit) or carve at a coarser --resolution"));
}

absl::Status CheckPlanarMemory(std::string_view what, uint64_t num_faces,
                               const std::function<uint64_t()>& held, uint64_t budget_bytes,
                               const std::function<void()>& settle) {
  if (budget_bytes == 0) return absl::OkStatus();
  absl::Status fits = CheckPlanarMemory(what, num_faces, held(), budget_bytes);
  if (fits.ok() || !settle) return fits;
  settle();
  return CheckPlanarMemory(what, num_faces, held(), budget_bytes);
}

}  // namespace carvemap
