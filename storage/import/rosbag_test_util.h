// Test support for the ROS bag reader and import: bags and messages written byte by byte from
// the format's description (rosbag_reader.h), for the cases a well-behaved writer never makes
// (cut short, unknown compression, a message before its connection). The independent check
// is tests/tools/make_rosbag.py, which writes bags with ROS's own Python library.
#pragma once

#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <bzlib.h>

#include "storage/import/rosbag_reader.h"

namespace carvemap::testing {

using Bytes = std::vector<uint8_t>;

template <typename T>
void Put(Bytes& b, T v) {
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  b.insert(b.end(), p, p + sizeof(T));
}
inline void PutBytes(Bytes& b, const void* data, size_t n) {
  const auto* p = static_cast<const uint8_t*>(data);
  b.insert(b.end(), p, p + n);
}
inline void PutString(Bytes& b, const std::string& s) {
  Put<uint32_t>(b, static_cast<uint32_t>(s.size()));
  PutBytes(b, s.data(), s.size());
}
inline void PutHeader(Bytes& b, const RosHeader& h) {
  Put<uint32_t>(b, h.seq);
  const auto sec = static_cast<uint32_t>(h.stamp);
  Put<uint32_t>(b, sec);
  Put<uint32_t>(b, static_cast<uint32_t>(std::llround((h.stamp - sec) * 1e9)));
  PutString(b, h.frame_id);
}

// A record header field "name=value".
inline void Field(Bytes& b, const std::string& name, const Bytes& value) {
  Put<uint32_t>(b, static_cast<uint32_t>(name.size() + 1 + value.size()));
  PutBytes(b, name.data(), name.size());
  b.push_back('=');
  PutBytes(b, value.data(), value.size());
}
inline Bytes Str(const std::string& s) { return Bytes(s.begin(), s.end()); }
template <typename T>
Bytes Num(T v) {
  Bytes b;
  Put(b, v);
  return b;
}

class BagWriter {
 public:
  void Connection(uint32_t id, const std::string& topic, const std::string& type,
                  const std::string& md5) {
    Bytes h, d;
    Field(h, "op", Num<uint8_t>(0x07));
    Field(h, "conn", Num<uint32_t>(id));
    Field(h, "topic", Str(topic));
    Field(d, "topic", Str(topic));
    Field(d, "type", Str(type));
    Field(d, "md5sum", Str(md5));
    Field(d, "message_definition", Str(""));
    Record(h, d);
  }
  void Message(uint32_t conn, double t, const Bytes& data) {
    Bytes h;
    Field(h, "op", Num<uint8_t>(0x02));
    Field(h, "conn", Num<uint32_t>(conn));
    const auto sec = static_cast<uint32_t>(t);
    Bytes time = Num<uint32_t>(sec);
    Put<uint32_t>(time, static_cast<uint32_t>(std::llround((t - sec) * 1e9)));
    Field(h, "time", time);
    Record(h, data);
  }
  // Records until EndChunk go into a chunk.
  void BeginChunk() { in_chunk_ = true; }
  void EndChunk(const std::string& compression = "none") {
    in_chunk_ = false;
    Bytes data = chunk_;
    if (compression == "bz2") {
      data.resize(chunk_.size() * 2 + 1024);
      unsigned int n = static_cast<unsigned int>(data.size());
      BZ2_bzBuffToBuffCompress(reinterpret_cast<char*>(data.data()), &n,
                               reinterpret_cast<char*>(chunk_.data()),
                               static_cast<unsigned int>(chunk_.size()), 9, 0, 0);
      data.resize(n);
    }
    Bytes h;
    Field(h, "op", Num<uint8_t>(0x05));
    Field(h, "compression", Str(compression));
    Field(h, "size", Num<uint32_t>(static_cast<uint32_t>(chunk_.size())));
    chunk_.clear();
    Record(h, data);
  }
  // The whole file: magic, a bag header record padded as rosbag pads it, the records.
  [[nodiscard]] Bytes Serialized() const {
    Bytes out(kMagic, kMagic + 13);
    Bytes h;
    Field(h, "op", Num<uint8_t>(0x03));
    Field(h, "index_pos", Num<uint64_t>(0));
    Field(h, "conn_count", Num<uint32_t>(0));
    Field(h, "chunk_count", Num<uint32_t>(0));
    Put<uint32_t>(out, static_cast<uint32_t>(h.size()));
    out.insert(out.end(), h.begin(), h.end());
    const Bytes pad(4096 - h.size() - 8, ' ');
    Put<uint32_t>(out, static_cast<uint32_t>(pad.size()));
    out.insert(out.end(), pad.begin(), pad.end());
    out.insert(out.end(), file_.begin(), file_.end());
    return out;
  }
  void Write(const std::string& path, size_t keep = SIZE_MAX) const {
    const Bytes b = Serialized();
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(b.data()),
               static_cast<std::streamsize>(std::min(keep, b.size())));
  }

 private:
  static constexpr char kMagic[] = "#ROSBAG V2.0\n";
  void Record(const Bytes& header, const Bytes& data) {
    Bytes& to = in_chunk_ ? chunk_ : file_;
    Put<uint32_t>(to, static_cast<uint32_t>(header.size()));
    to.insert(to.end(), header.begin(), header.end());
    Put<uint32_t>(to, static_cast<uint32_t>(data.size()));
    to.insert(to.end(), data.begin(), data.end());
  }
  Bytes file_, chunk_;
  bool in_chunk_ = false;
};

inline Bytes SerializeLaserScan(const RosLaserScan& s) {
  Bytes b;
  PutHeader(b, s.header);
  for (float f : {s.angle_min, s.angle_max, s.angle_increment, s.time_increment, s.scan_time,
                  s.range_min, s.range_max}) {
    Put(b, f);
  }
  Put<uint32_t>(b, static_cast<uint32_t>(s.ranges.size()));
  PutBytes(b, s.ranges.data(), 4 * s.ranges.size());
  Put<uint32_t>(b, 0);  // no intensities
  return b;
}

inline Bytes SerializeTf(const std::vector<RosTransform>& ts) {
  Bytes b;
  Put<uint32_t>(b, static_cast<uint32_t>(ts.size()));
  for (const RosTransform& t : ts) {
    PutHeader(b, t.header);
    PutString(b, t.child_frame_id);
    for (double v : {t.translation.x(), t.translation.y(), t.translation.z(), t.rotation.x(),
                     t.rotation.y(), t.rotation.z(), t.rotation.w()}) {
      Put(b, v);
    }
  }
  return b;
}

// A cloud of 16-byte points (x, y, z at bytes 4, 8, 12 after a float "intensity" at 0).
inline Bytes SerializeCloud(const RosHeader& header, uint32_t height, uint32_t width,
                            const std::vector<Eigen::Vector3f>& pts, bool big_endian = false) {
  Bytes b;
  PutHeader(b, header);
  Put<uint32_t>(b, height);
  Put<uint32_t>(b, width);
  Put<uint32_t>(b, 4);
  const char* names[] = {"intensity", "x", "y", "z"};
  for (uint32_t i = 0; i < 4; ++i) {
    PutString(b, names[i]);
    Put<uint32_t>(b, 4 * i);
    Put<uint8_t>(b, 7);
    Put<uint32_t>(b, 1);
  }
  Put<uint8_t>(b, big_endian ? 1 : 0);
  Put<uint32_t>(b, 16);
  Put<uint32_t>(b, 16 * width);
  Put<uint32_t>(b, static_cast<uint32_t>(16 * pts.size()));
  for (const Eigen::Vector3f& p : pts) {
    Put<float>(b, 1.f);
    for (int d = 0; d < 3; ++d) Put<float>(b, p[d]);
  }
  Put<uint8_t>(b, 0);
  return b;
}

}  // namespace carvemap::testing
