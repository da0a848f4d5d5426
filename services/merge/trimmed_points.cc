#include "services/merge/trimmed_points.h"

#include <cstring>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {

absl::StatusOr<TrimmedPointsCounts> WriteTrimmedPoints(const CloudStreamFn& cloud,
                                                       const PlanVolume& plan,
                                                       double trim_distance_m,
                                                       const std::string& path) {
  TrimmedPointsCounts counts;
  auto kept = [&](const CloudPoint& p) {
    return !TrimmedByPlan(LookupPlan(plan, p.point), trim_distance_m);
  };
  if (absl::Status s = cloud([&](std::span<const CloudPoint> batch) {
        for (const CloudPoint& p : batch) ++(kept(p) ? counts.kept : counts.trimmed);
        return absl::OkStatus();
      });
      !s.ok()) {
    return s;
  }
  absl::Status stream_error;
  uint64_t written = 0;
  absl::Status s = WriteFileAtomically(path, [&](std::ostream& out) {
    out << "ply\nformat binary_little_endian 1.0\n"
        << "comment carvemap: scan points without those trimmed by the floor plans (seed 5.5)\n"
        << "element vertex " << counts.kept << "\nproperty float x\nproperty float y\n"
        << "property float z\nelement face 0\nproperty list uchar int vertex_indices\n"
        << "end_header\n";
    std::vector<char> buf;
    stream_error = cloud([&](std::span<const CloudPoint> batch) {
      buf.clear();
      for (const CloudPoint& p : batch) {
        if (!kept(p)) continue;
        const float xyz[3] = {float(p.point.x()), float(p.point.y()),
                              float(p.point.z())};
        const size_t at = buf.size();
        buf.resize(at + sizeof(xyz));
        std::memcpy(buf.data() + at, xyz, sizeof(xyz));  // x86-64 and ARM64 are little-endian
      }
      written += buf.size() / (3 * sizeof(float));
      if (written > counts.kept) {
        return absl::DataLossError("the point cloud gave more points on its second pass");
      }
      out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
      return out ? absl::OkStatus() : absl::DataLossError("write failed");
    });
    if (stream_error.ok() && written != counts.kept) {
      stream_error = absl::DataLossError("the point cloud gave fewer points on its second pass");
    }
    if (!stream_error.ok()) out.setstate(std::ios::badbit);  // no file at `path`
  });
  if (!stream_error.ok()) {
    return absl::Status(stream_error.code(),
                        absl::StrCat(path, ": ", stream_error.message()));
  }
  if (!s.ok()) return s;
  return counts;
}

}  // namespace carvemap
