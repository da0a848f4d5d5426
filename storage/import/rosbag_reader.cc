#include "storage/import/rosbag_reader.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <unordered_map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/import/byte_reader.h"
#include "storage/import/decompress.h"

namespace carvemap {
namespace {

static_assert(std::endian::native == std::endian::little,
              "ROS 1 serialization is little-endian; the reader copies numbers as they are");

constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr uint8_t kOpMessage = 0x02, kOpChunk = 0x05, kOpConnection = 0x07;
// A chunk's stated size is checked against this before it is allocated: rosbag writes chunks
// of ~768 KiB, and bz2 compresses sensor data by far less than this factor.
constexpr uint64_t kMaxChunkBytes = uint64_t{1} << 30;
constexpr uint64_t kMaxChunkRatio = 200;

// Sequential reads of serialized values from a byte span: ROS 1's serialization, or (cdr)
// ROS 2's classic little-endian CDR, where a number sits at a multiple of its size from the
// start of the payload, a string's length counts its closing NUL, and a header has no seq.
class Cursor {
 public:
  explicit Cursor(std::span<const uint8_t> d, bool cdr = false) : r_(d), cdr_(cdr) {}
  [[nodiscard]] size_t left() const { return r_.left(); }

  template <typename T>
  bool Read(T& v) {
    return (!cdr_ || r_.Align(sizeof(T))) && r_.Read(v);
  }
  bool Bytes(uint64_t n, std::span<const uint8_t>& out) { return r_.Bytes(n, out); }
  bool String(std::string& s) {
    uint32_t n = 0;
    std::span<const uint8_t> b;
    if (!Read(n) || !r_.Bytes(n, b)) return false;
    if (cdr_) {
      if (b.empty() || b.back() != 0) return false;
      b = b.first(b.size() - 1);
    }
    s.assign(reinterpret_cast<const char*>(b.data()), b.size());
    return true;
  }
  // ROS 1: u32 seq, u32 sec, u32 nsec, frame_id; ROS 2: i32 sec, u32 nanosec, frame_id.
  bool Header(RosHeader& h) {
    if (cdr_) {
      int32_t sec = 0;
      uint32_t nsec = 0;
      if (!Read(sec) || !Read(nsec) || !String(h.frame_id)) return false;
      h.stamp = sec + nsec * 1e-9;
      return true;
    }
    uint32_t sec = 0, nsec = 0;
    if (!Read(h.seq) || !Read(sec) || !Read(nsec) || !String(h.frame_id)) return false;
    h.stamp = sec + nsec * 1e-9;
    return true;
  }
  [[nodiscard]] bool cdr() const { return cdr_; }

 private:
  import_internal::SpanReader r_;
  bool cdr_;
};

// The cursor over a message's payload: a CDR message starts with its encapsulation (0x00 0x01
// for little-endian classic CDR, then two option bytes).
absl::StatusOr<Cursor> Payload(absl::string_view what, std::span<const uint8_t> data,
                               RosEncoding encoding) {
  if (encoding == RosEncoding::kRos1) return Cursor(data);
  if (data.size() < 4 || data[0] != 0x00 || data[1] != 0x01) {
    return absl::InvalidArgumentError(absl::StrCat(
        what,
        ": not little-endian CDR (its encapsulation is not 00 01; only ROS 2's default "
        "encoding is read)"));
  }
  return Cursor(data.subspan(4), true);
}

absl::Status Short(absl::string_view what, absl::string_view field) {
  return absl::InvalidArgumentError(
      absl::StrCat(what, ": the message ends inside its ", field, " (not a ", what, "?)"));
}

absl::Status CheckAllRead(absl::string_view what, const Cursor& c) {
  // A CDR payload may be padded to a multiple of 4 bytes.
  if (c.left() == 0 || (c.cdr() && c.left() < 4)) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat(what, ": ", c.left(), " bytes left over after the message (not a ", what, "?)"));
}

// A record header's fields, name ➜ value bytes.
using Fields = std::vector<std::pair<std::string, std::span<const uint8_t>>>;

bool ParseFields(std::span<const uint8_t> bytes, Fields& out) {
  out.clear();
  Cursor c(bytes);
  while (c.left() > 0) {
    uint32_t n = 0;
    std::span<const uint8_t> field;
    if (!c.Read(n) || !c.Bytes(n, field) || field.empty()) return false;
    const auto* eq = static_cast<const uint8_t*>(std::memchr(field.data(), '=', field.size()));
    if (!eq) return false;
    const size_t name_len = eq - field.data();
    out.emplace_back(std::string(reinterpret_cast<const char*>(field.data()), name_len),
                     field.subspan(name_len + 1));
  }
  return true;
}

const std::span<const uint8_t>* Find(const Fields& f, absl::string_view name) {
  for (const auto& [n, v] : f) {
    if (n == name) return &v;
  }
  return nullptr;
}

template <typename T>
bool FieldNumber(const Fields& f, absl::string_view name, T& out) {
  const std::span<const uint8_t>* v = Find(f, name);
  if (!v || v->size() != sizeof(T)) return false;
  std::memcpy(&out, v->data(), sizeof(T));
  return true;
}

std::string FieldString(const Fields& f, absl::string_view name) {
  const std::span<const uint8_t>* v = Find(f, name);
  return v ? std::string(reinterpret_cast<const char*>(v->data()), v->size()) : std::string();
}

class BagParser {
 public:
  BagParser(const std::string& path, const BagMessageFn& fn) : path_(path), fn_(fn) {}

  absl::Status Run(std::vector<BagConnection>* connections) {
    absl::StatusOr<import_internal::ByteReader> r = import_internal::ByteReader::Open(path_);
    if (!r.ok()) return r.status();
    char magic[sizeof(kMagic) - 1];
    if (!r->ReadBytes(magic, sizeof(magic)) || std::memcmp(magic, kMagic, sizeof(magic)) != 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          path_, ": not a ROS 1 bag of format 2.0 (it does not start with \"#ROSBAG V2.0\")"));
    }
    std::vector<uint8_t> header, data;
    while (r->remaining() > 0) {
      const uint64_t at = r->offset();
      uint32_t header_len = 0, data_len = 0;
      if (!r->Read(header_len) || header_len > r->remaining()) return CutShort(at);
      header.resize(header_len);
      if (!r->ReadBytes(header.data(), header_len) || !r->Read(data_len) ||
          data_len > r->remaining()) {
        return CutShort(at);
      }
      if (!ParseFields(header, fields_)) return Bad(at, "its header's fields are malformed");
      uint8_t op = 0;
      if (!FieldNumber(fields_, "op", op)) return Bad(at, "it has no op field");
      if (op != kOpChunk && op != kOpConnection && op != kOpMessage) {
        if (!r->Skip(data_len)) return CutShort(at);
        continue;
      }
      data.resize(data_len);
      if (!r->ReadBytes(data.data(), data_len)) return CutShort(at);
      absl::Status s = op == kOpChunk ? Chunk(at, data) : Record(at, op, data);
      if (!s.ok()) return s;
    }
    if (connections) {
      connections->clear();
      for (const auto& [id, c] : connections_) connections->push_back(c);
      std::sort(connections->begin(), connections->end(),
                [](const BagConnection& a, const BagConnection& b) { return a.id < b.id; });
    }
    return absl::OkStatus();
  }

 private:
  absl::Status Bad(uint64_t at, absl::string_view why) const {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": record at byte ", at, ": ", why));
  }
  absl::Status CutShort(uint64_t at) const {
    return absl::DataLossError(absl::StrCat(path_, ": record at byte ", at,
                                            " runs past the end of the file (a bag cut short?)"));
  }

  // A chunk: its records, decompressed.
  absl::Status Chunk(uint64_t at, std::span<const uint8_t> data) {
    const std::string compression = FieldString(fields_, "compression");
    uint32_t size = 0;
    if (!FieldNumber(fields_, "size", size)) return Bad(at, "a chunk without its size");
    std::span<const uint8_t> records = data;
    if (compression == "bz2" || compression == "lz4") {
      if (size > kMaxChunkBytes || size > kMaxChunkRatio * data.size() + 4096) {
        return Bad(at, absl::StrCat("a ", compression, " chunk claims ", size, " bytes from ",
                                    data.size()));
      }
      plain_.resize(size);
      absl::Status s = compression == "bz2" ? import_internal::DecompressBz2(data, plain_)
                                            : import_internal::DecompressLz4Frame(data, plain_);
      if (!s.ok()) return Bad(at, s.message());
      records = plain_;
    } else if (compression != "none") {
      return Bad(at, absl::StrCat("unknown chunk compression \"", compression, "\""));
    } else if (size != data.size()) {
      return Bad(at, absl::StrCat("an uncompressed chunk of ", data.size(), " bytes says ", size));
    }
    // The inner records use the same layout; `at` stays the chunk's offset in errors.
    Cursor c(records);
    while (c.left() > 0) {
      uint32_t header_len = 0, data_len = 0;
      std::span<const uint8_t> header, body;
      if (!c.Read(header_len) || !c.Bytes(header_len, header) || !c.Read(data_len) ||
          !c.Bytes(data_len, body)) {
        return Bad(at, "a record inside the chunk runs past the chunk's end");
      }
      if (!ParseFields(header, fields_)) return Bad(at, "a record inside the chunk is malformed");
      uint8_t op = 0;
      if (!FieldNumber(fields_, "op", op)) return Bad(at, "a record inside the chunk has no op");
      if (op != kOpConnection && op != kOpMessage) continue;
      if (absl::Status s = Record(at, op, body); !s.ok()) return s;
    }
    return absl::OkStatus();
  }

  // A connection or a message record (fields_ holds its header).
  absl::Status Record(uint64_t at, uint8_t op, std::span<const uint8_t> data) {
    uint32_t conn = 0;
    if (!FieldNumber(fields_, "conn", conn)) return Bad(at, "a record without its connection");
    if (op == kOpConnection) {
      if (connections_.contains(conn)) return absl::OkStatus();  // repeated after the index
      Fields info;
      if (!ParseFields(data, info)) return Bad(at, "a connection's fields are malformed");
      BagConnection c{conn, FieldString(fields_, "topic"), FieldString(info, "type"),
                      FieldString(info, "md5sum")};
      if (c.topic.empty()) c.topic = FieldString(info, "topic");
      connections_.emplace(conn, std::move(c));
      return absl::OkStatus();
    }
    auto it = connections_.find(conn);
    if (it == connections_.end()) {
      return Bad(at, absl::StrCat("a message of connection ", conn, ", which no record declared"));
    }
    uint32_t time[2] = {0, 0};
    if (!FieldNumber(fields_, "time", time)) return Bad(at, "a message without its time");
    BagMessage m{&it->second, time[0] + time[1] * 1e-9, data, next_index_++};
    return fn_(m);
  }

  const std::string& path_;
  const BagMessageFn& fn_;
  Fields fields_;
  std::vector<uint8_t> plain_;
  std::unordered_map<uint32_t, BagConnection> connections_;
  uint64_t next_index_ = 0;
};

}  // namespace

absl::Status ReadBag(const std::string& path, const BagMessageFn& fn,
                     std::vector<BagConnection>* connections) {
  return BagParser(path, fn).Run(connections);
}

absl::StatusOr<RosLaserScan> DecodeLaserScan(std::span<const uint8_t> data, RosEncoding encoding) {
  constexpr char kWhat[] = "LaserScan";
  absl::StatusOr<Cursor> payload = Payload(kWhat, data, encoding);
  if (!payload.ok()) return payload.status();
  Cursor& c = *payload;
  RosLaserScan s;
  if (!c.Header(s.header)) return Short(kWhat, "header");
  for (float* f : {&s.angle_min, &s.angle_max, &s.angle_increment, &s.time_increment, &s.scan_time,
                   &s.range_min, &s.range_max}) {
    if (!c.Read(*f)) return Short(kWhat, "angles and ranges limits");
  }
  // Each return's bearing is angle_min + i · angle_increment: without both finite no return
  // has a direction.
  if (!std::isfinite(s.angle_min) || !std::isfinite(s.angle_increment)) {
    return absl::InvalidArgumentError(absl::StrCat(kWhat, ": angle_min ", s.angle_min,
                                                   " or angle_increment ", s.angle_increment,
                                                   " is not finite"));
  }
  uint32_t n = 0;
  std::span<const uint8_t> bytes;
  if (!c.Read(n) || !c.Bytes(uint64_t{n} * 4, bytes)) return Short(kWhat, "ranges");
  s.ranges.resize(n);
  if (n > 0) std::memcpy(s.ranges.data(), bytes.data(), bytes.size());
  if (!c.Read(n) || !c.Bytes(uint64_t{n} * 4, bytes)) return Short(kWhat, "intensities");
  if (absl::Status st = CheckAllRead(kWhat, c); !st.ok()) return st;
  return s;
}

absl::StatusOr<RosPointCloud> DecodePointCloud2(std::span<const uint8_t> data, RosEncoding encoding,
                                                bool points) {
  constexpr char kWhat[] = "PointCloud2";
  constexpr uint8_t kFloat32 = 7;  // sensor_msgs/PointField.FLOAT32
  absl::StatusOr<Cursor> payload = Payload(kWhat, data, encoding);
  if (!payload.ok()) return payload.status();
  Cursor& c = *payload;
  RosPointCloud out;
  uint32_t num_fields = 0;
  if (!c.Header(out.header)) return Short(kWhat, "header");
  if (!c.Read(out.height) || !c.Read(out.width) || !c.Read(num_fields)) {
    return Short(kWhat, "size");
  }
  int64_t xyz[3] = {-1, -1, -1};
  for (uint32_t i = 0; i < num_fields; ++i) {
    std::string name;
    uint32_t offset = 0, count = 0;
    uint8_t datatype = 0;
    if (!c.String(name) || !c.Read(offset) || !c.Read(datatype) || !c.Read(count)) {
      return Short(kWhat, "fields");
    }
    const int axis = name == "x" ? 0 : name == "y" ? 1 : name == "z" ? 2 : -1;
    if (axis < 0) continue;
    if (datatype != kFloat32 || count > 1) {
      return absl::InvalidArgumentError(absl::StrCat(kWhat, ": field ", name, " is of datatype ",
                                                     int(datatype), " × ", count,
                                                     "; only one float32 (datatype 7) is read"));
    }
    xyz[axis] = offset;
  }
  uint8_t big_endian = 0, dense = 0;
  uint32_t point_step = 0, row_step = 0, data_len = 0;
  std::span<const uint8_t> bytes;
  if (!c.Read(big_endian) || !c.Read(point_step) || !c.Read(row_step) || !c.Read(data_len) ||
      !c.Bytes(data_len, bytes) || !c.Read(dense)) {
    return Short(kWhat, "data");
  }
  if (absl::Status st = CheckAllRead(kWhat, c); !st.ok()) return st;
  if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) {
    return absl::InvalidArgumentError(absl::StrCat(kWhat, ": the cloud has no x, y and z fields"));
  }
  if (big_endian) {
    return absl::InvalidArgumentError(absl::StrCat(kWhat, ": big-endian clouds are not read"));
  }
  for (int64_t o : xyz) {
    if (o + 4 > point_step) {
      return absl::InvalidArgumentError(absl::StrCat(
          kWhat, ": a field at byte ", o, " does not fit the point step of ", point_step));
    }
  }
  if (uint64_t{out.width} * point_step > row_step ||
      uint64_t{out.height} * row_step > bytes.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        kWhat, ": ", out.height, " rows of ", out.width, " points (point step ", point_step,
        ", row step ", row_step, ") need more than its ", bytes.size(), " bytes of data"));
  }
  if (!points) return out;
  out.points.reserve(uint64_t{out.height} * out.width);
  for (uint32_t v = 0; v < out.height; ++v) {
    for (uint32_t u = 0; u < out.width; ++u) {
      const uint8_t* p = bytes.data() + uint64_t{v} * row_step + uint64_t{u} * point_step;
      Eigen::Vector3f q;
      for (int d = 0; d < 3; ++d) std::memcpy(&q[d], p + xyz[d], 4);
      if (!q.allFinite() || q.isZero(0)) q.setConstant(std::numeric_limits<float>::quiet_NaN());
      out.points.push_back(q);
    }
  }
  return out;
}

absl::StatusOr<std::vector<RosTransform>> DecodeTfMessage(std::span<const uint8_t> data,
                                                          RosEncoding encoding) {
  constexpr char kWhat[] = "TFMessage";
  absl::StatusOr<Cursor> payload = Payload(kWhat, data, encoding);
  if (!payload.ok()) return payload.status();
  Cursor& c = *payload;
  uint32_t n = 0;
  if (!c.Read(n)) return Short(kWhat, "transform count");
  // Each transform takes at least 76 bytes (ROS 1 with empty frame names; CDR takes more):
  // bound the count before reserving.
  if (n > c.left() / 76) return Short(kWhat, "transforms");
  std::vector<RosTransform> out(n);
  for (uint32_t i = 0; i < n; ++i) {
    RosTransform& t = out[i];
    double q[4];
    if (!c.Header(t.header) || !c.String(t.child_frame_id) || !c.Read(t.translation.x()) ||
        !c.Read(t.translation.y()) || !c.Read(t.translation.z()) || !c.Read(q[0]) ||
        !c.Read(q[1]) || !c.Read(q[2]) || !c.Read(q[3])) {
      return Short(kWhat, "transforms");
    }
    const Eigen::Quaterniond r(q[3], q[0], q[1], q[2]);
    if (!t.translation.allFinite() || !r.coeffs().allFinite() || std::abs(r.norm() - 1) > 1e-3) {
      return absl::InvalidArgumentError(
          absl::StrCat(kWhat, ": transform ", i, " (", t.header.frame_id, " ➜ ", t.child_frame_id,
                       ") is not finite or its rotation is not a unit quaternion"));
    }
    t.rotation = r.normalized();
  }
  if (absl::Status st = CheckAllRead(kWhat, c); !st.ok()) return st;
  return out;
}

}  // namespace carvemap
