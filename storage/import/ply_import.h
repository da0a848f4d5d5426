// PLY point clouds with a per-vertex sensor origin ➜ one `points` sensor.
//
// Accepts format ascii, binary_little_endian and binary_big_endian 1.0. The `vertex` element
// needs x y z and a sensor origin under one of these names (the first complete triple wins):
//   sensor_x sensor_y sensor_z | sx sy sz | origin_x origin_y origin_z | vp_x vp_y vp_z
// and may carry a time (s) as `t`, `time` or `timestamp` (first found). Any numeric type is
// read; other properties and other elements (faces, ...) are ignored.
//
// Mapping: sensor "ply", kind points, identity extrinsics. Each run of consecutive vertices
// with the same origin (and time) is one frame; its /path row has identity rotation and
// translation = origin, so a point's sensor-frame coordinates are world point − origin. Frame
// time = the vertex time if present, else the frame index (0, 1, 2, ... seconds: synthetic).
// Frame times must increase strictly.
#pragma once

#include <array>
#include <string>

#include "absl/status/statusor.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct PlyImportOptions {
  // PLY says nothing about its sensor: laser-scanner-like defaults.
  double sigma_t_s = 0.0;  // times are taken as exact
  std::array<double, 2> range_sigma = {0.02, 0.0};
  double max_range_m = 30.0;
};

[[nodiscard]] SensorInfo PlySensor(const PlyImportOptions& options = {});

// Parses `file`; frames go to `sink` (or into the result if `sink` is empty) as they
// complete, so memory holds one frame. Errors name the file and the header line or the vertex
// row (counted from 0).
absl::StatusOr<ImportedScan> ImportPly(const std::string& file,
                                       const PlyImportOptions& options = {},
                                       const FrameSink& sink = nullptr);

}  // namespace carvemap
