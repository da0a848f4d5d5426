#include "storage/import/ply_import.h"

#include <array>
#include <cmath>
#include <optional>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"
#include "storage/import/byte_reader.h"

namespace carvemap {
namespace {

using import_internal::ByteReader;

enum class Format { kAscii, kBinaryLittle, kBinaryBig };
enum class Type { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

std::optional<Type> ParseType(absl::string_view name) {
  if (name == "char" || name == "int8") return Type::kInt8;
  if (name == "uchar" || name == "uint8") return Type::kUint8;
  if (name == "short" || name == "int16") return Type::kInt16;
  if (name == "ushort" || name == "uint16") return Type::kUint16;
  if (name == "int" || name == "int32") return Type::kInt32;
  if (name == "uint" || name == "uint32") return Type::kUint32;
  if (name == "float" || name == "float32") return Type::kFloat32;
  if (name == "double" || name == "float64") return Type::kFloat64;
  return std::nullopt;
}

int TypeBytes(Type t) {
  switch (t) {
    case Type::kInt8: case Type::kUint8: return 1;
    case Type::kInt16: case Type::kUint16: return 2;
    case Type::kInt32: case Type::kUint32: case Type::kFloat32: return 4;
    case Type::kFloat64: return 8;
  }
  return 0;
}

struct Property {
  std::string name;
  Type type = Type::kFloat32;
  bool is_list = false;
  Type count_type = Type::kUint8;  // lists only
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> properties;
};

struct Header {
  Format format = Format::kAscii;
  std::vector<Element> elements;
};

// Reads one value of `type` (binary) or one token (ASCII) as double; false at end of file or
// on a malformed token. ASCII: `delim` receives the character that ended the token.
bool ReadValue(ByteReader& r, Format format, Type type, double& out, int& delim) {
  if (format == Format::kAscii) {
    std::string token;
    int c = r.GetChar();
    while (c == ' ' || c == '\t' || c == '\n' || c == '\r') c = r.GetChar();
    while (c != EOF && c != ' ' && c != '\t' && c != '\n' && c != '\r') {
      token.push_back(static_cast<char>(c));
      if (token.size() > 64) return false;
      c = r.GetChar();
    }
    delim = c;
    return !token.empty() && absl::SimpleAtod(token, &out);
  }
  switch (type) {
#define CARVEMAP_PLY_READ(T)        \
  {                                 \
    T v;                            \
    if (!r.Read(v)) return false;   \
    out = static_cast<double>(v);   \
    return true;                    \
  }
    case Type::kInt8: CARVEMAP_PLY_READ(int8_t)
    case Type::kUint8: CARVEMAP_PLY_READ(uint8_t)
    case Type::kInt16: CARVEMAP_PLY_READ(int16_t)
    case Type::kUint16: CARVEMAP_PLY_READ(uint16_t)
    case Type::kInt32: CARVEMAP_PLY_READ(int32_t)
    case Type::kUint32: CARVEMAP_PLY_READ(uint32_t)
    case Type::kFloat32: CARVEMAP_PLY_READ(float)
    case Type::kFloat64: CARVEMAP_PLY_READ(double)
#undef CARVEMAP_PLY_READ
  }
  return false;
}

// Reads one row of `element` into `values` (list properties are read and dropped). ASCII
// rows must end at the end of a line, so a missing or extra value is caught in its own row.
bool ReadRow(ByteReader& r, Format format, const Element& element, std::vector<double>& values) {
  values.resize(element.properties.size());
  int delim = '\n';
  for (size_t i = 0; i < element.properties.size(); ++i) {
    const Property& p = element.properties[i];
    if (!p.is_list) {
      if (!ReadValue(r, format, p.type, values[i], delim)) return false;
      continue;
    }
    double n = 0;
    if (!ReadValue(r, format, p.count_type, n, delim) || n < 0 || n != std::floor(n)) {
      return false;
    }
    if (format != Format::kAscii) {
      if (!r.Skip(static_cast<uint64_t>(n) * TypeBytes(p.type))) return false;
    } else {
      for (double k = 0; k < n; ++k) {
        double ignored;
        if (!ReadValue(r, format, p.type, ignored, delim)) return false;
      }
    }
    values[i] = n;
  }
  if (format == Format::kAscii) {
    while (delim == ' ' || delim == '\t' || delim == '\r') delim = r.GetChar();
    if (delim != '\n' && delim != EOF) return false;
  }
  return true;
}

absl::StatusOr<Header> ReadHeader(const std::string& file, ByteReader& r) {
  constexpr size_t kMaxHeaderBytes = 1 << 20;  // a header is a few hundred bytes
  Header header;
  bool saw_format = false;
  for (int line_no = 1;; ++line_no) {
    std::string line;
    for (int c = r.GetChar(); c != '\n'; c = r.GetChar()) {
      if (c == EOF || r.offset() > kMaxHeaderBytes) {
        return absl::InvalidArgumentError(
            absl::StrCat(file, ": PLY header has no end_header line"));
      }
      line.push_back(static_cast<char>(c));
    }
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto bad = [&](absl::string_view what) {
      return absl::InvalidArgumentError(
          absl::StrCat(file, ": PLY header line ", line_no, " '", line, "': ", what));
    };
    std::vector<absl::string_view> tok = absl::StrSplit(line, ' ', absl::SkipWhitespace());
    if (line_no == 1) {
      if (line != "ply") return absl::InvalidArgumentError(file + ": not a PLY file");
      continue;
    }
    if (tok.empty() || tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "end_header") break;
    if (tok[0] == "format") {
      if (tok.size() != 3 || tok[2] != "1.0") return bad("expected 'format <type> 1.0'");
      if (tok[1] == "ascii") header.format = Format::kAscii;
      else if (tok[1] == "binary_little_endian") header.format = Format::kBinaryLittle;
      else if (tok[1] == "binary_big_endian") header.format = Format::kBinaryBig;
      else return bad("unknown format");
      saw_format = true;
    } else if (tok[0] == "element") {
      Element e;
      if (tok.size() != 3 || !absl::SimpleAtoi(tok[2], &e.count)) {
        return bad("expected 'element <name> <count>'");
      }
      e.name = std::string(tok[1]);
      header.elements.push_back(std::move(e));
    } else if (tok[0] == "property") {
      if (header.elements.empty()) return bad("property before any element");
      Property p;
      if (tok.size() == 5 && tok[1] == "list") {
        auto count_type = ParseType(tok[2]);
        auto type = ParseType(tok[3]);
        if (!count_type || !type) return bad("unknown type");
        // A list's length is a count (and a float one would not convert to the byte count).
        if (*count_type == Type::kFloat32 || *count_type == Type::kFloat64) {
          return bad("a list's count type must be an integer type");
        }
        p = Property{std::string(tok[4]), *type, true, *count_type};
      } else if (tok.size() == 3) {
        auto type = ParseType(tok[1]);
        if (!type) return bad("unknown type");
        p = Property{std::string(tok[2]), *type, false, Type::kUint8};
      } else {
        return bad("expected 'property <type> <name>' or 'property list <type> <type> <name>'");
      }
      header.elements.back().properties.push_back(std::move(p));
    } else {
      return bad("unknown keyword");
    }
  }
  if (!saw_format) return absl::InvalidArgumentError(file + ": PLY header has no format line");
  return header;
}

// Index of the scalar property `name` in `e`, or -1.
int FindScalar(const Element& e, absl::string_view name) {
  for (size_t i = 0; i < e.properties.size(); ++i) {
    if (e.properties[i].name == name && !e.properties[i].is_list) return static_cast<int>(i);
  }
  return -1;
}

constexpr std::array<std::array<absl::string_view, 3>, 4> kOriginNames = {{
    {"sensor_x", "sensor_y", "sensor_z"},
    {"sx", "sy", "sz"},
    {"origin_x", "origin_y", "origin_z"},
    {"vp_x", "vp_y", "vp_z"},
}};
constexpr std::array<absl::string_view, 3> kTimeNames = {"t", "time", "timestamp"};

}  // namespace

SensorInfo PlySensor(const PlyImportOptions& options) {
  SensorInfo info;
  info.name = "ply";
  info.kind = SensorKind::kPoints;
  info.sigma_t_s = options.sigma_t_s;
  info.range_sigma = options.range_sigma;
  info.max_range_m = options.max_range_m;
  return info;
}

absl::StatusOr<ImportedScan> ImportPly(const std::string& file, const PlyImportOptions& options,
                                       const FrameSink& sink) {
  auto opened = ByteReader::Open(file);
  if (!opened.ok()) return opened.status();
  ByteReader r = *std::move(opened);
  auto header = ReadHeader(file, r);
  if (!header.ok()) return header.status();
  const Format format = header->format;
  r.set_big_endian(format == Format::kBinaryBig);

  // Elements are stored in header order: skip those before `vertex`.
  const Element* vertex = nullptr;
  std::vector<double> row;
  for (const Element& e : header->elements) {
    if (e.name == "vertex") {
      vertex = &e;
      break;
    }
    // Rows without properties hold no bytes: nothing to skip, however many the count says.
    if (e.properties.empty()) continue;
    for (uint64_t i = 0; i < e.count; ++i) {
      if (!ReadRow(r, format, e, row)) {
        return absl::DataLossError(
            absl::StrCat(file, ": element '", e.name, "' row ", i, ": truncated or malformed"));
      }
    }
  }
  if (!vertex) return absl::InvalidArgumentError(file + ": PLY has no 'vertex' element");

  const int ix = FindScalar(*vertex, "x"), iy = FindScalar(*vertex, "y"),
            iz = FindScalar(*vertex, "z");
  if (ix < 0 || iy < 0 || iz < 0) {
    return absl::InvalidArgumentError(file + ": vertex element lacks scalar x, y and z");
  }
  std::array<int, 3> io = {-1, -1, -1};
  for (const auto& names : kOriginNames) {
    std::array<int, 3> found = {FindScalar(*vertex, names[0]), FindScalar(*vertex, names[1]),
                                FindScalar(*vertex, names[2])};
    if (found[0] >= 0 && found[1] >= 0 && found[2] >= 0) {
      io = found;
      break;
    }
  }
  if (io[0] < 0) {
    std::vector<std::string> accepted;
    for (const auto& names : kOriginNames) accepted.push_back(absl::StrJoin(names, " "));
    return absl::InvalidArgumentError(
        absl::StrCat(file, ": vertex element has no sensor origin; expected one of: ",
                     absl::StrJoin(accepted, " | ")));
  }
  int it = -1;
  for (absl::string_view name : kTimeNames) {
    if ((it = FindScalar(*vertex, name)) >= 0) break;
  }
  if (vertex->count == 0) return absl::InvalidArgumentError(file + ": PLY has no vertices");
  if (format != Format::kAscii) {
    uint64_t row_bytes = 0;  // lower bound (lists count their length field only)
    for (const Property& p : vertex->properties) {
      row_bytes += TypeBytes(p.is_list ? p.count_type : p.type);
    }
    if (vertex->count > r.remaining() / row_bytes) {
      return absl::DataLossError(absl::StrCat(file, ": header declares ", vertex->count,
                                              " vertices of ", row_bytes, " bytes but only ",
                                              r.remaining(), " bytes follow (truncated?)"));
    }
  }

  ImportedScan scan;
  scan.sensor = PlySensor(options);
  std::vector<Eigen::Vector3f> points;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double frame_t = 0;
  const auto flush = [&]() -> absl::Status {
    scan.path.push_back(PathRecord{frame_t, origin.x(), origin.y(), origin.z(), 1, 0, 0, 0});
    absl::Status s = EmitFrame(sink, frame_t, points, scan);
    points.clear();
    return s;
  };
  for (uint64_t v = 0; v < vertex->count; ++v) {
    if (!ReadRow(r, format, *vertex, row)) {
      return absl::DataLossError(
          absl::StrCat(file, ": vertex row ", v,
                       ": file ends, a value is malformed, or the row does not match the header"));
    }
    const Eigen::Vector3d world(row[ix], row[iy], row[iz]);
    const Eigen::Vector3d o(row[io[0]], row[io[1]], row[io[2]]);
    const double t = it >= 0 ? row[it] : 0.0;
    if (!world.allFinite() || !o.allFinite() || !std::isfinite(t)) {
      return absl::InvalidArgumentError(
          absl::StrCat(file, ": vertex row ", v, ": non-finite position, origin or time"));
    }
    const bool new_frame = v == 0 || o != origin || (it >= 0 && t != frame_t);
    if (new_frame) {
      if (v > 0) {
        if (absl::Status s = flush(); !s.ok()) return s;
      }
      const double next_t = it >= 0 ? t : static_cast<double>(scan.path.size());
      if (v > 0 && !(next_t > frame_t)) {
        return absl::InvalidArgumentError(absl::StrCat(
            file, ": vertex row ", v, ": a new frame (origin ", o.x(), " ", o.y(), " ", o.z(),
            ") starts at time ", next_t, ", not after the previous frame's ", frame_t,
            "; frames are runs of vertices with one origin and time, and times must increase"));
      }
      origin = o;
      frame_t = next_t;
    }
    const Eigen::Vector3f point = (world - origin).cast<float>();
    // scan.h5 stores points as f32: a finite double can still overflow it.
    if (!point.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat(
          file, ": vertex row ", v, ": point minus sensor origin is beyond float range"));
    }
    points.push_back(point);
  }
  if (absl::Status s = flush(); !s.ok()) return s;
  return scan;
}

}  // namespace carvemap
