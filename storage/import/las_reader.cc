#include "storage/import/las_reader.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/import/byte_reader.h"

namespace carvemap {
namespace {

static_assert(std::endian::native == std::endian::little,
              "LAS is little-endian; the reader copies numbers as they are");

// The bytes of each point data format's fields (a record may be longer: extra bytes).
constexpr uint16_t kFormatBytes[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};

// The public header block's size in each minor version of 1.x.
uint16_t HeaderSizeOf(uint8_t minor) { return minor <= 2 ? 227 : minor == 3 ? 235 : 375; }

template <typename T>
T At(const std::vector<uint8_t>& b, size_t offset) {
  T v;
  std::memcpy(&v, b.data() + offset, sizeof(T));
  return v;
}

std::string Text(const std::vector<uint8_t>& b, size_t offset, size_t n) {
  std::string s(reinterpret_cast<const char*>(b.data() + offset), n);
  s.resize(std::strlen(s.c_str()));
  return s;
}

}  // namespace

bool LasHeader::has_gps_time() const { return point_format != 0 && point_format != 2; }

struct LasReader::State {
  std::string path;
  import_internal::ByteReader file;
  LasHeader header;
  uint64_t next = 0;
  std::vector<uint8_t> buffer;
};

LasReader::LasReader(std::unique_ptr<State> state) : state_(std::move(state)) {}
LasReader::LasReader(LasReader&&) noexcept = default;
LasReader& LasReader::operator=(LasReader&&) noexcept = default;
LasReader::~LasReader() = default;

const LasHeader& LasReader::header() const { return state_->header; }
uint64_t LasReader::next_index() const { return state_->next; }

absl::StatusOr<LasReader> LasReader::Open(const std::string& path) {
  absl::StatusOr<import_internal::ByteReader> file = import_internal::ByteReader::Open(path);
  if (!file.ok()) return file.status();
  auto bad = [&](absl::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", why));
  };
  // The 1.0–1.2 header first; LAS 1.3 and 1.4 add fields after it.
  std::vector<uint8_t> b(375, 0);
  if (!file->ReadBytes(b.data(), 227) || std::memcmp(b.data(), "LASF", 4) != 0) {
    return bad("not a LAS file (no \"LASF\" signature and 227-byte header at its start)");
  }
  LasHeader h;
  const uint16_t global_encoding = At<uint16_t>(b, 6);
  h.adjusted_gps_time = (global_encoding & 1) != 0;
  h.version_major = b[24];
  h.version_minor = b[25];
  if (h.version_major != 1 || h.version_minor > 4) {
    return bad(absl::StrCat("LAS version ", int(h.version_major), ".", int(h.version_minor),
                            "; versions 1.0 to 1.4 are read"));
  }
  h.system_identifier = Text(b, 26, 32);
  h.generating_software = Text(b, 58, 32);
  h.header_size = At<uint16_t>(b, 94);
  h.point_offset = At<uint32_t>(b, 96);
  const uint8_t format_byte = b[104];
  h.record_length = At<uint16_t>(b, 105);
  const uint32_t legacy_count = At<uint32_t>(b, 107);
  for (int d = 0; d < 3; ++d) {
    h.scale[d] = At<double>(b, 131 + 8 * d);
    h.offset[d] = At<double>(b, 155 + 8 * d);
    h.max[d] = At<double>(b, 179 + 16 * d);
    h.min[d] = At<double>(b, 187 + 16 * d);
  }
  const uint16_t need = HeaderSizeOf(h.version_minor);
  if (h.header_size < need) {
    return bad(absl::StrCat("header size ", h.header_size, " for LAS 1.", int(h.version_minor),
                            " (at least ", need, ")"));
  }
  if (!file->ReadBytes(b.data() + 227, need - 227)) return bad("the file ends inside its header");
  if ((format_byte & 0xC0) != 0) {
    return bad("compressed points (LAZ); `laszip` or `pdal translate` writes plain LAS");
  }
  h.point_format = format_byte;
  if (h.point_format > 10) {
    return bad(
        absl::StrCat("point data format ", int(h.point_format), "; formats 0 to 10 are read"));
  }
  if (h.record_length < kFormatBytes[h.point_format]) {
    return bad(absl::StrCat("point records of ", h.record_length, " bytes for format ",
                            int(h.point_format), ", which needs ", kFormatBytes[h.point_format]));
  }
  h.point_count = legacy_count;
  if (h.version_minor >= 4) {
    const uint64_t count64 = At<uint64_t>(b, 247);
    if (count64 != 0 || h.point_format >= 6) h.point_count = count64;
    if (legacy_count != 0 && count64 != 0 && legacy_count != count64) {
      return bad(absl::StrCat("its legacy point count ", legacy_count, " and its count ", count64,
                              " differ"));
    }
  }
  for (int d = 0; d < 3; ++d) {
    if (!std::isfinite(h.scale[d]) || h.scale[d] == 0 || !std::isfinite(h.offset[d])) {
      return bad(absl::StrCat("scale ", h.scale[d], " and offset ", h.offset[d], " of ",
                              std::string(1, "XYZ"[d]), " (need finite, scale not 0)"));
    }
  }
  if (h.point_offset < h.header_size) {
    return bad(absl::StrCat("its points start at byte ", h.point_offset, ", inside its ",
                            h.header_size, "-byte header"));
  }
  const uint64_t end = h.point_offset + h.point_count * uint64_t{h.record_length};
  if (h.point_count > file->size() / std::max<uint16_t>(h.record_length, 1) || end > file->size()) {
    return absl::DataLossError(absl::StrCat(path, ": ", h.point_count, " points of ",
                                            h.record_length, " bytes from byte ", h.point_offset,
                                            " run past the end of the file at byte ", file->size(),
                                            " (a file cut short?)"));
  }
  if (!file->Skip(h.point_offset - need)) return bad("cannot seek to its points");
  auto state = std::make_unique<State>(State{path, *std::move(file), h, 0, {}});
  return LasReader(std::move(state));
}

absl::Status LasReader::Next(std::vector<LasPoint>& out, size_t max) {
  State& s = *state_;
  out.clear();
  const uint64_t n = std::min<uint64_t>(max, s.header.point_count - s.next);
  if (n == 0) return absl::OkStatus();
  const size_t len = s.header.record_length;
  s.buffer.resize(n * len);
  if (!s.file.ReadBytes(s.buffer.data(), s.buffer.size())) {
    return absl::DataLossError(
        absl::StrCat(s.path, ": point ", s.next, " runs past the end of the file"));
  }
  const size_t time_at = s.header.point_format >= 6 ? 22 : 20;
  const bool timed = s.header.has_gps_time();
  out.resize(n);
  for (uint64_t i = 0; i < n; ++i) {
    const uint8_t* r = s.buffer.data() + i * len;
    int32_t xyz[3];
    std::memcpy(xyz, r, sizeof(xyz));
    for (int d = 0; d < 3; ++d) out[i].p[d] = xyz[d] * s.header.scale[d] + s.header.offset[d];
    if (timed) std::memcpy(&out[i].t, r + time_at, sizeof(double));
  }
  s.next += n;
  return absl::OkStatus();
}

}  // namespace carvemap
