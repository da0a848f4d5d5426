// TUM RGB-D style depth images with poses ➜ one `grid` sensor.
//
// Input: a directory with depth/<t>.png (16-bit gray, metres = value / depth_scale, 0 = no
// return) and an association file whose data lines read
//   rgb/<t_rgb>.png depth/<t_depth>.png tx ty tz qx qy qz qw
// (quaternion LAST, scalar last; lines starting with # are comments). The pose is the colour
// camera's optical centre in the motion-capture world frame; TUM depth images are registered
// to the colour camera, so one frame serves both.
//
// Mapping: sensor "depth", kind grid (rows × cols = the image, or every stride-th pixel in both
// directions), identity extrinsics: the system frame IS the camera optical frame (x right,
// y down, z forward). Pixel (u = column, v = row) with depth z becomes
//   (x, y, z) = ((u − cx)·z/fx, (v − cy)·z/fy, z); depth 0 or range > max_range ➜ NaN row.
// /path = every association line's pose at t_rgb (the pose was matched to the colour image),
// sorted; exact duplicate lines are dropped. Frames = association lines whose depth image
// exists, at t_depth, in time order (each image once).
#pragma once

#include <array>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct TumOptions {
  // Association file; empty = "<dir>/my_association.txt".
  std::string association_file;
  // Intrinsics of TUM freiburg2 (the fr2 sequences), pixels.
  double fx = 520.9, fy = 521.0, cx = 325.1, cy = 249.7;
  int width = 640, height = 480;  // expected image size, pixels
  double depth_scale = 5000.0;    // stored value per metre (TUM convention)
  int stride = 1;                 // keep every stride-th pixel in both directions
  // Kinect-style depth noise grows with range (Khoshelham & Elberink 2012: random error
  // ≈ 1.4e-3·z² m, about 4 cm at 5 m). A linear model a + b·range with a = 2 mm (quantisation
  // at close range) and b = 8 mm/m matches 4 cm at 5 m and over-bounds the error nearer.
  std::array<double, 2> range_sigma = {0.002, 0.008};
  // Kinect v1 returns depth out to ~8–10 m, but beyond ~8 m its error exceeds 10 cm; such
  // pixels become NaN (no return) rather than carve with that noise.
  double max_range_m = 8.0;
  // Clock sync std-dev: TUM's mocap and camera clocks plus the depth/colour pairing (up to
  // 0.02 s in the association).
  double sigma_t_s = 0.01;

  [[nodiscard]] absl::Status Validate() const;
};

// The sensor the import declares (rows/cols follow the stride).
[[nodiscard]] SensorInfo TumSensor(const TumOptions& options = {});

// Parses the association file and the depth images of `dir`. Frames go to `sink` (or into the
// result if `sink` is empty) one image at a time. Errors name the file and the line or image.
absl::StatusOr<ImportedScan> ImportTum(const std::string& dir, const TumOptions& options = {},
                                       const FrameSink& sink = nullptr);

}  // namespace carvemap
