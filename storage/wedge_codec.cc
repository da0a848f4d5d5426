#include "storage/wedge_codec.h"

#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace carvemap {
namespace {

constexpr char kFrameTag = 0x01;
constexpr char kRayTag = 0x02;
constexpr uint8_t kWedgeTag = 0x10;  // + num_rays (1 to 4)
constexpr char kEndTag = 0x7f;
constexpr size_t kHeaderBytes = 2;

// Explicit byte order, so files written on any host read the same everywhere.
void PutFloat(float v, std::string& out) {
  const uint32_t u = std::bit_cast<uint32_t>(v);
  const char b[4] = {char(u), char(u >> 8), char(u >> 16), char(u >> 24)};
  out.append(b, 4);
}
void PutFloats(const float* v, int n, std::string& out) {
  for (int i = 0; i < n; ++i) PutFloat(v[i], out);
}

float GetFloat(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return std::bit_cast<float>(uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 |
                              uint32_t(b[3]) << 24);
}

// Unsigned LEB128: 7 bits per byte, low first; ray back-references are mostly below 128.
void PutVarint(uint64_t v, std::string& out) {
  while (v >= 0x80) {
    out.push_back(char(v | 0x80));
    v >>= 7;
  }
  out.push_back(char(v));
}

const char* FieldName(int i) {
  static constexpr const char* kNames[] = {"sensor_mean", "point_mean", "sensor_cov",
                                           "point_cov"};
  return i < 6 ? kNames[i / 3] : kNames[2 + (i - 6) / 6];
}

// The 18 floats of a ray in the order above (means, then covariances).
std::array<float, 18> RayFloats(const RayModel& r) {
  std::array<float, 18> f;
  for (int i = 0; i < 3; ++i) {
    f[i] = r.sensor_mean[i];
    f[3 + i] = r.point_mean[i];
  }
  for (int i = 0; i < 6; ++i) {
    f[6 + i] = r.sensor_cov[i];
    f[12 + i] = r.point_cov[i];
  }
  return f;
}

// Walks a payload; with `out` set, also decodes it (and checks every float).
absl::StatusOr<uint64_t> Walk(std::string_view bytes, IndexedWedges* out) {
  if (bytes.empty()) return 0;
  auto bad = [](size_t record, size_t pos, auto&&... what) {
    return absl::DataLossError(
        absl::StrCat("wedge payload record ", record, " at byte ", pos, ": ", what...));
  };
  const auto first = static_cast<unsigned char>(bytes[0]);
  if (first >= 1 && first <= 4) {
    return absl::DataLossError(
        "wedge payload of version 1 (289-byte wedge records, no header); this build reads "
        "version 2: ingest the scan again");
  }
  if (bytes.size() < kHeaderBytes || first != kWedgePayloadMagic) {
    return absl::DataLossError(
        absl::StrFormat("not a wedge payload (first byte 0x%02x, want 0x%02x)", first,
                        kWedgePayloadMagic));
  }
  if (const auto v = static_cast<unsigned char>(bytes[1]); v != kWedgePayloadVersion) {
    return absl::DataLossError(absl::StrCat("wedge payload version ", int(v),
                                            "; this build reads version ",
                                            int(kWedgePayloadVersion)));
  }
  struct Frame {
    Eigen::Vector3f mean;
    SymCov3f cov;
  };
  std::vector<Frame> frames;
  uint64_t num_frames = 0, num_rays = 0, num_wedges = 0;
  size_t record = 0;
  bool ended = false;
  for (size_t pos = kHeaderBytes; pos < bytes.size(); ++record) {
    if (ended) return bad(record, pos, "bytes after the end record");
    const char tag = bytes[pos];
    const size_t left = bytes.size() - pos;
    auto floats = [&](size_t at, int n, int first_field, float* dst) -> absl::Status {
      for (int i = 0; i < n; ++i) {
        dst[i] = GetFloat(bytes.data() + at + 4 * i);
        if (!std::isfinite(dst[i])) {
          return bad(record, pos, "non-finite ", FieldName(first_field + i));
        }
      }
      return absl::OkStatus();
    };
    if (tag == kFrameTag) {
      if (left < kFrameRecordBytes) return bad(record, pos, "frame record is truncated");
      if (out != nullptr) {
        std::array<float, 9> f;
        if (absl::Status s = floats(pos + 1, 3, 0, f.data()); !s.ok()) return s;
        if (absl::Status s = floats(pos + 13, 6, 6, f.data() + 3); !s.ok()) return s;
        Frame fr;
        fr.mean = Eigen::Vector3f(f[0], f[1], f[2]);
        std::copy(f.begin() + 3, f.end(), fr.cov.begin());
        frames.push_back(fr);
      }
      ++num_frames;
      pos += kFrameRecordBytes;
    } else if (tag == kRayTag) {
      if (left < kRayRecordBytes) return bad(record, pos, "ray record is truncated");
      const auto back = static_cast<unsigned char>(bytes[pos + 1]);
      if (back >= num_frames) {
        return bad(record, pos, "ray of frame ", back, " records back, but only ", num_frames,
                   " frames precede it");
      }
      if (out != nullptr) {
        std::array<float, 9> f;
        if (absl::Status s = floats(pos + 2, 3, 3, f.data()); !s.ok()) return s;
        if (absl::Status s = floats(pos + 14, 6, 12, f.data() + 3); !s.ok()) return s;
        const Frame& fr = frames[frames.size() - 1 - back];
        RayModel ray;
        ray.sensor_mean = fr.mean;
        ray.sensor_cov = fr.cov;
        ray.point_mean = Eigen::Vector3f(f[0], f[1], f[2]);
        std::copy(f.begin() + 3, f.end(), ray.point_cov.begin());
        out->rays.push_back(ray);
      }
      ++num_rays;
      pos += kRayRecordBytes;
    } else if (const auto t = static_cast<unsigned char>(tag);
               t > kWedgeTag && t <= kWedgeTag + 4) {
      WedgeRef w;
      w.num_rays = uint8_t(t - kWedgeTag);
      size_t p = pos + 1;
      for (int r = 0; r < w.num_rays; ++r) {
        uint64_t back = 0;
        for (int shift = 0;; shift += 7) {
          if (p >= bytes.size()) return bad(record, pos, "wedge record is truncated");
          if (shift > 28) return bad(record, pos, "ray reference longer than 5 bytes");
          const auto b = static_cast<unsigned char>(bytes[p++]);
          back |= uint64_t(b & 0x7f) << shift;
          if (!(b & 0x80)) break;
        }
        if (back >= num_rays) {
          return bad(record, pos, "ray ", r, " refers ", back, " rays back, but only ",
                     num_rays, " rays precede it");
        }
        w.ray[r] = uint32_t(num_rays - 1 - back);
      }
      if (w.num_rays > 1) {
        for (int shift = 0;; shift += 7) {
          if (p >= bytes.size()) return bad(record, pos, "wedge record is truncated");
          if (shift > 63) return bad(record, pos, "hull hint longer than 10 bytes");
          const auto b = static_cast<unsigned char>(bytes[p++]);
          w.facets |= uint64_t(b & 0x7f) << shift;
          if (!(b & 0x80)) break;
        }
      }
      if (out != nullptr) out->wedges.push_back(w);
      ++num_wedges;
      pos = p;
    } else if (tag == kEndTag) {
      uint64_t count = 0;
      size_t p = pos + 1;
      for (int shift = 0;; shift += 7) {
        if (p >= bytes.size()) return bad(record, pos, "end record is truncated");
        if (shift > 63) return bad(record, pos, "wedge count longer than 10 bytes");
        const auto b = static_cast<unsigned char>(bytes[p++]);
        count |= uint64_t(b & 0x7f) << shift;
        if (!(b & 0x80)) break;
      }
      if (count != num_wedges) {
        return bad(record, pos, "end record counts ", count, " wedges, the payload holds ",
                   num_wedges);
      }
      ended = true;
      pos = p;
    } else {
      return bad(record, pos,
                 absl::StrFormat("unknown record tag 0x%02x", static_cast<unsigned char>(tag)));
    }
  }
  if (!ended) {
    return absl::DataLossError(absl::StrCat("wedge payload of ", bytes.size(),
                                            " bytes has no end record (truncated)"));
  }
  return num_wedges;
}

}  // namespace

absl::Status ValidateWedge(const Wedge& wedge) {
  if (wedge.num_rays < 1 || wedge.num_rays > 4) {
    return absl::InvalidArgumentError(
        absl::StrCat("wedge has num_rays ", int(wedge.num_rays), ", want 1 to 4"));
  }
  for (int r = 0; r < wedge.num_rays; ++r) {
    const std::array<float, 18> f = RayFloats(wedge.rays[r]);
    for (int i = 0; i < 18; ++i) {
      if (!std::isfinite(f[i])) {
        return absl::InvalidArgumentError(
            absl::StrCat("wedge ray ", r, " has a non-finite ", FieldName(i)));
      }
    }
  }
  return absl::OkStatus();
}

WedgePayloadWriter::FrameState& WedgePayloadWriter::Frame(const RayId& id, const RayModel& ray,
                                                          std::string& out) {
  SensorState& sensor = sensors_[id.sensor];
  FrameState* f = nullptr;
  for (FrameState& k : sensor.frames) {
    if (k.local >= 0 && k.frame == id.frame) f = &k;
  }
  if (f == nullptr) {
    FrameState& a = sensor.frames[0];
    FrameState& b = sensor.frames[1];
    FrameState* slot = a.local < 0 ? &a : b.local < 0 ? &b : a.frame < b.frame ? &a : &b;
    if (slot->local >= 0 && slot->frame > id.frame) {
      slot = &stale_;  // older than both frames kept: written again, not kept
    }
    *slot = FrameState{};
    slot->frame = id.frame;
    f = slot;
  }
  // The ray record names its frame by a one-byte back-reference.
  if (f->local < 0 || frames_ - 1 - f->local > 255) {
    out.push_back(kFrameTag);
    PutFloats(ray.sensor_mean.data(), 3, out);
    PutFloats(ray.sensor_cov.data(), 6, out);
    f->local = frames_++;
  }
  return *f;
}

void WedgePayloadWriter::Add(const Wedge& wedge, std::span<const RayId> ids, std::string& out,
                             uint64_t facets) {
  if (frames_ == 0 && rays_ == 0 && wedges_ == 0) {
    out.push_back(char(kWedgePayloadMagic));
    out.push_back(char(kWedgePayloadVersion));
  }
  std::array<uint32_t, 4> refs{};
  for (int r = 0; r < wedge.num_rays; ++r) {
    const RayModel& ray = wedge.rays[r];
    FrameState& f = Frame(ids[r], ray, out);
    if (auto it = f.rays.find(ids[r].index); it != f.rays.end()) {
      refs[r] = it->second;
      continue;
    }
    out.push_back(kRayTag);
    out.push_back(char(frames_ - 1 - f.local));
    PutFloats(ray.point_mean.data(), 3, out);
    PutFloats(ray.point_cov.data(), 6, out);
    refs[r] = rays_++;
    f.rays.emplace(ids[r].index, refs[r]);
  }
  out.push_back(char(kWedgeTag + wedge.num_rays));
  for (int r = 0; r < wedge.num_rays; ++r) PutVarint(rays_ - 1 - refs[r], out);
  if (wedge.num_rays > 1) PutVarint(facets, out);
  ++wedges_;
}

void WedgePayloadWriter::Finish(std::string& out) const {
  if (frames_ == 0 && rays_ == 0 && wedges_ == 0) return;
  out.push_back(kEndTag);
  PutVarint(wedges_, out);
}

std::string EncodeWedges(std::span<const Wedge> wedges) {
  // Ids by bit identity: a sensor per distinct sensor Gaussian, all in its frame 0.
  absl::flat_hash_map<std::string, uint32_t> sensors, rays;
  WedgePayloadWriter writer;
  std::string out;
  for (const Wedge& w : wedges) {
    std::array<RayId, 4> ids;
    for (int r = 0; r < w.num_rays; ++r) {
      const std::array<float, 18> f = RayFloats(w.rays[r]);
      std::string sensor(12 + 24, '\0');
      std::memcpy(sensor.data(), f.data(), 12);
      std::memcpy(sensor.data() + 12, f.data() + 6, 24);
      ids[r].sensor = sensors.try_emplace(sensor, uint32_t(sensors.size())).first->second;
      ids[r].index = rays.try_emplace(std::string(reinterpret_cast<const char*>(f.data()), 72),
                                      uint32_t(rays.size()))
                         .first->second;
    }
    writer.Add(w, std::span(ids.data(), w.num_rays), out);
  }
  writer.Finish(out);
  return out;
}

absl::StatusOr<IndexedWedges> DecodeWedgePayload(std::string_view bytes) {
  IndexedWedges out;
  absl::StatusOr<uint64_t> n = Walk(bytes, &out);
  if (!n.ok()) return n.status();
  return out;
}

absl::StatusOr<uint64_t> CountWedgeRecords(std::string_view bytes) {
  return Walk(bytes, nullptr);
}

absl::StatusOr<std::vector<Wedge>> DecodeWedges(std::string_view bytes) {
  absl::StatusOr<IndexedWedges> indexed = DecodeWedgePayload(bytes);
  if (!indexed.ok()) return indexed.status();
  const RayModel zero{Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero(), {}, {}};
  std::vector<Wedge> out;
  out.reserve(indexed->wedges.size());
  for (const WedgeRef& ref : indexed->wedges) {
    Wedge w;
    w.num_rays = ref.num_rays;
    for (int r = 0; r < 4; ++r) w.rays[r] = r < ref.num_rays ? indexed->rays[ref.ray[r]] : zero;
    out.push_back(w);
  }
  return out;
}

}  // namespace carvemap
