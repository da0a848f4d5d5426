// E57 files (ASTM E2807) ➜ scan.h5 (docs/DESIGN.md §3): every scan of /data3D is one frame, taken
// from its setup's pose.
//
// A structured scan (its records carry rowIndex and columnIndex) is a frame of a `grid` sensor
// of rows × cols pixels, so that wedges join neighbouring pixels (§4.2.1); pixels without a
// record, and records whose invalid state is not 0, are rays with no return. Scans of one grid
// size share a sensor (named "grid_<rows>x<cols>"); the grid's size comes from indexBounds, or
// from the records' indices when the file has none. An unstructured scan is a frame of the
// `points` sensor. Points come from cartesianX/Y/Z, or from sphericalRange/Azimuth/Elevation
// when the scan has no Cartesian ones. Of several returns per pixel (returnIndex), the first is
// kept. Every sensor is the scanner itself (identity mounting); the system's path is one pose
// per scan, the scan's pose, at time t = the scan's index in /data3D (E57 scans are taken
// standing still, and their time stamps are optional).
//
// Coordinates are shifted so that carving works near the origin, as for LAS: by default the
// first scan's position rounded down to whole kilometres in x and y (0 in z); the report says
// the shift, which added to the outputs' coordinates gives the E57 file's frame again.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/import/import_writer.h"
#include "storage/scan_types.h"

namespace carvemap {

struct E57ImportOptions {
  // 0: the farthest return, rounded up to the next centimetre; else returns farther than this
  // are rays with no return.
  double max_range_m = 0;
  std::array<double, 2> range_sigma = {0.005, 0.0};  // a terrestrial scanner's few millimetres
  std::optional<Eigen::Vector3d> shift;              // none: see above

  [[nodiscard]] absl::Status Validate() const;
};

struct E57Report {
  uint64_t scans = 0, structured_scans = 0;
  uint64_t records = 0;
  uint64_t rays = 0, no_return = 0;  // rays written, and those of them with no return
  uint64_t later_returns = 0;        // records of a second or later return, not written
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
};

// An E57 file read once (its structure, every scan's records, their grid sizes and ranges) so
// that the sensors are known before any frame is written; Run() reads the records again for
// the frames. Errors name the file, the scan and what is wrong (the reader's errors; a scan
// with neither Cartesian nor spherical coordinates; a record whose row or column lies outside
// indexBounds, or repeats a pixel; a grid too large for one frame).
class E57Import {
 public:
  static absl::StatusOr<E57Import> Open(const std::string& file, const E57ImportOptions& options);
  E57Import(E57Import&&) noexcept;
  E57Import& operator=(E57Import&&) noexcept;
  ~E57Import();

  [[nodiscard]] const std::vector<SensorInfo>& sensors() const;
  // Sends each scan's frame to `sink` (in /data3D order) and returns the path.
  absl::StatusOr<std::vector<PathRecord>> Run(const SensorFrameSink& sink,
                                              E57Report* report = nullptr) const;

  struct State;

 private:
  explicit E57Import(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace carvemap
