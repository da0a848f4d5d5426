// E57 files (ASTM E2807), as survey laser scanners export them: the scans' structure (the XML
// section) and their points (the binary compressed-vector sections).
//
// An E57 file is a sequence of 1024-byte pages: 1020 bytes of data, then a CRC-32C of them. The
// pages' data, checksums removed, are the file's "logical" bytes; offsets in the file are
// physical. It opens with a 48-byte header: the signature "ASTM-E57", the version, the file's
// length, the XML section's offset and length, the page size. The XML lists the scans under
// /data3D, each with a pose (scan ➜ file frame) and its points as a CompressedVector: a
// prototype (the fields of a record: Integer, ScaledInteger or Float, with their bounds) and
// the offset of a binary section. That section holds data packets, each carrying the next
// bytes of every field's byte stream. An Integer is bit-packed: value − minimum in
// ⌈log2(maximum − minimum + 1)⌉ bits, least significant bit first, the stream running on
// from packet to packet; a ScaledInteger is such an integer · scale + offset; a Float is an
// IEEE number, little-endian.
//
// Our own reader: Debian 12 packages no E57 library (libE57Format is not in it), and the
// binary part is a page layer, a packet layer and a bit unpacker. The XML is read with
// pugixml. Every page read is checked against its CRC-32C (storage/crc32c.h). Tests read files that
// an independent reader from the npm registry agrees with (tests/data/e57/).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace carvemap {

struct E57Header {
  uint32_t version_major = 0, version_minor = 0;
  uint64_t file_length = 0;  // physical bytes
  uint64_t xml_offset = 0;   // physical
  uint64_t xml_length = 0;   // logical bytes
  uint64_t page_size = 0;
};

// One field of a points record: a terminal element of the prototype, depth first.
struct E57Field {
  enum class Kind { kInteger, kScaledInteger, kFloat };
  std::string name;  // its path below the prototype: "cartesianX", "a/b" when nested
  Kind kind = Kind::kFloat;
  int64_t minimum = 0, maximum = 0;  // Integer and ScaledInteger: the raw bounds
  double scale = 1.0, offset = 0.0;  // ScaledInteger
  bool double_precision = true;      // Float
  // Bits of one value in the byte stream: 32 or 64 for a Float, 0–64 for an integer.
  [[nodiscard]] int bits() const;
};

struct E57IndexBounds {
  int64_t row_min = 0, row_max = 0, col_min = 0, col_max = 0;
};

// One /data3D entry: a scan from one setup of the scanner.
struct E57Scan {
  std::string name, guid;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // scan ➜ file frame
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  uint64_t section_offset = 0;  // physical offset of the points' binary section
  uint64_t record_count = 0;
  std::vector<E57Field> prototype;
  std::optional<E57IndexBounds> index_bounds;

  // The prototype's index of field `name`, or -1.
  [[nodiscard]] int FieldIndex(std::string_view name) const;
};

class E57Reader {
 public:
  // Reads the header and the XML section. Errors name the file and what is wrong: not an E57
  // file, a version other than 1, a length that is not the file's (a truncated copy), a page
  // whose CRC-32C is wrong, XML that does not parse, a scan without points, a prototype
  // element of an unsupported type, a compressed vector with codecs other than bit-packing.
  static absl::StatusOr<E57Reader> Open(const std::string& path);
  E57Reader(E57Reader&&) noexcept;
  E57Reader& operator=(E57Reader&&) noexcept;
  ~E57Reader();

  [[nodiscard]] const std::string& path() const;
  [[nodiscard]] const E57Header& header() const;
  [[nodiscard]] const std::vector<E57Scan>& scans() const;
  // How errors name scan `scan`: "FILE: data3D 2 (\"Scan B\")".
  [[nodiscard]] std::string Where(size_t scan) const;

  // Called with the next `n` records of a scan: columns[k][i] is field fields[k] of record i.
  using RecordBatch =
      std::function<absl::Status(std::span<const std::vector<double>> columns, size_t n)>;
  // Decodes scan `scan`'s records in order, in batches of at most `batch` records, giving the
  // prototype fields whose indices are `fields` (as doubles: an Integer exactly up to 2⁵³).
  // Memory holds one packet's worth of each stream and one batch. Errors name the scan, the
  // packet's byte and what is wrong (a packet past the section, a stream count that is not the
  // prototype's, records missing at the section's end, a value outside its bounds).
  absl::Status ReadRecords(int scan, std::span<const int> fields, const RecordBatch& on_batch,
                           size_t batch = 65536) const;

  struct State;

 private:
  explicit E57Reader(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace carvemap
