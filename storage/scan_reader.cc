#include "storage/scan_reader.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <span>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/h5_util.h"

namespace carvemap {
namespace {

using h5::Hid;

constexpr double kQuaternionNormTolerance = 1e-3;

// One sensor's group and its open frames and points datasets, with block reads that name the
// file, dataset and row on error.
struct SensorData {
  std::string file;
  SensorInfo info;
  std::string group_path;  // "/sensors/<name>"
  Hid frames;
  Hid points;
  Hid frame_mem = h5::FrameMemType();
  uint64_t frame_count = 0;
  uint64_t point_count = 0;

  [[nodiscard]] std::string frames_path() const { return group_path + "/frames"; }
  [[nodiscard]] std::string points_path() const { return group_path + "/points"; }
  absl::Status ReadFrameRows(uint64_t first, uint64_t n, std::vector<FrameRecord>& out) const;
  absl::Status ReadPoints(uint64_t first, uint64_t n, std::vector<Eigen::Vector3f>& out) const;
  // OK when the frame's rays lie inside /points.
  absl::Status CheckFrameRange(uint64_t row, const FrameRecord& f) const;
};

absl::Status Invalid(absl::string_view file, absl::string_view dataset, absl::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat(file, ": ", dataset, ": ", what));
}

absl::Status RowError(absl::string_view file, absl::string_view dataset, uint64_t row,
                      absl::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat(file, ": ", dataset, " row ", row, ": ", what));
}

bool AllFinite(std::span<const double> values) {
  return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v); });
}

// Rows of a checked dataset: its rank is `cols` ? 2 : 1, and rank-2 datasets have `cols` columns.
absl::StatusOr<uint64_t> CheckShape(hid_t dataset, hsize_t cols) {
  auto dims = h5::Dims(dataset);
  if (!dims.ok()) return dims.status();
  const size_t rank = cols > 0 ? 2 : 1;
  if (dims->size() != rank || (cols > 0 && (*dims)[1] != cols)) {
    std::string shape = "[";
    for (size_t i = 0; i < dims->size(); ++i) absl::StrAppend(&shape, i ? "][" : "", (*dims)[i]);
    absl::StrAppend(&shape, "]");
    return absl::InvalidArgumentError(
        cols > 0 ? absl::StrCat("shape ", shape, ", expected [N][", cols, "]")
                 : absl::StrCat("shape ", shape, ", expected a 1-D table"));
  }
  // Before anything is allocated for the rows or streamed through them.
  if (absl::Status s = h5::CheckDataStored(dataset); !s.ok()) return s;
  return (*dims)[0];
}

// A numeric (integer or float) rank-2 dataset with `cols` columns.
absl::StatusOr<uint64_t> CheckNumericMatrix(hid_t dataset, hsize_t cols) {
  Hid type(H5Dget_type(dataset));
  const H5T_class_t cls = H5Tget_class(type.get());
  if (cls != H5T_FLOAT && cls != H5T_INTEGER) {
    return absl::InvalidArgumentError("not a numeric dataset");
  }
  if (absl::Status s = h5::CheckTypeIsSane(type.get()); !s.ok()) return s;
  return CheckShape(dataset, cols);
}

absl::StatusOr<uint64_t> CheckCompoundTable(hid_t dataset, std::span<const h5::Field> fields) {
  Hid type(H5Dget_type(dataset));
  if (absl::Status s = h5::CheckCompoundFields(type.get(), fields); !s.ok()) return s;
  return CheckShape(dataset, 0);
}

std::string Interval(uint64_t first, uint64_t end) {
  return absl::StrCat("[", first, ", ", end, ")");
}

absl::Status SensorData::ReadFrameRows(uint64_t first, uint64_t n,
                                       std::vector<FrameRecord>& out) const {
  out.resize(n);
  absl::Status status = h5::ReadRows(frames.get(), frame_mem.get(), 0, first, n, out.data());
  if (status.ok()) return status;
  return absl::DataLossError(
      absl::StrCat(file, ": ", frames_path(), " row ", first, ": ", status.message()));
}

absl::Status SensorData::ReadPoints(uint64_t first, uint64_t n,
                                    std::vector<Eigen::Vector3f>& out) const {
  out.resize(n);
  absl::Status status = h5::ReadRows(points.get(), H5T_NATIVE_FLOAT, 3, first, n, out.data());
  if (status.ok()) return status;
  return absl::DataLossError(
      absl::StrCat(file, ": ", points_path(), " row ", first, ": ", status.message()));
}

absl::Status SensorData::CheckFrameRange(uint64_t row, const FrameRecord& f) const {
  if (f.first > point_count || f.count > point_count - f.first) {
    return RowError(file, frames_path(), row,
                    absl::StrCat("rays ", Interval(f.first, f.first + f.count), " outside ",
                                 points_path(), " (", point_count, " rows)"));
  }
  return absl::OkStatus();
}

}  // namespace

struct ScanReader::Impl {
  std::string file;
  Hid fid;
  // OpenOptions::world_yaw_rad; 0: nothing is turned.
  double yaw = 0;
  [[nodiscard]] Eigen::Quaterniond Turn() const {
    return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  }
  std::vector<PathRecord> path;
  std::vector<TimedPose> timed_path;
  std::optional<std::vector<PathCovariance>> path_cov;
  std::optional<std::vector<MagnetometerRecord>> magnetometer;
  std::vector<SensorData> sensor_data;
  std::vector<SensorInfo> sensors;
  // The file's path tables (what path, path_cov and magnetometer hold may be part of them).
  uint64_t path_rows = 0;
  bool has_path_cov = false;
  uint64_t magnetometer_rows = 0;
  bool has_magnetometer = false;

  absl::StatusOr<Hid> OpenDataset(const std::string& name) const;
  absl::Status CheckRoot() const;
  absl::Status CheckPathTables();
  // Rows [first, first + n) of /path (and /path_cov when there is one).
  absl::Status LoadPath(uint64_t first, uint64_t n);
  absl::Status LoadPathCov(uint64_t first, uint64_t n);
  absl::Status LoadPathAroundFrames(std::span<const RowRange> rows);
  absl::StatusOr<PathRecord> PathRow(uint64_t row) const;
  absl::Status LoadMagnetometer();
  absl::Status LoadSensors();
  absl::Status LoadSensor(hid_t sensors_group, const std::string& name);

  // Calls `fn(first row, rows)` on /path in blocks of kPathBlockRows, whatever Open kept.
  absl::Status ForEachPathBlock(
      const std::function<absl::Status(uint64_t, std::span<const PathRecord>)>& fn) const;
  absl::Status ValidatePath() const;
  // The same on /path_cov (when the scan has one), in the file's frame.
  absl::Status ForEachPathCovBlock(
      const std::function<absl::Status(uint64_t, std::span<const PathCovariance>)>& fn) const;
  absl::Status ValidatePathCov() const;
  absl::Status ValidateMagnetometer() const;
  absl::Status ValidateFrames(const SensorData& s, size_t block_rows) const;
  absl::Status ValidatePoints(const SensorData& s, size_t block_rows) const;
};

absl::StatusOr<Hid> ScanReader::Impl::OpenDataset(const std::string& name) const {
  if (!h5::Exists(fid.get(), name)) return Invalid(file, name, "missing");
  H5O_info_t info;
  if (H5Oget_info_by_name(fid.get(), name.c_str(), &info, H5P_DEFAULT) < 0 ||
      info.type != H5O_TYPE_DATASET) {
    h5::TakeErrorStack();
    return Invalid(file, name, "not a dataset");
  }
  auto dataset = h5::CheckId(H5Dopen2(fid.get(), name.c_str(), H5P_DEFAULT), "cannot open");
  if (!dataset.ok()) return h5::Prefixed(absl::StrCat(file, ": ", name), dataset.status());
  return dataset;
}

absl::Status ScanReader::Impl::CheckRoot() const {
  const hid_t root = fid.get();
  auto format = h5::ReadStringAttr(root, "format");
  if (!format.ok()) return Invalid(file, "/", format.status().message());
  if (*format != std::string(kScanFormatName)) {
    return Invalid(
        file, "/",
        absl::StrCat("format is '", *format, "', expected '", std::string(kScanFormatName), "'"));
  }
  auto version = h5::ReadIntAttr(root, "version");
  if (!version.ok()) return Invalid(file, "/", version.status().message());
  if (*version != kScanFormatVersion) {
    return absl::InvalidArgumentError(absl::StrCat(file, ": unknown format version ", *version,
                                                   " (this reader knows ", kScanFormatVersion,
                                                   ")"));
  }
  return absl::OkStatus();
}

absl::Status ScanReader::Impl::CheckPathTables() {
  auto dataset = OpenDataset("/path");
  if (!dataset.ok()) return dataset.status();
  auto rows = CheckCompoundTable(dataset->get(), h5::PathFields());
  if (!rows.ok()) return Invalid(file, "/path", rows.status().message());
  path_rows = *rows;
  if (h5::Exists(fid.get(), "/path_cov")) {
    auto cov = OpenDataset("/path_cov");
    if (!cov.ok()) return cov.status();
    auto cov_rows = CheckNumericMatrix(cov->get(), 12);
    if (!cov_rows.ok()) return Invalid(file, "/path_cov", cov_rows.status().message());
    if (*cov_rows != path_rows) {
      return Invalid(file, "/path_cov",
                     absl::StrCat(*cov_rows, " rows, but /path has ", path_rows));
    }
    has_path_cov = true;
  }
  if (h5::Exists(fid.get(), "/magnetometer")) {
    auto mag = OpenDataset("/magnetometer");
    if (!mag.ok()) return mag.status();
    auto mag_rows = CheckCompoundTable(mag->get(), h5::MagnetometerFields());
    if (!mag_rows.ok()) return Invalid(file, "/magnetometer", mag_rows.status().message());
    magnetometer_rows = *mag_rows;
    has_magnetometer = true;
  }
  return absl::OkStatus();
}

absl::StatusOr<PathRecord> ScanReader::Impl::PathRow(uint64_t row) const {
  auto dataset = OpenDataset("/path");
  if (!dataset.ok()) return dataset.status();
  PathRecord record;
  Hid mem = h5::PathMemType();
  if (absl::Status s = h5::ReadRows(dataset->get(), mem.get(), 0, row, 1, &record); !s.ok()) {
    return h5::Prefixed(absl::StrCat(file, ": /path row ", row), s);
  }
  return record;
}

absl::Status ScanReader::Impl::LoadPathAroundFrames(std::span<const RowRange> rows) {
  if (rows.size() != sensor_data.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        file, ": ", rows.size(), " frame row ranges for ", sensor_data.size(), " sensors"));
  }
  double t_first = std::numeric_limits<double>::infinity(), t_last = -t_first;
  std::vector<FrameRecord> record;
  for (size_t i = 0; i < rows.size(); ++i) {
    const SensorData& sd = sensor_data[i];
    if (rows[i].begin >= rows[i].end) continue;
    if (rows[i].end > sd.frame_count) {
      return absl::InvalidArgumentError(absl::StrCat(file, ": ", sd.frames_path(), ": rows [",
                                                     rows[i].begin, ", ", rows[i].end,
                                                     ") outside its ", sd.frame_count, " rows"));
    }
    for (uint64_t row : {rows[i].begin, rows[i].end - 1}) {
      if (absl::Status st = sd.ReadFrameRows(row, 1, record); !st.ok()) return st;
      t_first = std::min(t_first, record[0].t);
      t_last = std::max(t_last, record[0].t);
    }
  }
  if (path_rows == 0 || !(t_first <= t_last)) return LoadPath(0, 0);
  // The first row whose time is above t (path_rows when none), by bisection: ~2·log2(rows)
  // single-row reads instead of the whole table.
  const auto first_above = [&](double t, bool or_equal) -> absl::StatusOr<uint64_t> {
    uint64_t lo = 0, hi = path_rows;
    while (lo < hi) {
      const uint64_t mid = lo + (hi - lo) / 2;
      absl::StatusOr<PathRecord> r = PathRow(mid);
      if (!r.ok()) return r.status();
      if (r->t > t || (or_equal && r->t == t)) {
        hi = mid;
      } else {
        lo = mid + 1;
      }
    }
    return lo;
  };
  absl::StatusOr<uint64_t> after_first = first_above(t_first, false);
  if (!after_first.ok()) return after_first.status();
  absl::StatusOr<uint64_t> at_last = first_above(t_last, true);
  if (!at_last.ok()) return at_last.status();
  // The pose at or before t_first is row after_first − 1, the one at or after t_last row
  // at_last; one more row either way.
  const uint64_t begin = *after_first >= 2 ? *after_first - 2 : 0;
  const uint64_t end = std::min(path_rows, *at_last + 2);
  if (absl::Status st = LoadPath(begin, end - begin); !st.ok()) return st;
  return has_path_cov ? LoadPathCov(begin, end - begin) : absl::OkStatus();
}

absl::Status ScanReader::Impl::LoadPath(uint64_t first, uint64_t n) {
  auto dataset = OpenDataset("/path");
  if (!dataset.ok()) return dataset.status();
  path.resize(n);
  Hid mem = h5::PathMemType();
  if (absl::Status s = h5::ReadRows(dataset->get(), mem.get(), 0, first, n, path.data()); !s.ok()) {
    return h5::Prefixed(absl::StrCat(file, ": /path"), s);
  }
  if (yaw != 0) {
    for (PathRecord& p : path) TurnAboutVertical(yaw, p);
  }
  timed_path.clear();
  timed_path.reserve(path.size());
  for (const PathRecord& p : path) {
    Eigen::Quaterniond q(p.qw, p.qx, p.qy, p.qz);
    // Interpolation wants unit quaternions; Validate() reports norms far from 1.
    if (q.norm() > 0 && std::isfinite(q.norm())) q.normalize();
    timed_path.push_back(TimedPose{p.t, Pose{q, Eigen::Vector3d(p.x, p.y, p.z)}});
  }
  return absl::OkStatus();
}

absl::Status ScanReader::Impl::LoadPathCov(uint64_t first, uint64_t n) {
  auto dataset = OpenDataset("/path_cov");
  if (!dataset.ok()) return dataset.status();
  path_cov.emplace(n);
  absl::Status s = h5::Prefixed(
      absl::StrCat(file, ": /path_cov"),
      h5::ReadRows(dataset->get(), H5T_NATIVE_FLOAT, 12, first, n, path_cov->data()));
  if (s.ok() && yaw != 0) {
    for (PathCovariance& c : *path_cov) TurnAboutVertical(yaw, c);
  }
  return s;
}

absl::Status ScanReader::Impl::LoadMagnetometer() {
  if (!has_magnetometer) return absl::OkStatus();
  auto dataset = OpenDataset("/magnetometer");
  if (!dataset.ok()) return dataset.status();
  magnetometer.emplace(magnetometer_rows);
  Hid mem = h5::MagnetometerMemType();
  return h5::Prefixed(
      absl::StrCat(file, ": /magnetometer"),
      h5::ReadRows(dataset->get(), mem.get(), 0, 0, magnetometer_rows, magnetometer->data()));
}

namespace {

herr_t CollectName(hid_t /*group*/, const char* name, const H5L_info_t* /*info*/, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

absl::StatusOr<SensorKind> ParseKind(absl::string_view kind) {
  if (kind == "line") return SensorKind::kLine;
  if (kind == "grid") return SensorKind::kGrid;
  if (kind == "points") return SensorKind::kPoints;
  return absl::InvalidArgumentError(
      absl::StrCat("kind is '", kind, "', expected 'line', 'grid' or 'points'"));
}

absl::StatusOr<uint32_t> ReadDimAttr(hid_t group, const char* name) {
  auto value = h5::ReadIntAttr(group, name);
  if (!value.ok()) return value.status();
  if (*value <= 0 || *value > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(
        absl::StrCat("attribute '", name, "' is ", *value, ", expected a positive integer"));
  }
  return static_cast<uint32_t>(*value);
}

// The attributes of a sensor group into `info` (name already set).
absl::Status ReadSensorAttrs(hid_t group, SensorInfo& info) {
  auto kind_name = h5::ReadStringAttr(group, "kind");
  if (!kind_name.ok()) return kind_name.status();
  auto kind = ParseKind(*kind_name);
  if (!kind.ok()) return kind.status();
  info.kind = *kind;
  if (info.kind == SensorKind::kGrid) {
    auto rows = ReadDimAttr(group, "rows");
    if (!rows.ok()) return rows.status();
    auto cols = ReadDimAttr(group, "cols");
    if (!cols.ok()) return cols.status();
    info.rows = *rows;
    info.cols = *cols;
  }
  auto r = h5::ReadDoublesAttr(group, "R_s2c", 9);
  if (!r.ok()) return r.status();
  auto t = h5::ReadDoublesAttr(group, "T_s2c", 3);
  if (!t.ok()) return t.status();
  auto sigma_t = h5::ReadDoublesAttr(group, "sigma_t", 1);
  if (!sigma_t.ok()) return sigma_t.status();
  auto range_sigma = h5::ReadDoublesAttr(group, "range_sigma", 2);
  if (!range_sigma.ok()) return range_sigma.status();
  auto max_range = h5::ReadDoublesAttr(group, "max_range", 1);
  if (!max_range.ok()) return max_range.status();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) info.R_s2c(i, j) = (*r)[3 * i + j];
  }
  info.T_s2c = Eigen::Vector3d((*t)[0], (*t)[1], (*t)[2]);
  info.sigma_t_s = (*sigma_t)[0];
  info.range_sigma = {(*range_sigma)[0], (*range_sigma)[1]};
  info.max_range_m = (*max_range)[0];
  if (const std::string problem = SensorParametersProblem(info); !problem.empty()) {
    return absl::InvalidArgumentError(problem);
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ScanReader::Impl::LoadSensors() {
  if (!h5::Exists(fid.get(), "/sensors")) return absl::OkStatus();  // a path-only scan
  auto group = h5::CheckId(H5Gopen2(fid.get(), "/sensors", H5P_DEFAULT), "not a group");
  if (!group.ok()) return h5::Prefixed(absl::StrCat(file, ": /sensors"), group.status());
  // Creation order when the writer tracked it (ours does), so indices match the writer's;
  // otherwise (h5py's default) names in ascending order.
  Hid gcpl(H5Gget_create_plist(group->get()));
  unsigned order_flags = 0;
  H5Pget_link_creation_order(gcpl.get(), &order_flags);
  const H5_index_t index =
      (order_flags & H5P_CRT_ORDER_INDEXED) ? H5_INDEX_CRT_ORDER : H5_INDEX_NAME;
  std::vector<std::string> names;
  if (H5Literate(group->get(), index, H5_ITER_INC, nullptr, CollectName, &names) < 0) {
    return h5::Error(absl::StatusCode::kDataLoss,
                     absl::StrCat(file, ": /sensors: cannot list the sensors"));
  }
  for (const std::string& name : names) {
    if (absl::Status s = LoadSensor(group->get(), name); !s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::Status ScanReader::Impl::LoadSensor(hid_t sensors_group, const std::string& name) {
  SensorData data;
  data.file = file;
  data.info.name = name;
  data.group_path = "/sensors/" + name;
  H5O_info_t object;
  if (H5Oget_info_by_name(sensors_group, name.c_str(), &object, H5P_DEFAULT) < 0 ||
      object.type != H5O_TYPE_GROUP) {
    h5::TakeErrorStack();
    return Invalid(file, data.group_path, "not a group");
  }
  Hid group(H5Gopen2(sensors_group, name.c_str(), H5P_DEFAULT));
  if (absl::Status s = ReadSensorAttrs(group.get(), data.info); !s.ok()) {
    return Invalid(file, data.group_path, s.message());
  }
  auto frames = OpenDataset(data.frames_path());
  if (!frames.ok()) return frames.status();
  auto frame_rows = CheckCompoundTable(frames->get(), h5::FrameFields());
  if (!frame_rows.ok()) return Invalid(file, data.frames_path(), frame_rows.status().message());
  auto points = OpenDataset(data.points_path());
  if (!points.ok()) return points.status();
  auto point_rows = CheckNumericMatrix(points->get(), 3);
  if (!point_rows.ok()) return Invalid(file, data.points_path(), point_rows.status().message());
  data.frames = *std::move(frames);
  data.points = *std::move(points);
  data.frame_count = *frame_rows;
  data.point_count = *point_rows;
  sensors.push_back(data.info);
  sensor_data.push_back(std::move(data));
  return absl::OkStatus();
}

// --- Open and accessors ------------------------------------------------------------------

ScanReader::ScanReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ScanReader::~ScanReader() = default;

absl::StatusOr<std::unique_ptr<ScanReader>> ScanReader::Open(const std::string& path) {
  return Open(path, OpenOptions());
}

absl::StatusOr<std::unique_ptr<ScanReader>> ScanReader::Open(const std::string& path,
                                                             const OpenOptions& options) {
  h5::Init();
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    return absl::NotFoundError(absl::StrCat(path, ": no such file"));
  }
  if (H5Fis_hdf5(path.c_str()) <= 0) {
    const std::string hdf5 = h5::TakeErrorStack();
    return absl::DataLossError(absl::StrCat(path, ": not an HDF5 file (truncated or corrupt)",
                                            hdf5.empty() ? "" : " (HDF5: " + hdf5 + ")"));
  }
  auto impl = std::make_unique<Impl>();
  impl->file = path;
  if (!std::isfinite(options.world_yaw_rad)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": world yaw is not finite"));
  }
  impl->yaw = options.world_yaw_rad;
  const hid_t fid = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (fid < 0) {
    // HDF5 1.10 compares the superblock's end-of-file address with the file's size.
    return h5::Error(absl::StatusCode::kDataLoss,
                     absl::StrCat(path, ": truncated or corrupt HDF5 file"));
  }
  impl->fid = Hid(fid);
  absl::Status s = impl->CheckRoot();
  if (s.ok()) s = impl->CheckPathTables();
  if (s.ok()) s = impl->LoadSensors();
  if (s.ok()) {
    switch (options.path_rows) {
      case PathRows::kAll:
        s = impl->LoadPath(0, impl->path_rows);
        if (s.ok() && impl->has_path_cov) s = impl->LoadPathCov(0, impl->path_rows);
        if (s.ok()) s = impl->LoadMagnetometer();
        break;
      case PathRows::kFrames:
        s = impl->LoadPathAroundFrames(options.frame_rows);
        break;
      case PathRows::kNone:
        break;
    }
  }
  if (!s.ok()) return s;
  return std::unique_ptr<ScanReader>(new ScanReader(std::move(impl)));
}

const std::string& ScanReader::file() const { return impl_->file; }
const std::vector<PathRecord>& ScanReader::path() const { return impl_->path; }
const std::vector<TimedPose>& ScanReader::timed_path() const { return impl_->timed_path; }
const std::optional<std::vector<PathCovariance>>& ScanReader::path_covariance() const {
  return impl_->path_cov;
}
const std::optional<std::vector<MagnetometerRecord>>& ScanReader::magnetometer() const {
  return impl_->magnetometer;
}
const std::vector<SensorInfo>& ScanReader::sensors() const { return impl_->sensors; }
uint64_t ScanReader::frame_count(int sensor) const {
  return impl_->sensor_data.at(sensor).frame_count;
}
uint64_t ScanReader::point_count(int sensor) const {
  return impl_->sensor_data.at(sensor).point_count;
}

Pose ScanReader::PoseAt(double t) const {
  if (impl_->timed_path.empty()) return Pose{};
  return PoseAtTime(impl_->timed_path, t);
}

absl::StatusOr<ScanFrame> ScanReader::ReadFrame(int sensor, uint64_t row) {
  if (sensor < 0 || sensor >= static_cast<int>(impl_->sensor_data.size())) {
    return absl::InvalidArgumentError(absl::StrCat(impl_->file, ": unknown sensor index ", sensor));
  }
  const SensorData& s = impl_->sensor_data[sensor];
  if (row >= s.frame_count) {
    return absl::OutOfRangeError(absl::StrCat(impl_->file, ": ", s.frames_path(), " row ", row,
                                              ": past the end (", s.frame_count, " rows)"));
  }
  std::vector<FrameRecord> record;
  if (absl::Status st = s.ReadFrameRows(row, 1, record); !st.ok()) return st;
  if (absl::Status st = s.CheckFrameRange(row, record[0]); !st.ok()) return st;
  ScanFrame frame;
  frame.sensor = sensor;
  frame.row = row;
  frame.t = record[0].t;
  if (absl::Status st = s.ReadPoints(record[0].first, record[0].count, frame.points_sensor);
      !st.ok()) {
    return st;
  }
  return frame;
}

// --- Streaming ---------------------------------------------------------------------------

namespace {

// One sensor's read position: a block of frame rows and a block of points, refilled by
// hyperslab reads so memory stays within the budget (plus one frame when a frame is larger).
class SensorCursor {
 public:
  // Rows [begin, end) of the sensor.
  SensorCursor(const SensorData& data, int index, size_t block_bytes, uint64_t begin,
               uint64_t end)
      : data_(data),
        index_(index),
        frame_block_rows_(std::max<size_t>(1, block_bytes / 2 / sizeof(FrameRecord))),
        point_block_rows_(std::max<size_t>(1, block_bytes / 2 / sizeof(Eigen::Vector3f))),
        end_row_(std::min(end, data.frame_count)),
        next_row_(begin) {}

  [[nodiscard]] bool done() const { return next_row_ >= end_row_; }
  [[nodiscard]] int index() const { return index_; }
  [[nodiscard]] uint64_t row() const { return next_row_; }
  // REQUIRES: !done() and Load() succeeded.
  [[nodiscard]] double time() const { return frames_[next_row_ - frames_first_].t; }

  // Makes the frame row at the cursor available.
  absl::Status Load() {
    if (done() || (next_row_ >= frames_first_ && next_row_ < frames_first_ + frames_.size())) {
      return absl::OkStatus();
    }
    frames_first_ = next_row_;
    const uint64_t n = std::min<uint64_t>(frame_block_rows_, end_row_ - next_row_);
    return data_.ReadFrameRows(frames_first_, n, frames_);
  }

  // Fills `frame` with the frame at the cursor and advances. REQUIRES: !done(), Load() ok.
  absl::Status Take(ScanFrame& frame) {
    const FrameRecord record = frames_[next_row_ - frames_first_];
    if (absl::Status s = data_.CheckFrameRange(next_row_, record); !s.ok()) return s;
    if (absl::Status s = LoadPoints(record.first, record.count); !s.ok()) return s;
    frame.sensor = index_;
    frame.row = next_row_;
    frame.t = record.t;
    const auto begin = points_.begin() + static_cast<ptrdiff_t>(record.first - points_first_);
    frame.points_sensor.assign(begin, begin + record.count);
    ++next_row_;
    return absl::OkStatus();
  }

 private:
  // Makes points [first, first+count) resident, reading a block that starts at `first`.
  absl::Status LoadPoints(uint64_t first, uint64_t count) {
    if (first >= points_first_ && first + count <= points_first_ + points_.size()) {
      return absl::OkStatus();
    }
    points_first_ = first;
    const uint64_t n =
        std::min<uint64_t>(std::max<uint64_t>(count, point_block_rows_), data_.point_count - first);
    return data_.ReadPoints(first, n, points_);
  }

  const SensorData& data_;
  int index_;
  size_t frame_block_rows_;
  size_t point_block_rows_;
  uint64_t end_row_;
  uint64_t next_row_;
  uint64_t frames_first_ = 0;
  std::vector<FrameRecord> frames_;
  uint64_t points_first_ = 0;
  std::vector<Eigen::Vector3f> points_;
};

class MergedFrameStream : public ScanReader::FrameStream {
 public:
  MergedFrameStream(const std::vector<SensorData>& sensors, size_t block_bytes,
                    std::span<const ScanReader::RowRange> rows) {
    for (size_t i = 0; i < sensors.size(); ++i) {
      const ScanReader::RowRange r = rows.empty() ? ScanReader::RowRange{0, sensors[i].frame_count}
                                                  : rows[i];
      cursors_.emplace_back(sensors[i], static_cast<int>(i), block_bytes, r.begin, r.end);
    }
  }

  absl::StatusOr<bool> Next(ScanFrame& frame) override {
    if (!error_.ok()) return error_;
    SensorCursor* best = nullptr;
    // Few sensors: a linear scan beats a heap. Ties go to the lower sensor index because the
    // comparison is strict; rows of one sensor come in order by construction.
    for (SensorCursor& cursor : cursors_) {
      if (absl::Status s = cursor.Load(); !s.ok()) return error_ = s;
      if (cursor.done()) continue;
      if (best == nullptr || cursor.time() < best->time()) best = &cursor;
    }
    if (best == nullptr) return false;
    if (absl::Status s = best->Take(frame); !s.ok()) return error_ = s;
    return true;
  }

 private:
  std::vector<SensorCursor> cursors_;
  absl::Status error_;
};

}  // namespace

std::unique_ptr<ScanReader::FrameStream> ScanReader::StreamFrames(size_t block_bytes) {
  return std::make_unique<MergedFrameStream>(impl_->sensor_data, block_bytes,
                                             std::span<const RowRange>{});
}

absl::StatusOr<std::unique_ptr<ScanReader::FrameStream>> ScanReader::StreamFrames(
    std::span<const RowRange> rows, size_t block_bytes) {
  if (rows.size() != impl_->sensor_data.size()) {
    return absl::InvalidArgumentError(absl::StrCat(impl_->file, ": ", rows.size(),
                                                   " row ranges for ",
                                                   impl_->sensor_data.size(), " sensors"));
  }
  for (size_t i = 0; i < rows.size(); ++i) {
    const SensorData& s = impl_->sensor_data[i];
    if (rows[i].begin > rows[i].end || rows[i].end > s.frame_count) {
      return absl::InvalidArgumentError(
          absl::StrCat(impl_->file, ": ", s.frames_path(), ": rows [", rows[i].begin, ", ",
                       rows[i].end, ") outside its ", s.frame_count, " rows"));
    }
  }
  return std::unique_ptr<FrameStream>(
      std::make_unique<MergedFrameStream>(impl_->sensor_data, block_bytes, rows));
}

absl::StatusOr<std::vector<FrameRecord>> ScanReader::FrameRecords(int sensor) {
  if (sensor < 0 || sensor >= static_cast<int>(impl_->sensor_data.size())) {
    return absl::InvalidArgumentError(absl::StrCat(impl_->file, ": unknown sensor index ", sensor));
  }
  const SensorData& s = impl_->sensor_data[sensor];
  std::vector<FrameRecord> records;
  records.reserve(s.frame_count);
  constexpr uint64_t kBlock = 1 << 16;
  std::vector<FrameRecord> block;
  for (uint64_t first = 0; first < s.frame_count; first += kBlock) {
    const uint64_t n = std::min(kBlock, s.frame_count - first);
    if (absl::Status st = s.ReadFrameRows(first, n, block); !st.ok()) return st;
    records.insert(records.end(), block.begin(), block.end());
  }
  return records;
}

// --- Validation --------------------------------------------------------------------------

// The path tables are read in blocks of this many rows, whatever Open kept of them: memory
// does not grow with the survey's length.
constexpr uint64_t kPathBlockRows = 1 << 16;

absl::Status ScanReader::Impl::ForEachPathBlock(
    const std::function<absl::Status(uint64_t, std::span<const PathRecord>)>& fn) const {
  auto dataset = OpenDataset("/path");
  if (!dataset.ok()) return dataset.status();
  Hid mem = h5::PathMemType();
  std::vector<PathRecord> block;
  for (uint64_t first = 0; first < path_rows; first += block.size()) {
    block.resize(std::min(kPathBlockRows, path_rows - first));
    if (absl::Status s =
            h5::ReadRows(dataset->get(), mem.get(), 0, first, block.size(), block.data());
        !s.ok()) {
      return h5::Prefixed(absl::StrCat(file, ": /path"), s);
    }
    if (absl::Status s = fn(first, block); !s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<Eigen::Vector3d>> ScanReader::PathPositions() {
  std::vector<Eigen::Vector3d> positions;
  positions.reserve(impl_->path_rows);
  absl::Status s = impl_->ForEachPathBlock([&](uint64_t, std::span<const PathRecord> block) {
    for (const PathRecord& p : block) positions.emplace_back(p.x, p.y, p.z);
    return absl::OkStatus();
  });
  if (!s.ok()) return s;
  if (impl_->yaw != 0) {
    const Eigen::Quaterniond turn = impl_->Turn();
    for (Eigen::Vector3d& x : positions) x = turn * x;
  }
  return positions;
}

absl::StatusOr<std::pair<double, double>> ScanReader::PathTimeSpan() {
  if (impl_->path_rows == 0) return Invalid(impl_->file, "/path", "no poses");
  auto dataset = impl_->OpenDataset("/path");
  if (!dataset.ok()) return dataset.status();
  Hid mem = h5::PathMemType();
  PathRecord first{}, last{};
  for (auto [row, out] : {std::pair{uint64_t{0}, &first}, std::pair{impl_->path_rows - 1, &last}}) {
    if (absl::Status s = h5::ReadRows(dataset->get(), mem.get(), 0, row, 1, out); !s.ok()) {
      return h5::Prefixed(absl::StrCat(impl_->file, ": /path"), s);
    }
  }
  return std::pair{first.t, last.t};
}

absl::StatusOr<std::vector<Eigen::Vector3d>> ScanReader::MagnetometerInWorld() {
  std::vector<Eigen::Vector3d> out;
  if (!impl_->has_magnetometer) return out;
  std::vector<MagnetometerRecord> readings;
  if (impl_->magnetometer) {
    readings = *impl_->magnetometer;
  } else {
    if (absl::Status s = impl_->LoadMagnetometer(); !s.ok()) return s;
    readings = *std::move(impl_->magnetometer);
    impl_->magnetometer.reset();
  }
  std::stable_sort(
      readings.begin(), readings.end(),
      [](const MagnetometerRecord& a, const MagnetometerRecord& b) { return a.t < b.t; });
  out.reserve(readings.size());
  const Eigen::Quaterniond turn = impl_->Turn();
  // One pass over the path in blocks: each reading between two consecutive poses takes their
  // interpolation (§2.4), as PoseAt does on a path held whole.
  size_t next = 0;
  bool have_previous = false;
  TimedPose previous;
  absl::Status s = impl_->ForEachPathBlock([&](uint64_t, std::span<const PathRecord> block) {
    for (const PathRecord& p : block) {
      const TimedPose pose{p.t, Pose{Eigen::Quaterniond(p.qw, p.qx, p.qy, p.qz).normalized(),
                                     Eigen::Vector3d(p.x, p.y, p.z)}};
      while (next < readings.size() && readings[next].t < pose.t) {
        if (have_previous && readings[next].t >= previous.t) {
          const double u = (readings[next].t - previous.t) / (pose.t - previous.t);
          const Pose at = InterpolatePose(previous.pose, pose.pose, u);
          const MagnetometerRecord& m = readings[next];
          out.push_back(turn * (at.rotation * Eigen::Vector3d(m.mx, m.my, m.mz)));
        }
        ++next;
      }
      while (next < readings.size() && readings[next].t == pose.t) {
        const MagnetometerRecord& m = readings[next++];
        out.push_back(turn * (pose.pose.rotation * Eigen::Vector3d(m.mx, m.my, m.mz)));
      }
      previous = pose;
      have_previous = true;
    }
    return absl::OkStatus();
  });
  if (!s.ok()) return s;
  return out;
}

absl::Status ScanReader::Impl::ValidatePath() const {
  if (path_rows == 0) return Invalid(file, "/path", "no poses");
  double previous_t = 0;
  return ForEachPathBlock([&](uint64_t first, std::span<const PathRecord> block) {
    for (size_t k = 0; k < block.size(); ++k) {
      const uint64_t i = first + k;
      const PathRecord& p = block[k];
      const std::array<double, 8> values = {p.t, p.x, p.y, p.z, p.qw, p.qx, p.qy, p.qz};
      if (!AllFinite(values)) return RowError(file, "/path", i, "non-finite value");
      if (i > 0 && !(p.t > previous_t)) {
        return RowError(file, "/path", i,
                        absl::StrCat("time ", p.t, " is not after row ", i - 1, "'s ", previous_t));
      }
      previous_t = p.t;
      const double norm = std::sqrt(p.qw * p.qw + p.qx * p.qx + p.qy * p.qy + p.qz * p.qz);
      if (std::abs(norm - 1.0) > kQuaternionNormTolerance) {
        return RowError(file, "/path", i, absl::StrCat("non-unit quaternion (norm ", norm, ")"));
      }
    }
    return absl::OkStatus();
  });
}

absl::Status ScanReader::Impl::ForEachPathCovBlock(
    const std::function<absl::Status(uint64_t, std::span<const PathCovariance>)>& fn) const {
  auto dataset = OpenDataset("/path_cov");
  if (!dataset.ok()) return dataset.status();
  std::vector<PathCovariance> block;
  for (uint64_t first = 0; first < path_rows; first += block.size()) {
    block.resize(std::min(kPathBlockRows, path_rows - first));
    if (absl::Status s =
            h5::ReadRows(dataset->get(), H5T_NATIVE_FLOAT, 12, first, block.size(), block.data());
        !s.ok()) {
      return h5::Prefixed(absl::StrCat(file, ": /path_cov"), s);
    }
    if (absl::Status s = fn(first, block); !s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::StatusOr<std::optional<double>> ScanReader::HorizontalPositionSigma() {
  if (!impl_->has_path_cov || impl_->path_rows == 0) return std::nullopt;
  double sum = 0;  // of (xx + yy) / 2, which a turn about the vertical keeps
  absl::Status s = impl_->ForEachPathCovBlock([&](uint64_t, std::span<const PathCovariance> block) {
    for (const PathCovariance& c : block) sum += 0.5 * (double(c[0]) + double(c[3]));
    return absl::OkStatus();
  });
  if (!s.ok()) return s;
  return std::sqrt(std::max(0.0, sum / static_cast<double>(impl_->path_rows)));
}

absl::Status ScanReader::Impl::ValidatePathCov() const {
  if (!has_path_cov) return absl::OkStatus();
  constexpr std::array<int, 6> kDiagonal = {0, 3, 5, 6, 9, 11};  // xx yy zz of both blocks
  return ForEachPathCovBlock([&](uint64_t first, std::span<const PathCovariance> block) {
    for (size_t k = 0; k < block.size(); ++k) {
      const uint64_t i = first + k;
      const PathCovariance& c = block[k];
      if (!std::all_of(c.begin(), c.end(), [](float v) { return std::isfinite(v); })) {
        return RowError(file, "/path_cov", i, "non-finite value");
      }
      for (int d : kDiagonal) {
        if (c[d] < 0) {
          return RowError(file, "/path_cov", i,
                          absl::StrCat("negative variance ", c[d], " in column ", d));
        }
      }
    }
    return absl::OkStatus();
  });
}

absl::Status ScanReader::Impl::ValidateMagnetometer() const {
  if (!has_magnetometer) return absl::OkStatus();
  auto dataset = OpenDataset("/magnetometer");
  if (!dataset.ok()) return dataset.status();
  Hid mem = h5::MagnetometerMemType();
  std::vector<MagnetometerRecord> block;
  for (uint64_t first = 0; first < magnetometer_rows; first += block.size()) {
    block.resize(std::min(kPathBlockRows, magnetometer_rows - first));
    if (absl::Status s =
            h5::ReadRows(dataset->get(), mem.get(), 0, first, block.size(), block.data());
        !s.ok()) {
      return h5::Prefixed(absl::StrCat(file, ": /magnetometer"), s);
    }
    for (size_t k = 0; k < block.size(); ++k) {
      const MagnetometerRecord& m = block[k];
      const std::array<double, 4> values = {m.t, m.mx, m.my, m.mz};
      if (!AllFinite(values)) {
        return RowError(file, "/magnetometer", first + k, "non-finite value");
      }
    }
  }
  return absl::OkStatus();
}

absl::Status ScanReader::Impl::ValidateFrames(const SensorData& s, size_t block_rows) const {
  absl::StatusOr<PathRecord> first_pose = PathRow(0);
  if (!first_pose.ok()) return first_pose.status();
  absl::StatusOr<PathRecord> last_pose = PathRow(path_rows - 1);
  if (!last_pose.ok()) return last_pose.status();
  const double t_begin = first_pose->t;
  const double t_end = last_pose->t;
  const std::string dataset = s.frames_path();
  std::vector<FrameRecord> block;
  double previous_t = 0;
  for (uint64_t first = 0; first < s.frame_count; first += block.size()) {
    const uint64_t n = std::min<uint64_t>(block_rows, s.frame_count - first);
    if (absl::Status st = s.ReadFrameRows(first, n, block); !st.ok()) return st;
    for (uint64_t k = 0; k < n; ++k) {
      const uint64_t row = first + k;
      const FrameRecord& f = block[k];
      if (!std::isfinite(f.t)) return RowError(file, dataset, row, "non-finite time");
      if (row > 0 && !(f.t > previous_t)) {
        return RowError(
            file, dataset, row,
            absl::StrCat("time ", f.t, " is not after row ", row - 1, "'s ", previous_t));
      }
      previous_t = f.t;
      if (absl::Status st = s.CheckFrameRange(row, f); !st.ok()) return st;
      if (s.info.kind == SensorKind::kGrid &&
          f.count != static_cast<uint64_t>(s.info.rows) * s.info.cols) {
        return RowError(file, dataset, row,
                        absl::StrCat("grid frame has ", f.count, " rays, expected ", s.info.rows,
                                     "x", s.info.cols));
      }
      if (f.t < t_begin || f.t > t_end) {
        return RowError(file, dataset, row,
                        absl::StrCat("time ", f.t, " is outside the path's time span [", t_begin,
                                     ", ", t_end, "]: no pose to interpolate"));
      }
    }
  }
  return absl::OkStatus();
}

absl::Status ScanReader::Impl::ValidatePoints(const SensorData& s, size_t block_rows) const {
  std::vector<Eigen::Vector3f> block;
  for (uint64_t first = 0; first < s.point_count; first += block.size()) {
    const uint64_t n = std::min<uint64_t>(block_rows, s.point_count - first);
    if (absl::Status st = s.ReadPoints(first, n, block); !st.ok()) return st;
    for (uint64_t k = 0; k < n; ++k) {
      const Eigen::Vector3f& p = block[k];
      if (p.allFinite() || p.array().isNaN().all()) continue;  // all-NaN: no return
      return RowError(file, s.points_path(), first + k,
                      absl::StrCat("point (", p.x(), ", ", p.y(), ", ", p.z(),
                                   ") is partly non-finite (a no-return row is all NaN)"));
    }
  }
  return absl::OkStatus();
}

absl::Status ScanReader::Validate() {
  constexpr size_t kBlockBytes = 4 << 20;
  const Impl& r = *impl_;
  absl::Status s = r.ValidatePath();
  if (s.ok()) s = r.ValidatePathCov();
  if (s.ok()) s = r.ValidateMagnetometer();
  for (const SensorData& sensor : r.sensor_data) {
    if (s.ok()) s = r.ValidateFrames(sensor, kBlockBytes / sizeof(FrameRecord));
    if (s.ok()) s = r.ValidatePoints(sensor, kBlockBytes / sizeof(Eigen::Vector3f));
  }
  return s;
}

}  // namespace carvemap
