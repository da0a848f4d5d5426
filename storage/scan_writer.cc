#include "storage/scan_writer.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"
#include "storage/h5_util.h"

namespace carvemap {
namespace {

using h5::Hid;

// Rows are buffered per dataset up to this size, then written as one hyperslab: few HDF5 calls
// for many small appends, and memory bounded whatever the scan's length.
constexpr size_t kBufferBytes = 1 << 20;
// Chunk sizes in rows: ~100-200 KiB chunks, good for both streaming and random reads.
constexpr hsize_t kPathChunkRows = 2048;
constexpr hsize_t kFrameChunkRows = 4096;
constexpr hsize_t kPointChunkRows = 16384;

static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "points are written as float[3]");
static_assert(sizeof(PathCovariance) == 12 * sizeof(float), "path_cov rows are float[12]");

// Buffered appends to one extendible dataset of rows of T.
template <typename T>
class RowAppender {
 public:
  RowAppender() = default;
  RowAppender(Hid dataset, hid_t mem_type, hsize_t cols)
      : dataset_(std::move(dataset)), mem_type_(mem_type), cols_(cols) {}

  [[nodiscard]] bool valid() const { return dataset_.valid(); }
  [[nodiscard]] uint64_t rows() const { return written_ + buffer_.size(); }

  absl::Status Append(std::span<const T> rows) {
    if ((buffer_.size() + rows.size()) * sizeof(T) <= kBufferBytes) {
      buffer_.insert(buffer_.end(), rows.begin(), rows.end());
      return absl::OkStatus();
    }
    // Too big to buffer: write what is buffered, then these rows directly.
    if (absl::Status s = Flush(); !s.ok()) return s;
    if (rows.size() * sizeof(T) <= kBufferBytes) {
      buffer_.assign(rows.begin(), rows.end());
      return absl::OkStatus();
    }
    absl::Status s =
        h5::WriteRows(dataset_.get(), mem_type_, cols_, written_, rows.size(), rows.data());
    written_ += rows.size();
    return s;
  }

  absl::Status Flush() {
    absl::Status s =
        h5::WriteRows(dataset_.get(), mem_type_, cols_, written_, buffer_.size(), buffer_.data());
    written_ += buffer_.size();
    buffer_.clear();
    return s;
  }

  void Close() { dataset_.Reset(); }

 private:
  Hid dataset_;
  hid_t mem_type_ = H5I_INVALID_HID;  // owned by the writer's Impl
  hsize_t cols_ = 0;
  uint64_t written_ = 0;
  std::vector<T> buffer_;
};

struct SensorState {
  SensorInfo info;
  Hid group;
  RowAppender<FrameRecord> frames;
  RowAppender<Eigen::Vector3f> points;
  double last_t = -std::numeric_limits<double>::infinity();
};

absl::Status ValidateSensorName(const std::string& name) {
  // An HDF5 link name: no '/', not "." (the group itself), not empty.
  if (name.empty() || name == "." || name.find('/') != std::string::npos ||
      name.find('\0') != std::string::npos) {
    return absl::InvalidArgumentError(
        absl::StrCat("sensor name '", name, "' is not a valid HDF5 name"));
  }
  return absl::OkStatus();
}

absl::Status ValidateSensorInfo(const SensorInfo& info) {
  if (absl::Status s = ValidateSensorName(info.name); !s.ok()) return s;
  if (info.kind == SensorKind::kGrid && (info.rows == 0 || info.cols == 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("sensor '", info.name, "': a grid sensor needs rows and cols > 0"));
  }
  if (const std::string problem = SensorParametersProblem(info); !problem.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("sensor '", info.name, "': ", problem));
  }
  return absl::OkStatus();
}

absl::Status WriteSensorAttrs(hid_t group, const SensorInfo& info) {
  std::array<double, 9> r;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) r[3 * i + j] = info.R_s2c(i, j);  // row-major, docs/DESIGN.md §3
  }
  const std::array<double, 3> t = {info.T_s2c.x(), info.T_s2c.y(), info.T_s2c.z()};
  absl::Status s = h5::WriteStringAttr(group, "kind", std::string(SensorKindName(info.kind)));
  if (s.ok() && info.kind == SensorKind::kGrid) s = h5::WriteIntAttr(group, "rows", info.rows);
  if (s.ok() && info.kind == SensorKind::kGrid) s = h5::WriteIntAttr(group, "cols", info.cols);
  if (s.ok()) s = h5::WriteDoublesAttr(group, "R_s2c", r);
  if (s.ok()) s = h5::WriteDoublesAttr(group, "T_s2c", t);
  if (s.ok()) s = h5::WriteDoubleAttr(group, "sigma_t", info.sigma_t_s);
  if (s.ok()) s = h5::WriteDoublesAttr(group, "range_sigma", info.range_sigma);
  if (s.ok()) s = h5::WriteDoubleAttr(group, "max_range", info.max_range_m);
  return s;
}

}  // namespace

struct ScanWriter::Impl {
  std::string path;
  std::string partial;
  Hid file;
  Hid sensors_group;
  Hid path_mem = h5::PathMemType();
  Hid frame_mem = h5::FrameMemType();
  Hid mag_mem = h5::MagnetometerMemType();
  RowAppender<PathRecord> poses;
  RowAppender<PathCovariance> cov;
  RowAppender<MagnetometerRecord> mag;
  std::vector<std::unique_ptr<SensorState>> sensors;
  std::set<std::string> names;
  std::optional<bool> has_cov;  // decided by the first non-empty AppendPath
  double last_pose_t = -std::numeric_limits<double>::infinity();
  bool closed = false;

  absl::Status Err(const absl::Status& s) const { return h5::Prefixed(partial, s); }
  absl::Status CheckOpen() const {
    if (closed) return absl::FailedPreconditionError(absl::StrCat(path, ": writer is closed"));
    return absl::OkStatus();
  }
  absl::Status FlushAll();
  void CloseHandles();
};

absl::Status ScanWriter::Impl::FlushAll() {
  absl::Status s = poses.Flush();
  if (s.ok() && cov.valid()) s = cov.Flush();
  if (s.ok() && mag.valid()) s = mag.Flush();
  for (auto& sensor : sensors) {
    if (s.ok()) s = sensor->frames.Flush();
    if (s.ok()) s = sensor->points.Flush();
  }
  return s;
}

void ScanWriter::Impl::CloseHandles() {
  for (auto& sensor : sensors) {
    sensor->frames.Close();
    sensor->points.Close();
    sensor->group.Reset();
  }
  poses.Close();
  cov.Close();
  mag.Close();
  sensors_group.Reset();
}

ScanWriter::ScanWriter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

ScanWriter::~ScanWriter() {
  if (impl_ == nullptr || impl_->closed) return;
  impl_->CloseHandles();
  impl_->file.Reset();
  std::error_code ignored;
  std::filesystem::remove(impl_->partial, ignored);
}

absl::StatusOr<std::unique_ptr<ScanWriter>> ScanWriter::Create(const std::string& path) {
  h5::Init();
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->partial = path + ".partial";
  Hid fcpl(H5Pcreate(H5P_FILE_CREATE));
  H5Pset_obj_track_times(fcpl.get(), 0);  // the root group too: no time stamps anywhere
  auto file = h5::CheckId(H5Fcreate(impl->partial.c_str(), H5F_ACC_TRUNC, fcpl.get(), H5P_DEFAULT),
                          absl::StrCat(impl->partial, ": cannot create file"));
  if (!file.ok()) return absl::Status(absl::StatusCode::kInvalidArgument, file.status().message());
  impl->file = *std::move(file);
  auto writer = std::unique_ptr<ScanWriter>(new ScanWriter(std::move(impl)));
  Impl& w = *writer->impl_;
  const hid_t root = w.file.get();
  absl::Status s = h5::WriteStringAttr(root, "format", std::string(kScanFormatName));
  if (s.ok()) s = h5::WriteIntAttr(root, "version", kScanFormatVersion);
  if (!s.ok()) return w.Err(s);
  auto poses = h5::CreateRows(root, "path", h5::PathFileType().get(), 0, kPathChunkRows);
  if (!poses.ok()) return w.Err(poses.status());
  w.poses = RowAppender<PathRecord>(*std::move(poses), w.path_mem.get(), 0);
  Hid gcpl = h5::GroupCreatePlist(/*track_link_order=*/true);
  auto group = h5::CheckId(H5Gcreate2(root, "sensors", H5P_DEFAULT, gcpl.get(), H5P_DEFAULT),
                           "cannot create /sensors");
  if (!group.ok()) return w.Err(group.status());
  w.sensors_group = *std::move(group);
  return writer;
}

absl::Status ScanWriter::AppendPath(std::span<const PathRecord> poses,
                                    std::span<const PathCovariance> cov) {
  Impl& w = *impl_;
  if (absl::Status s = w.CheckOpen(); !s.ok()) return s;
  if (poses.empty() && cov.empty()) return absl::OkStatus();
  if (!cov.empty() && cov.size() != poses.size()) {
    return absl::InvalidArgumentError(absl::StrCat(w.path, ": /path_cov: ", cov.size(),
                                                   " covariances for ", poses.size(), " poses"));
  }
  if (w.has_cov.has_value() && *w.has_cov != !cov.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(w.path, ": /path_cov: every pose or none must have a covariance (row ",
                     w.poses.rows(), ")"));
  }
  for (size_t i = 0; i < poses.size(); ++i) {
    if (!(poses[i].t > w.last_pose_t)) {  // also rejects NaN
      return absl::InvalidArgumentError(
          absl::StrCat(w.path, ": /path row ", w.poses.rows() + i, ": time ", poses[i].t,
                       " is not after the previous pose's ", w.last_pose_t));
    }
    w.last_pose_t = poses[i].t;
  }
  if (!cov.empty() && !w.cov.valid()) {
    auto dataset = h5::CreateRows(w.file.get(), "path_cov", H5T_IEEE_F32LE, 12, kPathChunkRows);
    if (!dataset.ok()) return w.Err(dataset.status());
    w.cov = RowAppender<PathCovariance>(*std::move(dataset), H5T_NATIVE_FLOAT, 12);
  }
  w.has_cov = !cov.empty();
  absl::Status s = w.poses.Append(poses);
  if (s.ok() && !cov.empty()) s = w.cov.Append(cov);
  return w.Err(s);
}

absl::StatusOr<int> ScanWriter::AddSensor(const SensorInfo& info) {
  Impl& w = *impl_;
  if (absl::Status s = w.CheckOpen(); !s.ok()) return s;
  if (absl::Status s = ValidateSensorInfo(info); !s.ok()) return h5::Prefixed(w.path, s);
  if (w.names.count(info.name) > 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(w.path, ": sensor '", info.name, "' was already added"));
  }
  auto state = std::make_unique<SensorState>();
  state->info = info;
  Hid gcpl = h5::GroupCreatePlist(/*track_link_order=*/false);
  auto group = h5::CheckId(
      H5Gcreate2(w.sensors_group.get(), info.name.c_str(), H5P_DEFAULT, gcpl.get(), H5P_DEFAULT),
      absl::StrCat("cannot create /sensors/", info.name));
  if (!group.ok()) return w.Err(group.status());
  state->group = *std::move(group);
  if (absl::Status s = WriteSensorAttrs(state->group.get(), info); !s.ok()) {
    return w.Err(h5::Prefixed(absl::StrCat("/sensors/", info.name), s));
  }
  auto frames =
      h5::CreateRows(state->group.get(), "frames", h5::FrameFileType().get(), 0, kFrameChunkRows);
  if (!frames.ok()) return w.Err(frames.status());
  auto points = h5::CreateRows(state->group.get(), "points", H5T_IEEE_F32LE, 3, kPointChunkRows);
  if (!points.ok()) return w.Err(points.status());
  state->frames = RowAppender<FrameRecord>(*std::move(frames), w.frame_mem.get(), 0);
  state->points = RowAppender<Eigen::Vector3f>(*std::move(points), H5T_NATIVE_FLOAT, 3);
  w.names.insert(info.name);
  w.sensors.push_back(std::move(state));
  return static_cast<int>(w.sensors.size()) - 1;
}

absl::Status ScanWriter::AppendFrame(int sensor, double t,
                                     std::span<const Eigen::Vector3f> points_sensor) {
  Impl& w = *impl_;
  if (absl::Status s = w.CheckOpen(); !s.ok()) return s;
  if (sensor < 0 || sensor >= static_cast<int>(w.sensors.size())) {
    return absl::InvalidArgumentError(absl::StrCat(w.path, ": unknown sensor index ", sensor));
  }
  SensorState& state = *w.sensors[sensor];
  const std::string dataset =
      absl::StrCat(w.path, ": /sensors/", state.info.name, "/frames row ", state.frames.rows());
  const SensorInfo& info = state.info;
  if (info.kind == SensorKind::kGrid &&
      points_sensor.size() != static_cast<size_t>(info.rows) * info.cols) {
    return absl::InvalidArgumentError(absl::StrCat(dataset, ": grid frame has ",
                                                   points_sensor.size(), " points, expected ",
                                                   info.rows, "x", info.cols));
  }
  if (points_sensor.size() > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(dataset, ": too many points in one frame"));
  }
  if (!(t > state.last_t) || !std::isfinite(t)) {
    return absl::InvalidArgumentError(
        absl::StrCat(dataset, ": time ", t, " is not after the previous frame's ", state.last_t));
  }
  state.last_t = t;
  const FrameRecord record{t, state.points.rows(), static_cast<uint32_t>(points_sensor.size())};
  absl::Status s = state.frames.Append(std::span<const FrameRecord>(&record, 1));
  if (s.ok()) s = state.points.Append(points_sensor);
  return w.Err(s);
}

absl::Status ScanWriter::AppendMagnetometer(std::span<const MagnetometerRecord> records) {
  Impl& w = *impl_;
  if (absl::Status s = w.CheckOpen(); !s.ok()) return s;
  if (records.empty()) return absl::OkStatus();
  if (!w.mag.valid()) {
    auto dataset = h5::CreateRows(w.file.get(), "magnetometer", h5::MagnetometerFileType().get(), 0,
                                  kPathChunkRows);
    if (!dataset.ok()) return w.Err(dataset.status());
    w.mag = RowAppender<MagnetometerRecord>(*std::move(dataset), w.mag_mem.get(), 0);
  }
  return w.Err(w.mag.Append(records));
}

absl::Status ScanWriter::Close() {
  Impl& w = *impl_;
  if (absl::Status s = w.CheckOpen(); !s.ok()) return s;
  absl::Status s = w.FlushAll();
  w.CloseHandles();
  if (s.ok()) {
    s = h5::CheckRc(H5Fclose(w.file.Release()), "cannot close the file");
  }
  if (!s.ok()) return w.Err(s);  // the destructor removes the partial file
  // Durable: a job may be submitted on this scan as soon as it returns (atomic_file.h).
  if (absl::Status renamed = RenameDurably(w.partial, w.path); !renamed.ok()) return renamed;
  w.closed = true;
  return absl::OkStatus();
}

}  // namespace carvemap
