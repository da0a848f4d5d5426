#include "storage/import/e57_reader.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>
#include <utility>

#include <pugixml.hpp>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/strip.h"
#include "storage/crc32c.h"
#include "storage/import/byte_reader.h"
#include "storage/import/scan_import.h"

namespace carvemap {
namespace {

static_assert(std::endian::native == std::endian::little, "E57's numbers are little-endian");

constexpr uint64_t kPhysicalPage = 1024;
constexpr uint64_t kLogicalPage = 1020;  // a page's data; its last 4 bytes are the CRC-32C
constexpr size_t kHeaderBytes = 48;
constexpr size_t kSectionHeaderBytes = 32;
constexpr uint8_t kCompressedVectorSection = 1;
constexpr uint8_t kIndexPacket = 0, kDataPacket = 1, kEmptyPacket = 2;

// A physical offset ➜ the logical offset of the same byte (pages' checksums removed).
bool ToLogical(uint64_t physical, uint64_t& logical) {
  if (physical % kPhysicalPage >= kLogicalPage) return false;  // inside a checksum
  logical = physical / kPhysicalPage * kLogicalPage + physical % kPhysicalPage;
  return true;
}

uint64_t ToPhysical(uint64_t logical) {
  return logical / kLogicalPage * kPhysicalPage + logical % kLogicalPage;
}

// How errors name a scan: "data3D 2 (\"Scan B\")".
std::string ScanLabel(size_t index, absl::string_view name) {
  return absl::StrCat("data3D ", index, " (\"", name, "\")");
}

std::string Bytes(uint64_t first, uint64_t count) {
  return absl::StrCat("bytes ", first, "–", first + count - 1);
}

// The file's logical bytes, a page at a time, each page's CRC-32C checked when it is read.
class PagedFile {
 public:
  static absl::StatusOr<PagedFile> Open(const std::string& path) {
    auto bytes = import_internal::ByteReader::Open(path);
    if (!bytes.ok()) return bytes.status();
    return PagedFile(path, std::move(*bytes));
  }
  PagedFile(std::string path, import_internal::ByteReader file)
      : path_(std::move(path)), file_(std::move(file)) {}

  [[nodiscard]] uint64_t size() const { return file_.size(); }
  [[nodiscard]] uint64_t logical_size() const { return size() / kPhysicalPage * kLogicalPage; }

  // Reads `n` logical bytes from logical offset `at`.
  absl::Status Read(uint64_t at, void* out, uint64_t n) {
    auto* dst = static_cast<uint8_t*>(out);
    while (n > 0) {
      const uint64_t page = at / kLogicalPage, in_page = at % kLogicalPage;
      if (absl::Status s = Load(page); !s.ok()) return s;
      const uint64_t take = std::min(n, kLogicalPage - in_page);
      std::memcpy(dst, page_bytes_.data() + in_page, take);
      dst += take;
      at += take;
      n -= take;
    }
    return absl::OkStatus();
  }

 private:
  absl::Status Load(uint64_t page) {
    if (page == page_) return absl::OkStatus();
    const uint64_t at = page * kPhysicalPage;
    if (at + kPhysicalPage > size()) {
      return absl::DataLossError(absl::StrCat(path_, ": page ", page, " (",
                                              Bytes(at, kPhysicalPage),
                                              ") lies past the end of "
                                              "the file (",
                                              size(), " bytes): it is cut short"));
    }
    page_ = std::numeric_limits<uint64_t>::max();
    if (!file_.Seek(at) || !file_.ReadBytes(page_bytes_.data(), kPhysicalPage)) {
      return absl::DataLossError(absl::StrCat(path_, ": cannot read page ", page));
    }
    // The checksum is stored big-endian (the standard's byte order for it).
    const uint32_t stored = uint32_t{page_bytes_[1020]} << 24 | uint32_t{page_bytes_[1021]} << 16 |
                            uint32_t{page_bytes_[1022]} << 8 | uint32_t{page_bytes_[1023]};
    const uint32_t computed =
        Crc32c({reinterpret_cast<const char*>(page_bytes_.data()), kLogicalPage});
    if (stored != computed) {
      return absl::DataLossError(absl::StrFormat(
          "%s: page %d (%s): CRC-32C is 0x%08x, its data give 0x%08x: the file is damaged", path_,
          page, Bytes(at, kPhysicalPage), stored, computed));
    }
    page_ = page;
    return absl::OkStatus();
  }

  std::string path_;
  import_internal::ByteReader file_;
  uint64_t page_ = std::numeric_limits<uint64_t>::max();
  std::array<uint8_t, kPhysicalPage> page_bytes_{};
};

// --- The XML section -------------------------------------------------------------------------

struct XmlContext {
  const std::string& path;
  std::string where;  // "data3D 2 (\"Scan B\")"

  absl::Status Error(absl::string_view what) const {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", where, ": ", what));
  }
};

// An element's number: E57 writes a Float's or an Integer's value as its text (0 when empty).
absl::StatusOr<double> Number(const XmlContext& cx, pugi::xml_node node, double fallback) {
  if (!node) return fallback;
  const absl::string_view text = absl::StripAsciiWhitespace(node.text().get());
  if (text.empty()) return 0.0;
  double v = 0;
  if (!absl::SimpleAtod(text, &v) || !std::isfinite(v)) {
    return cx.Error(absl::StrCat(node.path('/'), " is \"", text, "\", not a finite number"));
  }
  return v;
}

template <typename T>
absl::StatusOr<T> IntegerAttribute(const XmlContext& cx, pugi::xml_node node, const char* name,
                                   T fallback) {
  const pugi::xml_attribute a = node.attribute(name);
  if (!a) return fallback;
  T v{};
  if (!absl::SimpleAtoi(absl::StripAsciiWhitespace(a.value()), &v)) {
    return cx.Error(absl::StrCat(node.path('/'), ": attribute ", name, "=\"", a.value(),
                                 "\" is not an integer in range"));
  }
  return v;
}

absl::StatusOr<double> DoubleAttribute(const XmlContext& cx, pugi::xml_node node, const char* name,
                                       double fallback) {
  const pugi::xml_attribute a = node.attribute(name);
  if (!a) return fallback;
  double v = 0;
  if (!absl::SimpleAtod(absl::StripAsciiWhitespace(a.value()), &v) || !std::isfinite(v)) {
    return cx.Error(absl::StrCat(node.path('/'), ": attribute ", name, "=\"", a.value(),
                                 "\" is not a finite number"));
  }
  return v;
}

// The prototype's terminal elements, depth first: the order of the section's byte streams.
absl::Status FlattenPrototype(const XmlContext& cx, pugi::xml_node node, const std::string& prefix,
                              std::vector<E57Field>& out) {
  for (pugi::xml_node child : node.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string name = prefix + child.name();
    const absl::string_view type = child.attribute("type").value();
    E57Field f;
    f.name = name;
    if (type == "Structure") {
      if (absl::Status s = FlattenPrototype(cx, child, name + "/", out); !s.ok()) return s;
      continue;
    }
    if (type == "Integer" || type == "ScaledInteger") {
      f.kind = type == "Integer" ? E57Field::Kind::kInteger : E57Field::Kind::kScaledInteger;
      auto lo =
          IntegerAttribute<int64_t>(cx, child, "minimum", std::numeric_limits<int64_t>::min());
      auto hi =
          IntegerAttribute<int64_t>(cx, child, "maximum", std::numeric_limits<int64_t>::max());
      auto scale = DoubleAttribute(cx, child, "scale", 1.0);
      auto offset = DoubleAttribute(cx, child, "offset", 0.0);
      for (const absl::Status& s : {lo.status(), hi.status(), scale.status(), offset.status()}) {
        if (!s.ok()) return s;
      }
      if (*lo > *hi) {
        return cx.Error(
            absl::StrCat("prototype field ", name, ": minimum ", *lo, " is above maximum ", *hi));
      }
      if (*scale == 0) return cx.Error(absl::StrCat("prototype field ", name, ": scale 0"));
      f.minimum = *lo;
      f.maximum = *hi;
      f.scale = *scale;
      f.offset = *offset;
    } else if (type == "Float") {
      const absl::string_view precision = child.attribute("precision").value();
      if (!precision.empty() && precision != "single" && precision != "double") {
        return cx.Error(absl::StrCat("prototype field ", name, ": precision \"", precision,
                                     "\" (need single or double)"));
      }
      f.double_precision = precision != "single";
    } else {
      return cx.Error(absl::StrCat("prototype field ", name, " has type \"", type,
                                   "\"; points records are read with Integer, ScaledInteger, "
                                   "Float and Structure fields only"));
    }
    out.push_back(std::move(f));
  }
  return absl::OkStatus();
}

absl::StatusOr<E57Scan> ParseScan(const XmlContext& cx, pugi::xml_node node) {
  E57Scan scan;
  scan.name = node.child("name").text().get();
  scan.guid = node.child("guid").text().get();
  if (pugi::xml_node pose = node.child("pose")) {
    const pugi::xml_node r = pose.child("rotation"), t = pose.child("translation");
    double q[4], p[3];
    const char* qn[4] = {"w", "x", "y", "z"};
    for (int i = 0; i < 4; ++i) {
      auto v = Number(cx, r.child(qn[i]), i == 0 ? 1.0 : 0.0);
      if (!v.ok()) return v.status();
      q[i] = *v;
    }
    for (int i = 0; i < 3; ++i) {
      auto v = Number(cx, t.child(qn[i + 1]), 0.0);
      if (!v.ok()) return v.status();
      p[i] = *v;
    }
    auto unit = CheckedUnitQuaternion(q[0], q[1], q[2], q[3]);
    if (!unit.ok()) return cx.Error(absl::StrCat("pose rotation: ", unit.status().message()));
    scan.rotation = Eigen::Quaterniond((*unit)[0], (*unit)[1], (*unit)[2], (*unit)[3]);
    scan.translation = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  const pugi::xml_node points = node.child("points");
  if (!points) return cx.Error("no points element");
  if (std::string_view(points.attribute("type").value()) != "CompressedVector") {
    return cx.Error(absl::StrCat("points has type \"", points.attribute("type").value(),
                                 "\", not CompressedVector"));
  }
  if (!points.attribute("fileOffset")) return cx.Error("points has no fileOffset");
  auto offset = IntegerAttribute<uint64_t>(cx, points, "fileOffset", 0);
  auto count = IntegerAttribute<uint64_t>(cx, points, "recordCount", 0);
  if (!offset.ok()) return offset.status();
  if (!count.ok()) return count.status();
  scan.section_offset = *offset;
  scan.record_count = *count;
  const pugi::xml_node prototype = points.child("prototype");
  if (!prototype) return cx.Error("points has no prototype");
  if (absl::Status s = FlattenPrototype(cx, prototype, "", scan.prototype); !s.ok()) return s;
  if (scan.prototype.empty()) return cx.Error("points' prototype has no fields");
  for (pugi::xml_node codec : points.child("codecs").children()) {
    if (codec.type() == pugi::node_element) {
      return cx.Error("points' codecs list a codec; only the default bit-packing is read");
    }
  }
  if (pugi::xml_node b = node.child("indexBounds");
      b && b.child("rowMaximum") && b.child("columnMaximum")) {
    E57IndexBounds bounds;
    int64_t* v[4] = {&bounds.row_min, &bounds.row_max, &bounds.col_min, &bounds.col_max};
    const char* names[4] = {"rowMinimum", "rowMaximum", "columnMinimum", "columnMaximum"};
    for (int i = 0; i < 4; ++i) {
      auto x = Number(cx, b.child(names[i]), 0.0);
      if (!x.ok()) return x.status();
      // No grid has 2⁴⁰ rows; farther bounds are damage (and would overflow as pixel counts).
      if (*x != std::floor(*x) || std::abs(*x) > 1099511627776.0) {
        return cx.Error(absl::StrCat("indexBounds/", names[i], " is not an integer within ±2⁴⁰"));
      }
      *v[i] = static_cast<int64_t>(*x);
    }
    if (bounds.row_min > bounds.row_max || bounds.col_min > bounds.col_max) {
      return cx.Error("indexBounds: a minimum above its maximum");
    }
    scan.index_bounds = bounds;
  }
  return scan;
}

absl::StatusOr<std::vector<E57Scan>> ParseXml(const std::string& path, std::string_view xml) {
  pugi::xml_document doc;
  const pugi::xml_parse_result parsed =
      doc.load_buffer(xml.data(), xml.size(), pugi::parse_default, pugi::encoding_utf8);
  if (!parsed) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": XML section, byte ", parsed.offset, ": ", parsed.description()));
  }
  const pugi::xml_node root = doc.child("e57Root");
  if (!root) return absl::InvalidArgumentError(path + ": XML section has no e57Root element");
  std::vector<E57Scan> scans;
  int index = 0;
  for (pugi::xml_node child : root.child("data3D").children()) {
    if (child.type() != pugi::node_element) continue;
    const XmlContext cx{path, ScanLabel(index, child.child("name").text().get())};
    auto scan = ParseScan(cx, child);
    if (!scan.ok()) return scan.status();
    scans.push_back(std::move(*scan));
    ++index;
  }
  return scans;
}

// --- The binary sections ---------------------------------------------------------------------

// One field's byte stream, as packets bring it: the bytes not yet decoded and the bit at which
// the next value starts.
struct Stream {
  std::vector<uint8_t> bytes;
  uint64_t bit = 0;
  int bits = 0;

  [[nodiscard]] uint64_t Available() const {
    if (bits == 0) return std::numeric_limits<uint64_t>::max();
    return (bytes.size() * 8 - bit) / static_cast<uint64_t>(bits);
  }
  // The next value's bits, least significant first (E57's bit order).
  uint64_t Next() {
    const uint8_t* b = bytes.data() + (bit >> 3);
    const int shift = static_cast<int>(bit & 7);
    const int nbytes = (shift + bits + 7) >> 3;  // at most 9
    unsigned __int128 w = 0;
    for (int i = 0; i < nbytes; ++i) w |= static_cast<unsigned __int128>(b[i]) << (8 * i);
    bit += static_cast<uint64_t>(bits);
    uint64_t v = static_cast<uint64_t>(w >> shift);
    if (bits < 64) v &= (uint64_t{1} << bits) - 1;
    return v;
  }
  void Append(std::span<const uint8_t> more) {
    bytes.erase(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(bit >> 3));
    bit &= 7;
    bytes.insert(bytes.end(), more.begin(), more.end());
  }
};

}  // namespace

int E57Field::bits() const {
  if (kind == Kind::kFloat) return double_precision ? 64 : 32;
  const uint64_t range = static_cast<uint64_t>(maximum) - static_cast<uint64_t>(minimum);
  return static_cast<int>(std::bit_width(range));
}

int E57Scan::FieldIndex(std::string_view name) const {
  for (size_t i = 0; i < prototype.size(); ++i) {
    if (prototype[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

struct E57Reader::State {
  std::string path;
  E57Header header;
  std::vector<E57Scan> scans;
};

E57Reader::E57Reader(std::unique_ptr<State> state) : state_(std::move(state)) {}
E57Reader::E57Reader(E57Reader&&) noexcept = default;
E57Reader& E57Reader::operator=(E57Reader&&) noexcept = default;
E57Reader::~E57Reader() = default;
const std::string& E57Reader::path() const { return state_->path; }
const E57Header& E57Reader::header() const { return state_->header; }
const std::vector<E57Scan>& E57Reader::scans() const { return state_->scans; }
std::string E57Reader::Where(size_t scan) const {
  return absl::StrCat(state_->path, ": ", ScanLabel(scan, state_->scans.at(scan).name));
}

absl::StatusOr<E57Reader> E57Reader::Open(const std::string& path) {
  auto raw = import_internal::ByteReader::Open(path);
  if (!raw.ok()) return raw.status();
  // The signature first, so that any other file is named as such before its checksums.
  char signature[8] = {};
  if (!raw->ReadBytes(signature, 8) || std::memcmp(signature, "ASTM-E57", 8) != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": not an E57 file (it does not begin with \"ASTM-E57\")"));
  }
  std::optional<PagedFile> file(std::in_place, path, *std::move(raw));
  uint8_t bytes[kHeaderBytes];
  if (absl::Status s = file->Read(0, bytes, kHeaderBytes); !s.ok()) return s;
  auto state = std::make_unique<State>();
  state->path = path;
  E57Header& h = state->header;
  import_internal::SpanReader r({bytes, kHeaderBytes});
  std::span<const uint8_t> skip;
  r.Bytes(8, skip);
  r.Read(h.version_major);
  r.Read(h.version_minor);
  r.Read(h.file_length);
  r.Read(h.xml_offset);
  r.Read(h.xml_length);
  r.Read(h.page_size);
  if (h.version_major != 1) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": E57 version ", h.version_major, ".",
                                                   h.version_minor, " (only 1.x is read)"));
  }
  if (h.page_size != kPhysicalPage) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": page size ", h.page_size, " (the standard's is 1024)"));
  }
  if (h.file_length != file->size()) {
    return absl::DataLossError(
        absl::StrCat(path, ": the header says the file has ", h.file_length, " bytes, it has ",
                     file->size(), h.file_length > file->size() ? ": it is cut short" : ""));
  }
  uint64_t xml_at = 0;
  if (!ToLogical(h.xml_offset, xml_at) || xml_at > file->logical_size() ||
      h.xml_length > file->logical_size() - xml_at) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": the XML section (offset ", h.xml_offset,
                                                   ", ", h.xml_length,
                                                   " bytes) lies outside the file"));
  }
  std::string xml(h.xml_length, '\0');
  if (absl::Status s = file->Read(xml_at, xml.data(), xml.size()); !s.ok()) return s;
  auto scans = ParseXml(path, xml);
  if (!scans.ok()) return scans.status();
  for (size_t i = 0; i < scans->size(); ++i) {
    const E57Scan& s = (*scans)[i];
    uint64_t at = 0;
    if (!ToLogical(s.section_offset, at) || at + kSectionHeaderBytes > file->logical_size()) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": ", ScanLabel(i, s.name), ": points fileOffset ", s.section_offset,
                       " lies outside the file (", file->size(), " bytes)"));
    }
  }
  state->scans = std::move(*scans);
  return E57Reader(std::move(state));
}

absl::Status E57Reader::ReadRecords(int scan_index, std::span<const int> fields,
                                    const RecordBatch& on_batch, size_t batch) const {
  const E57Scan& scan = state_->scans.at(static_cast<size_t>(scan_index));
  const std::string& path = state_->path;
  const std::string where = absl::StrCat(Where(static_cast<size_t>(scan_index)), " points");
  for (int f : fields) {
    if (f < 0 || static_cast<size_t>(f) >= scan.prototype.size()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": no field ", f));
    }
  }
  auto file = PagedFile::Open(path);
  if (!file.ok()) return file.status();

  uint64_t section = 0;
  ToLogical(scan.section_offset, section);  // checked by Open
  uint8_t head[kSectionHeaderBytes];
  if (absl::Status s = file->Read(section, head, sizeof head); !s.ok()) return s;
  uint64_t section_length = 0, data_offset = 0;
  std::memcpy(&section_length, head + 8, 8);
  std::memcpy(&data_offset, head + 16, 8);
  if (head[0] != kCompressedVectorSection) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": the section at byte ",
                                                   scan.section_offset, " has id ", head[0],
                                                   ", not a compressed vector's (1)"));
  }
  const uint64_t section_end = section + section_length;
  uint64_t pos = 0;
  if (section_length < kSectionHeaderBytes || section_length > file->logical_size() - section ||
      !ToLogical(data_offset, pos) || pos < section + kSectionHeaderBytes || pos > section_end) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": the section at byte ", scan.section_offset, " (", section_length,
                     " logical bytes, data at byte ", data_offset, ") does not fit the file"));
  }

  std::vector<Stream> streams(scan.prototype.size());
  uint64_t record_bits = 0;
  for (size_t i = 0; i < streams.size(); ++i) {
    streams[i].bits = scan.prototype[i].bits();
    record_bits += static_cast<uint64_t>(streams[i].bits);
  }
  // A record takes at least one bit of the section (a prototype of constants alone would let a
  // damaged recordCount promise any number of records in no bytes).
  if (scan.record_count > section_length * 8 / std::max<uint64_t>(record_bits, 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": recordCount ", scan.record_count, " of ", record_bits,
                     " bits each does not fit its section of ", section_length, " bytes"));
  }
  // Each stream's column in the batch, or -1 for a field not asked for.
  std::vector<int> column_of(streams.size(), -1);
  for (size_t k = 0; k < fields.size(); ++k) column_of[static_cast<size_t>(fields[k])] = int(k);
  std::vector<std::vector<double>> columns(fields.size());
  std::vector<uint8_t> packet;
  uint64_t done = 0;

  // Decodes every record whose values have all arrived.
  const auto decode = [&](uint64_t packet_at) -> absl::Status {
    uint64_t ready = scan.record_count - done;
    for (const Stream& s : streams) ready = std::min(ready, s.Available());
    while (ready > 0) {
      const size_t n = static_cast<size_t>(std::min<uint64_t>(ready, batch));
      for (size_t k = 0; k < fields.size(); ++k) columns[k].resize(n);
      for (size_t i = 0; i < streams.size(); ++i) {
        Stream& s = streams[i];
        const E57Field& f = scan.prototype[i];
        if (column_of[i] < 0) {
          s.bit += static_cast<uint64_t>(s.bits) * n;
          continue;
        }
        std::vector<double>& out = columns[static_cast<size_t>(column_of[i])];
        if (f.kind == E57Field::Kind::kFloat) {
          for (size_t j = 0; j < n; ++j) {
            const uint64_t v = s.Next();
            if (f.double_precision) {
              out[j] = std::bit_cast<double>(v);
            } else {
              out[j] = std::bit_cast<float>(static_cast<uint32_t>(v));
            }
          }
          continue;
        }
        const uint64_t range = static_cast<uint64_t>(f.maximum) - static_cast<uint64_t>(f.minimum);
        for (size_t j = 0; j < n; ++j) {
          const uint64_t raw = s.bits == 0 ? 0 : s.Next();
          if (raw > range) {
            return absl::InvalidArgumentError(
                absl::StrCat(where, ": record ", done + j, " (packet at byte ", packet_at,
                             "): field ", f.name, " is above its maximum ", f.maximum));
          }
          const auto value = static_cast<int64_t>(static_cast<uint64_t>(f.minimum) + raw);
          out[j] = f.kind == E57Field::Kind::kInteger
                       ? static_cast<double>(value)
                       : static_cast<double>(value) * f.scale + f.offset;
        }
      }
      if (absl::Status s = on_batch(columns, n); !s.ok()) return s;
      done += n;
      ready -= n;
    }
    return absl::OkStatus();
  };

  while (done < scan.record_count) {
    const uint64_t physical = ToPhysical(pos);
    uint8_t ph[4];
    if (pos + 4 > section_end) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": the section ends after ", done,
                                                     " of its ", scan.record_count, " records"));
    }
    if (absl::Status s = file->Read(pos, ph, 4); !s.ok()) return s;
    const uint64_t length = uint64_t{ph[2]} + (uint64_t{ph[3]} << 8) + 1;
    if (pos + length > section_end) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": the packet at byte ", physical, " (",
                                                     length,
                                                     " bytes) runs past its section's end"));
    }
    if (ph[0] == kDataPacket) {
      packet.resize(length);
      if (absl::Status s = file->Read(pos, packet.data(), length); !s.ok()) return s;
      import_internal::SpanReader pr(packet);
      std::span<const uint8_t> skip;
      uint16_t count = 0;
      pr.Bytes(4, skip);
      if (!pr.Read(count) || count != streams.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat(where, ": the packet at byte ", physical, " has ", count,
                         " byte streams; the prototype has ", streams.size(), " fields"));
      }
      std::vector<uint16_t> lengths(count);
      bool ok = true;
      for (uint16_t& l : lengths) ok = ok && pr.Read(l);
      std::vector<std::span<const uint8_t>> buffers(count);
      for (size_t i = 0; ok && i < count; ++i) ok = pr.Bytes(lengths[i], buffers[i]);
      if (!ok) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": the packet at byte ", physical,
                                                       " is shorter than its streams' lengths"));
      }
      for (size_t i = 0; i < count; ++i) streams[i].Append(buffers[i]);
      if (absl::Status s = decode(physical); !s.ok()) return s;
    } else if (ph[0] != kIndexPacket && ph[0] != kEmptyPacket) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": the packet at byte ", physical,
                                                     " has type ", ph[0],
                                                     " (0 index, 1 data, 2 empty)"));
    }
    pos += length;
  }
  return absl::OkStatus();
}

}  // namespace carvemap
