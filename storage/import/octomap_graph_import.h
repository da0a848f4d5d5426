// OctoMap scan graphs (.graph, OctoMap's ScanGraph::writeBinary) ➜ one `points` sensor.
//
// Layout (little-endian): uint32 n_nodes; per node: uint32 n_pts, n_pts × {int32 3; f64 x y z}
// in the sensor frame; pose {int32 3; f64 tx ty tz}{int32 4; f64 qw qx qy qz}; uint32 id. Then
// uint32 n_edges; per edge: uint32 id1, id2, a pose as above, f64 weight.
//
// Mapping: sensor "graph", kind points, identity extrinsics (the node pose is the sensor pose,
// so the system frame is the sensor frame). Node k becomes frame k and /path row k. Graphs
// carry no time stamps, so times are SYNTHETIC: node k is at t = k seconds. Points keep their
// sensor-frame coordinates (as f32). Edges are read and checked (known node ids, finite
// values) but not stored.
#pragma once

#include <array>
#include <string>

#include "absl/status/statusor.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct OctomapGraphOptions {
  // Sensor attributes written to scan.h5. The graph says nothing about its sensor; these are
  // laser-scanner-like defaults (a few cm of range noise).
  double sigma_t_s = 0.0;  // synthetic times are exact by construction
  std::array<double, 2> range_sigma = {0.02, 0.0};
  double max_range_m = 30.0;
};

// The sensor the import declares (independent of the file's contents).
[[nodiscard]] SensorInfo OctomapGraphSensor(const OctomapGraphOptions& options = {});

// Parses `file`; frames go to `sink` (or into the result if `sink` is empty) as nodes are
// read, so memory holds one node at a time. Errors name the file, the node (or edge) index
// and the byte offset; counts are checked against the remaining file size before allocating.
absl::StatusOr<ImportedScan> ImportOctomapGraph(const std::string& file,
                                                const OctomapGraphOptions& options = {},
                                                const FrameSink& sink = nullptr);

}  // namespace carvemap
