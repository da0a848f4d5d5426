// The scan's point cloud with §5.5's exterior trimming (seed Fig 5.13e, "we can automatically
// remove scans from the input point cloud that fall outside our desired area"), written on
// request as OUT/points.ply: every return in the world frame (scan_cloud_stream.h) except
// those on a level farther than the trim distance from its floor plan's interior
// (TrimmedByPlan, the rule the octree's interior cells follow). Points above or below every
// level are kept.
//
// Binary little-endian PLY as docs/DESIGN.md §7 (vertex float x y z; `element face 0`), through
// "<path>.partial" and a rename. The cloud streams once, so memory stays bounded whatever the
// scan's size; the header, padded to a fixed size, is rewritten with the vertex count at the end.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "services/floorplan/samples/pointcloud_wall_samples.h"
#include "services/segment/plan_volume.h"

namespace carvemap {

struct TrimmedPointsCounts {
  uint64_t kept = 0;
  uint64_t trimmed = 0;
};

// Errors: the stream's (e.g. a read error naming the scan), or the file's (naming `path`); no
// file is left at `path` then.
[[nodiscard]] absl::StatusOr<TrimmedPointsCounts> WriteTrimmedPoints(
    const CloudStreamFn& cloud, const PlanVolume& plan, double trim_distance_m,
    const std::string& path);

}  // namespace carvemap
