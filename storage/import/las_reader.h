// LAS 1.0–1.4 point clouds (ASPRS LAS specification), uncompressed, read record by record.
//
// A LAS file is a public header block (the signature "LASF", the version, the point data
// format and record length, the point count, the scale and offset of the integer coordinates,
// their bounds), variable length records (skipped), then the point records: X, Y, Z as int32
// (coordinate = value · scale + offset), then the format's fields. Formats 1, 3, 4 and 5 carry
// a GPS time (f64) at byte 20, formats 6–10 at byte 22; 0 and 2 carry none. LAS 1.4 counts its
// points in a 64-bit field (the legacy 32-bit count is 0 for formats 6–10). LAZ (the point
// format's compression bits set) is refused.
//
// Our own reader: no LAS library is packaged by Debian 12 (PDAL and libLAS are not); the
// format is a fixed header and fixed-size records. Tests read files whose headers and points
// an independent reader from the npm registry agrees with (tests/data/las/).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"

namespace carvemap {

struct LasHeader {
  uint8_t version_major = 0, version_minor = 0;
  uint16_t header_size = 0;
  uint32_t point_offset = 0;  // bytes from the file's start to the first point record
  uint8_t point_format = 0;
  uint16_t record_length = 0;
  uint64_t point_count = 0;
  bool adjusted_gps_time = false;  // global encoding bit 0: GPS time − 10⁹ s, else GPS week time
  Eigen::Vector3d scale = Eigen::Vector3d::Ones(), offset = Eigen::Vector3d::Zero();
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
  std::string system_identifier, generating_software;

  [[nodiscard]] bool has_gps_time() const;
};

struct LasPoint {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();  // scaled and offset, the file's frame
  double t = 0;                                 // GPS time, s (0 when the format has none)
};

class LasReader {
 public:
  // Reads and checks the header: errors name the file and the field (not a LAS file, a version
  // or point format outside 1.0–1.4 and 0–10, LAZ, a record shorter than its format, a zero
  // scale, points running past the end of the file).
  static absl::StatusOr<LasReader> Open(const std::string& path);
  LasReader(LasReader&&) noexcept;
  LasReader& operator=(LasReader&&) noexcept;
  ~LasReader();

  [[nodiscard]] const LasHeader& header() const;
  // Index of the next record to read (from 0).
  [[nodiscard]] uint64_t next_index() const;
  // The next records, at most `max`, into `out` (cleared); an empty `out` at the end.
  absl::Status Next(std::vector<LasPoint>& out, size_t max = 1 << 16);

  struct State;

 private:
  explicit LasReader(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace carvemap
