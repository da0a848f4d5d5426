#include "services/merge/face_store.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

constexpr size_t kRecordBytes = 48;
// A bucket's records are appended to its file once this many bytes wait: memory for the
// buckets stays at ~1 MiB each whatever the building.
constexpr size_t kFlushBytes = size_t{1} << 20;

void Encode(const BoundaryFace& f, char* out) {
  std::memcpy(out, f.center.data(), 24);
  std::memcpy(out + 24, &f.size_m, 8);
  std::memcpy(out + 32, &f.isosurface_m, 8);
  std::memcpy(out + 40, &f.exterior_weight, 4);
  out[44] = static_cast<char>(f.axis);
  out[45] = static_cast<char>(f.sign);
  out[46] = f.exterior_observed ? 1 : 0;
  out[47] = 0;
}

BoundaryFace Decode(const char* in) {
  BoundaryFace f;
  std::memcpy(f.center.data(), in, 24);
  std::memcpy(&f.size_m, in + 24, 8);
  std::memcpy(&f.isosurface_m, in + 32, 8);
  std::memcpy(&f.exterior_weight, in + 40, 4);
  f.axis = static_cast<int8_t>(in[44]);
  f.sign = static_cast<int8_t>(in[45]);
  f.exterior_observed = in[46] != 0;
  return f;
}

// Reads `count` records from `path` at record `first`.
absl::StatusOr<std::vector<BoundaryFace>> ReadRecords(const std::string& path, uint64_t first,
                                                      uint64_t count) {
  std::vector<BoundaryFace> out;
  if (count == 0) return out;
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::DataLossError(absl::StrCat(path, ": cannot open the faces' scratch file"));
  in.seekg(static_cast<std::streamoff>(first * kRecordBytes));
  out.reserve(count);
  std::vector<char> buf(std::min<uint64_t>(count, 1 << 16) * kRecordBytes);
  for (uint64_t done = 0; done < count;) {
    const uint64_t n = std::min<uint64_t>(count - done, buf.size() / kRecordBytes);
    in.read(buf.data(), static_cast<std::streamsize>(n * kRecordBytes));
    if (!in) {
      return absl::DataLossError(absl::StrCat(path, ": the faces' scratch file ends before face ",
                                              first + done + n, " (truncated?)"));
    }
    for (uint64_t i = 0; i < n; ++i) out.push_back(Decode(buf.data() + i * kRecordBytes));
    done += n;
  }
  return out;
}

}  // namespace

FaceStore::FaceStore(std::string path, const OctreeGrid& grid)
    : path_(std::move(path)),
      xy_min_(Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity())),
      xy_max_(-xy_min_) {
  heights_.half_cell_m = grid.resolution_m() / 2;
}

absl::StatusOr<std::unique_ptr<FaceStore>> FaceStore::Create(std::string path,
                                                             const OctreeGrid& grid) {
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) {
      return absl::UnavailableError(
          absl::StrCat(path, ": cannot create the faces' scratch file: ", std::strerror(errno)));
    }
  }
  return std::unique_ptr<FaceStore>(new FaceStore(std::move(path), grid));
}

FaceStore::~FaceStore() {
  std::error_code ec;
  for (const auto& [k, bucket] : buckets_) std::filesystem::remove(bucket.path, ec);
  std::filesystem::remove(path_, ec);
}

absl::Status FaceStore::Add(std::span<const BoundaryFace> faces) {
  if (finished_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already sorted"));
  // A chunk's faces lie within a few buckets: the last one found is looked up first.
  int64_t last_key = 0;
  Bucket* last = nullptr;
  for (const BoundaryFace& f : faces) {
    if (!f.center.allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": a boundary face's centre is not finite"));
    }
    const int64_t k = static_cast<int64_t>(std::floor(f.center.z() / kFaceBucketM));
    if (last == nullptr || k != last_key) {
      auto [it, added] = buckets_.try_emplace(k);
      if (added) it->second.path = absl::StrCat(path_, ".", k);
      last_key = k;
      last = &it->second;
    }
    Bucket& bucket = *last;
    const size_t at = bucket.pending.size();
    bucket.pending.resize(at + kRecordBytes);
    Encode(f, bucket.pending.data() + at);
    if (bucket.pending.size() >= kFlushBytes) {
      if (absl::Status s = Flush(bucket); !s.ok()) return s;
    }
    max_size_m_ = std::max(max_size_m_, f.size_m);
    area_m2_ += f.area_m2();
    xy_min_ = xy_min_.cwiseMin(f.center.head<2>() - Eigen::Vector2d::Constant(f.size_m / 2));
    xy_max_ = xy_max_.cwiseMax(f.center.head<2>() + Eigen::Vector2d::Constant(f.size_m / 2));
  }
  return absl::OkStatus();
}

absl::Status FaceStore::Flush(Bucket& bucket) {
  if (bucket.pending.empty()) return absl::OkStatus();
  std::ofstream out(bucket.path, std::ios::binary | std::ios::app);
  errno = 0;
  out.write(bucket.pending.data(), static_cast<std::streamsize>(bucket.pending.size()));
  out.close();
  if (!out) return StreamWriteError(bucket.path, errno);
  bucket.on_disk += bucket.pending.size() / kRecordBytes;
  bucket.pending.clear();
  return absl::OkStatus();
}

absl::Status FaceStore::Finish() {
  if (finished_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already sorted"));
  finished_ = true;
  std::ofstream out(path_, std::ios::binary | std::ios::trunc);
  std::vector<char> buf;
  for (auto& [k, bucket] : buckets_) {
    absl::StatusOr<std::vector<BoundaryFace>> faces = ReadRecords(bucket.path, 0, bucket.on_disk);
    if (!faces.ok()) return faces.status();
    for (size_t at = 0; at < bucket.pending.size(); at += kRecordBytes) {
      faces->push_back(Decode(bucket.pending.data() + at));
    }
    bucket.pending = {};
    std::error_code ec;
    std::filesystem::remove(bucket.path, ec);
    if (absl::Status s = SortFacesByHeight(*faces); !s.ok()) return s;
    buf.resize(faces->size() * kRecordBytes);
    for (size_t i = 0; i < faces->size(); ++i) {
      Encode((*faces)[i], buf.data() + i * kRecordBytes);
      if (absl::Status s = heights_.Append((*faces)[i].center.z()); !s.ok()) {
        return absl::InternalError(absl::StrCat(path_, ": ", s.message()));
      }
    }
    errno = 0;
    out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    if (!out) return StreamWriteError(path_, errno);
  }
  errno = 0;
  out.close();
  if (!out) return StreamWriteError(path_, errno);
  buckets_.clear();
  return absl::OkStatus();
}

absl::StatusOr<std::vector<BoundaryFace>> FaceStore::Read(uint64_t begin, uint64_t end) const {
  if (!finished_ || begin > end || end > size()) {
    return absl::OutOfRangeError(absl::StrCat(path_, ": faces [", begin, ", ", end, ") of ",
                                              finished_ ? size() : 0, " sorted"));
  }
  return ReadRecords(path_, begin, end - begin);
}

ReadFacesFn FaceStore::Reader() const {
  return [this](uint64_t begin, uint64_t end) { return Read(begin, end); };
}

}  // namespace carvemap
