#include "services/merge/trimmed_points.h"

#include <cstring>
#include <limits>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

// The PLY header for `count` vertices, `size` bytes long: a comment line of spaces pads it, so
// the header written first (count 0) is rewritten in place with the count once the points are
// written. That spares a counting pass over the scan (every return read, posed and looked up
// twice).
// Comment lines are in every PLY reader's grammar.
std::string Header(uint64_t count, size_t size) {
  const std::string head =
      "ply\nformat binary_little_endian 1.0\n"
      "comment carvemap: scan points without those trimmed by the floor plans (seed 5.5)\n";
  const std::string tail = absl::StrCat(
      "element vertex ", count, "\nproperty float x\nproperty float y\nproperty float z\n",
      "element face 0\nproperty list uchar int vertex_indices\nend_header\n");
  const std::string pad_open = "comment ", pad_close = "\n";
  const size_t fixed = head.size() + tail.size() + pad_open.size() + pad_close.size();
  return head + pad_open + std::string(size > fixed ? size - fixed : 0, ' ') + pad_close + tail;
}

}  // namespace

absl::StatusOr<TrimmedPointsCounts> WriteTrimmedPoints(const CloudStreamFn& cloud,
                                                       const PlanVolume& plan,
                                                       double trim_distance_m,
                                                       const std::string& path) {
  TrimmedPointsCounts counts;
  // Long enough for any count: the header with the most digits and no padding.
  const size_t header_size = Header(std::numeric_limits<uint64_t>::max(), 0).size();
  absl::Status stream_error;
  absl::Status s = WriteFileAtomically(path, [&](std::ostream& out) {
    out << Header(0, header_size);
    std::vector<char> buf;
    stream_error = cloud([&](std::span<const CloudPoint> batch) {
      buf.clear();
      for (const CloudPoint& p : batch) {
        if (TrimmedByPlan(LookupPlan(plan, p.point), trim_distance_m)) {
          ++counts.trimmed;
          continue;
        }
        const float xyz[3] = {float(p.point.x()), float(p.point.y()),
                              float(p.point.z())};
        const size_t at = buf.size();
        buf.resize(at + sizeof(xyz));
        std::memcpy(buf.data() + at, xyz, sizeof(xyz));  // x86-64 and ARM64 are little-endian
      }
      counts.kept += buf.size() / (3 * sizeof(float));
      out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
      return out ? absl::OkStatus() : absl::DataLossError("write failed");
    });
    if (!stream_error.ok()) {
      out.setstate(std::ios::badbit);  // no file at `path`
      return;
    }
    out.seekp(0);  // the .partial file (WriteFileAtomically's ofstream)
    out << Header(counts.kept, header_size);
  });
  if (!stream_error.ok()) {
    return absl::Status(stream_error.code(),
                        absl::StrCat(path, ": ", stream_error.message()));
  }
  if (!s.ok()) return s;
  return counts;
}

}  // namespace carvemap
