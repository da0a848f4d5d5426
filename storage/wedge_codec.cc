#include "storage/wedge_codec.h"

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// The 18 floats of a ray in record order.
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

RayModel RayFromFloats(const std::array<float, 18>& f) {
  RayModel r;
  r.sensor_mean = Eigen::Vector3f(f[0], f[1], f[2]);
  r.point_mean = Eigen::Vector3f(f[3], f[4], f[5]);
  for (int i = 0; i < 6; ++i) {
    r.sensor_cov[i] = f[6 + i];
    r.point_cov[i] = f[12 + i];
  }
  return r;
}

RayModel ZeroRay() { return RayFromFloats({}); }

// Explicit byte order, so files written on any host read the same everywhere.
void PutFloat(float v, std::string& out) {
  const uint32_t u = std::bit_cast<uint32_t>(v);
  const char b[4] = {char(u), char(u >> 8), char(u >> 16), char(u >> 24)};
  out.append(b, 4);
}

float GetFloat(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return std::bit_cast<float>(uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 |
                              uint32_t(b[3]) << 24);
}

const char* FieldName(int i) {
  static constexpr const char* kNames[] = {"sensor_mean", "point_mean", "sensor_cov",
                                           "point_cov"};
  return i < 6 ? kNames[i / 3] : kNames[2 + (i - 6) / 6];
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

void AppendWedgeRecord(const Wedge& wedge, std::string& out) {
  out.push_back(char(wedge.num_rays));
  for (int r = 0; r < wedge.num_rays && r < 4; ++r) {
    for (float v : RayFloats(wedge.rays[r])) PutFloat(v, out);
  }
}

std::string EncodeWedges(std::span<const Wedge> wedges) {
  size_t bytes = 0;
  for (const Wedge& w : wedges) bytes += WedgeRecordBytes(w.num_rays);
  std::string out;
  out.reserve(bytes);
  for (const Wedge& w : wedges) AppendWedgeRecord(w, out);
  return out;
}

absl::StatusOr<std::vector<Wedge>> DecodeWedges(std::string_view bytes) {
  std::vector<Wedge> out;
  size_t pos = 0;
  while (pos < bytes.size()) {
    const size_t index = out.size();
    const int num_rays = static_cast<unsigned char>(bytes[pos]);
    if (num_rays < 1 || num_rays > 4) {
      return absl::DataLossError(absl::StrCat("wedge record ", index, " at byte ", pos,
                                              ": num_rays ", num_rays, ", want 1 to 4"));
    }
    if (bytes.size() - pos < WedgeRecordBytes(num_rays)) {
      return absl::DataLossError(absl::StrCat(
          "wedge record ", index, " at byte ", pos, " is truncated: ", bytes.size() - pos,
          " bytes left of ", WedgeRecordBytes(num_rays), " (", bytes.size(), " bytes in all)"));
    }
    Wedge w;
    w.num_rays = uint8_t(num_rays);
    const char* p = bytes.data() + pos + 1;
    for (int r = 0; r < 4; ++r) {
      if (r >= num_rays) {
        w.rays[r] = ZeroRay();
        continue;
      }
      std::array<float, 18> f;
      for (int i = 0; i < 18; ++i, p += 4) {
        f[i] = GetFloat(p);
        if (!std::isfinite(f[i])) {
          return absl::DataLossError(absl::StrCat("wedge record ", index, " at byte ", pos,
                                                  ": ray ", r, " has a non-finite ",
                                                  FieldName(i)));
        }
      }
      w.rays[r] = RayFromFloats(f);
    }
    out.push_back(w);
    pos += WedgeRecordBytes(num_rays);
  }
  return out;
}

}  // namespace carvemap
