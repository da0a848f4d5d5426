// ScanReader::Open and Validate on bad files: each test writes a good scan, corrupts one thing
// with raw HDF5 calls (or truncates the bytes), and checks that the error names the file, the
// dataset and the row. A file from a "foreign" writer (padded, reordered compounds, other
// numeric widths, fixed- and variable-length strings) must open fine.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "storage/h5_util.h"
#include "storage/scan_reader.h"
#include "storage/scan_writer.h"

namespace carvemap {
namespace {

using h5::Hid;
using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

std::string TempPath(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string test = std::string(info->test_suite_name()) + "." + info->name();
  std::replace(test.begin(), test.end(), '/', '_');
  const std::string dir = ::testing::TempDir() + "carvemap_scan_validate_test/" + test;
  std::filesystem::create_directories(dir);
  return dir + "/" + name;
}

SensorInfo Sensor(const std::string& name, SensorKind kind, uint32_t rows = 0, uint32_t cols = 0) {
  SensorInfo info;
  info.name = name;
  info.kind = kind;
  info.rows = rows;
  info.cols = cols;
  return info;
}

std::vector<Eigen::Vector3f> Points(int n) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < n; ++i) points.emplace_back(1.0f + i, 2.0f, 3.0f);
  return points;
}

// A valid scan: 11 poses over [0, 10] s with covariances, a magnetometer, and sensors h0
// (line, 4 frames of 3 rays), cam (grid 2x2, 2 frames) and cloud (points, 2 frames).
std::string WriteGoodScan() {
  const std::string path = TempPath("scan.h5");
  auto writer = ScanWriter::Create(path);
  EXPECT_TRUE(writer.ok()) << writer.status();
  ScanWriter& w = **writer;
  std::vector<PathRecord> poses;
  std::vector<PathCovariance> cov;
  for (int i = 0; i <= 10; ++i) {
    poses.push_back({double(i), double(i), 0, 1, 1, 0, 0, 0});
    PathCovariance c{};
    for (int d : {0, 3, 5, 6, 9, 11}) c[d] = 0.01f;
    cov.push_back(c);
  }
  EXPECT_TRUE(w.AppendPath(poses, cov).ok());
  const int h0 = *w.AddSensor(Sensor("h0", SensorKind::kLine));
  const int cam = *w.AddSensor(Sensor("cam", SensorKind::kGrid, 2, 2));
  const int cloud = *w.AddSensor(Sensor("cloud", SensorKind::kPoints));
  for (int i = 0; i < 4; ++i) {
    std::vector<Eigen::Vector3f> pts = Points(3);
    if (i == 1) pts[1] = Eigen::Vector3f(kNaN, kNaN, kNaN);  // no return: valid
    EXPECT_TRUE(w.AppendFrame(h0, 1.0 + i, pts).ok());
  }
  EXPECT_TRUE(w.AppendFrame(cam, 1.5, Points(4)).ok());
  EXPECT_TRUE(w.AppendFrame(cam, 2.5, Points(4)).ok());
  EXPECT_TRUE(w.AppendFrame(cloud, 2.0, Points(5)).ok());
  EXPECT_TRUE(w.AppendFrame(cloud, 3.0, Points(2)).ok());
  const std::vector<MagnetometerRecord> mag = {{0, 1, 2, 3}, {1, 1, 2, 3}, {2, 1, 2, 3}};
  EXPECT_TRUE(w.AppendMagnetometer(mag).ok());
  EXPECT_TRUE(w.Close().ok());
  return path;
}

Hid OpenForWrite(const std::string& path) {
  h5::Init();
  Hid file(H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT));
  EXPECT_TRUE(file.valid()) << h5::TakeErrorStack();
  return file;
}

// Reads row `row` of `dataset`, lets `edit` change it, writes it back.
template <typename T>
void EditRow(const std::string& path, const char* dataset, hid_t mem_type, hsize_t cols,
             uint64_t row, const std::function<void(T&)>& edit) {
  Hid file = OpenForWrite(path);
  Hid dset(H5Dopen2(file.get(), dataset, H5P_DEFAULT));
  ASSERT_TRUE(dset.valid()) << dataset;
  T value;
  ASSERT_TRUE(h5::ReadRows(dset.get(), mem_type, cols, row, 1, &value).ok());
  edit(value);
  ASSERT_TRUE(h5::WriteRows(dset.get(), mem_type, cols, row, 1, &value).ok());
}

void EditPath(const std::string& path, uint64_t row, const std::function<void(PathRecord&)>& f) {
  Hid mem = h5::PathMemType();
  EditRow<PathRecord>(path, "/path", mem.get(), 0, row, f);
}

void EditFrame(const std::string& path, const char* dataset, uint64_t row,
               const std::function<void(FrameRecord&)>& f) {
  Hid mem = h5::FrameMemType();
  EditRow<FrameRecord>(path, dataset, mem.get(), 0, row, f);
}

void ReplaceAttr(hid_t obj, const char* name, const std::function<void()>& write) {
  if (h5::HasAttr(obj, name)) H5Adelete(obj, name);
  write();
}

// Open's error, else Validate's.
// Validate reads the path's tables in blocks whatever Open kept of them: holding the whole
// path or none of it, the same verdict.
absl::Status OpenAndValidate(const std::string& path) {
  absl::Status verdicts[2];
  for (int i = 0; i < 2; ++i) {
    ScanReader::OpenOptions options;
    options.path_rows = i == 0 ? ScanReader::PathRows::kAll : ScanReader::PathRows::kNone;
    auto reader = ScanReader::Open(path, options);
    verdicts[i] = reader.ok() ? (*reader)->Validate() : reader.status();
  }
  EXPECT_EQ(verdicts[0].ToString(), verdicts[1].ToString());
  return verdicts[0];
}

MATCHER_P3(ErrorNaming, file, dataset_row, detail, "") {
  const std::string message(arg.message());
  *result_listener << "status: " << arg;
  return !arg.ok() && message.find(file) != std::string::npos &&
         message.find(dataset_row) != std::string::npos &&
         message.find(detail) != std::string::npos;
}

TEST(ScanValidateTest, GoodScanIsValid) {
  const std::string path = WriteGoodScan();
  EXPECT_TRUE(OpenAndValidate(path).ok()) << OpenAndValidate(path);
}

// --- Structure (Open) ----------------------------------------------------------------------

TEST(ScanValidateTest, TruncatedFile) {
  const std::string path = WriteGoodScan();
  std::filesystem::resize_file(path, std::filesystem::file_size(path) / 2);
  const absl::Status s = ScanReader::Open(path).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(s, ErrorNaming(path, ":", "truncated or corrupt"));
}

TEST(ScanValidateTest, NotHdf5) {
  const std::string path = TempPath("scan.h5");
  std::ofstream(path) << "t,x,y,z\n0,1,2,3\n";
  EXPECT_THAT(ScanReader::Open(path).status(), ErrorNaming(path, "not an HDF5 file", ""));
}

TEST(ScanValidateTest, WrongFormatName) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    ReplaceAttr(file.get(), "format",
                [&] { (void)h5::WriteStringAttr(file.get(), "format", "x"); });
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/: format is 'x'", "expected 'carvemap-scan'"));
}

TEST(ScanValidateTest, MissingFormat) {
  const std::string path = WriteGoodScan();
  H5Adelete(OpenForWrite(path).get(), "format");
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/", "missing attribute 'format'"));
}

TEST(ScanValidateTest, UnknownVersion) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    ReplaceAttr(file.get(), "version", [&] { (void)h5::WriteIntAttr(file.get(), "version", 2); });
  }
  EXPECT_THAT(ScanReader::Open(path).status(), ErrorNaming(path, "", "unknown format version 2"));
}

TEST(ScanValidateTest, VersionMustBeAnInteger) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    ReplaceAttr(file.get(), "version",
                [&] { (void)h5::WriteDoubleAttr(file.get(), "version", 1.0); });
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/", "attribute 'version' is not a single integer"));
}

TEST(ScanValidateTest, MissingPath) {
  const std::string path = WriteGoodScan();
  H5Ldelete(OpenForWrite(path).get(), "/path", H5P_DEFAULT);
  EXPECT_THAT(ScanReader::Open(path).status(), ErrorNaming(path, "/path", "missing"));
}

TEST(ScanValidateTest, PathMissingField) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    H5Ldelete(file.get(), "/path", H5P_DEFAULT);
    // t, x, y, z, qw, qx, qy: no qz.
    Hid type = h5::MakeCompound(sizeof(PathRecord), h5::PathFields().first(7));
    ASSERT_TRUE(h5::CreateRows(file.get(), "path", type.get(), 0, 16).ok());
  }
  EXPECT_THAT(ScanReader::Open(path).status(), ErrorNaming(path, "/path", "missing field 'qz'"));
}

TEST(ScanValidateTest, SensorMissingAttribute) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    Hid group(H5Gopen2(file.get(), "/sensors/cam", H5P_DEFAULT));
    H5Adelete(group.get(), "rows");
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/sensors/cam", "missing attribute 'rows'"));
}

TEST(ScanValidateTest, SensorAttributeWrongShape) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    Hid group(H5Gopen2(file.get(), "/sensors/h0", H5P_DEFAULT));
    const std::vector<double> four = {1, 2, 3, 4};
    ReplaceAttr(group.get(), "T_s2c",
                [&] { (void)h5::WriteDoublesAttr(group.get(), "T_s2c", four); });
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/sensors/h0", "attribute 'T_s2c' must hold 3 numbers"));
}

// Mounting and noise parameters §3 rules out: each named with the sensor's group.
TEST(ScanValidateTest, SensorParametersOutOfRange) {
  const struct {
    const char* attr;
    std::vector<double> values;
    const char* detail;
  } cases[] = {
      {"R_s2c", {2, 0, 0, 0, 2, 0, 0, 0, 2}, "R_s2c is not a rotation"},
      {"R_s2c", {1, 0, 0, 0, 1, 0, 0, 0, -1}, "R_s2c is not a rotation"},  // a reflection
      {"R_s2c", {std::nan(""), 0, 0, 0, 1, 0, 0, 0, 1}, "non-finite"},
      {"sigma_t", {-0.001}, "must not be negative"},
      {"range_sigma", {0.01, -0.001}, "must not be negative"},
      {"max_range", {0}, "max_range must be > 0 m"},
  };
  for (const auto& c : cases) {
    const std::string path = WriteGoodScan();
    {
      Hid file = OpenForWrite(path);
      Hid group(H5Gopen2(file.get(), "/sensors/h0", H5P_DEFAULT));
      ReplaceAttr(group.get(), c.attr,
                  [&] { (void)h5::WriteDoublesAttr(group.get(), c.attr, c.values); });
    }
    EXPECT_THAT(ScanReader::Open(path).status(), ErrorNaming(path, "/sensors/h0", c.detail))
        << c.attr;
  }
}

TEST(ScanValidateTest, UnknownSensorKind) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    Hid group(H5Gopen2(file.get(), "/sensors/h0", H5P_DEFAULT));
    ReplaceAttr(group.get(), "kind",
                [&] { (void)h5::WriteStringAttr(group.get(), "kind", "sonar"); });
  }
  EXPECT_THAT(ScanReader::Open(path).status(), ErrorNaming(path, "/sensors/h0", "'sonar'"));
}

TEST(ScanValidateTest, PointsWrongShape) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    H5Ldelete(file.get(), "/sensors/cloud/points", H5P_DEFAULT);
    Hid group(H5Gopen2(file.get(), "/sensors/cloud", H5P_DEFAULT));
    ASSERT_TRUE(h5::CreateRows(group.get(), "points", H5T_IEEE_F32LE, 2, 16).ok());
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/sensors/cloud/points", "expected [N][3]"));
}

TEST(ScanValidateTest, FramesNotCompound) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    H5Ldelete(file.get(), "/sensors/h0/frames", H5P_DEFAULT);
    Hid group(H5Gopen2(file.get(), "/sensors/h0", H5P_DEFAULT));
    ASSERT_TRUE(h5::CreateRows(group.get(), "frames", H5T_IEEE_F64LE, 0, 16).ok());
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/sensors/h0/frames", "not a compound"));
}

TEST(ScanValidateTest, PathCovWrongRows) {
  const std::string path = WriteGoodScan();
  {
    Hid file = OpenForWrite(path);
    Hid dset(H5Dopen2(file.get(), "/path_cov", H5P_DEFAULT));
    const hsize_t dims[2] = {7, 12};
    H5Dset_extent(dset.get(), dims);
  }
  EXPECT_THAT(ScanReader::Open(path).status(),
              ErrorNaming(path, "/path_cov", "7 rows, but /path has 11"));
}

// --- Rows (Validate) -----------------------------------------------------------------------

TEST(ScanValidateTest, PathNonFinite) {
  const std::string path = WriteGoodScan();
  EditPath(path, 3, [](PathRecord& p) { p.y = kInf; });
  EXPECT_THAT(OpenAndValidate(path), ErrorNaming(path, "/path row 3", "non-finite"));
}

TEST(ScanValidateTest, PathTimeNotAscending) {
  const std::string path = WriteGoodScan();
  EditPath(path, 4, [](PathRecord& p) { p.t = 3.0; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/path row 4", "time 3 is not after row 3's 3"));
}

TEST(ScanValidateTest, NonUnitQuaternion) {
  const std::string path = WriteGoodScan();
  EditPath(path, 5, [](PathRecord& p) { p.qw = 0.93; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/path row 5", "non-unit quaternion (norm 0.93)"));
}

TEST(ScanValidateTest, PathCovNonFinite) {
  const std::string path = WriteGoodScan();
  EditRow<PathCovariance>(path, "/path_cov", H5T_NATIVE_FLOAT, 12, 2,
                          [](PathCovariance& c) { c[1] = kNaN; });
  EXPECT_THAT(OpenAndValidate(path), ErrorNaming(path, "/path_cov row 2", "non-finite"));
}

TEST(ScanValidateTest, PathCovNegativeVariance) {
  const std::string path = WriteGoodScan();
  EditRow<PathCovariance>(path, "/path_cov", H5T_NATIVE_FLOAT, 12, 6,
                          [](PathCovariance& c) { c[9] = -0.5f; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/path_cov row 6", "negative variance -0.5 in column 9"));
}

TEST(ScanValidateTest, FrameTimesEqual) {
  const std::string path = WriteGoodScan();
  EditFrame(path, "/sensors/h0/frames", 2, [](FrameRecord& f) { f.t = 2.0; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/sensors/h0/frames row 2", "time 2 is not after row 1's 2"));
}

TEST(ScanValidateTest, FrameRangeOutsidePoints) {
  const std::string path = WriteGoodScan();
  EditFrame(path, "/sensors/cloud/frames", 1, [](FrameRecord& f) { f.count = 9; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/sensors/cloud/frames row 1",
                          "rays [5, 14) outside /sensors/cloud/points (7 rows)"));
  // Streaming and random access report it too, instead of reading past the end.
  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_THAT((*reader)->ReadFrame(2, 1).status(),
              ErrorNaming(path, "/sensors/cloud/frames row 1", "outside"));
  auto stream = (*reader)->StreamFrames();
  ScanFrame frame;
  absl::StatusOr<bool> more;
  while ((more = stream->Next(frame)).ok() && *more) {
  }
  EXPECT_THAT(more.status(), ErrorNaming(path, "/sensors/cloud/frames row 1", "outside"));
}

// Found by tests/fuzz (scan_reader): HDF5 reads rows that were never written as fill values,
// so a small file can declare 2^40 rows. Open allocated the whole of /path (bad_alloc), and
// Validate would have streamed through 2^40 points. Datasets ScanWriter made extendible show
// it with one H5Dset_extent, which allocates nothing.
TEST(ScanValidateTest, RowsDeclaredButNeverWritten) {
  for (const char* dataset : {"/path", "/path_cov", "/magnetometer", "/sensors/h0/frames",
                              "/sensors/cloud/points"}) {
    SCOPED_TRACE(dataset);
    const std::string path = WriteGoodScan();
    {
      Hid file = OpenForWrite(path);
      Hid dset(H5Dopen2(file.get(), dataset, H5P_DEFAULT));
      ASSERT_TRUE(dset.valid());
      auto dims = h5::Dims(dset.get());
      ASSERT_TRUE(dims.ok());
      (*dims)[0] = uint64_t{1} << 40;
      ASSERT_GE(H5Dset_extent(dset.get(), dims->data()), 0);
    }
    EXPECT_THAT(OpenAndValidate(path),
                ErrorNaming(path, dataset, "declares 1099511627776 rows"));
  }
}

TEST(ScanValidateTest, GridFrameWrongCount) {
  const std::string path = WriteGoodScan();
  EditFrame(path, "/sensors/cam/frames", 1, [](FrameRecord& f) { f.count = 3; });
  EXPECT_THAT(OpenAndValidate(path), ErrorNaming(path, "/sensors/cam/frames row 1",
                                                 "grid frame has 3 rays, expected 2x2"));
}

TEST(ScanValidateTest, FrameOutsidePathTimeSpan) {
  const std::string path = WriteGoodScan();
  EditFrame(path, "/sensors/h0/frames", 3, [](FrameRecord& f) { f.t = 10.5; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/sensors/h0/frames row 3",
                          "time 10.5 is outside the path's time span [0, 10]"));
}

TEST(ScanValidateTest, PointPartlyNaN) {
  const std::string path = WriteGoodScan();
  EditRow<Eigen::Vector3f>(path, "/sensors/h0/points", H5T_NATIVE_FLOAT, 3, 7,
                           [](Eigen::Vector3f& p) { p.y() = kNaN; });
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/sensors/h0/points row 7", "partly non-finite"));
}

TEST(ScanValidateTest, PointInfinite) {
  const std::string path = WriteGoodScan();
  EditRow<Eigen::Vector3f>(
      path, "/sensors/cam/points", H5T_NATIVE_FLOAT, 3, 5,
      [](Eigen::Vector3f& p) { p.z() = std::numeric_limits<float>::infinity(); });
  EXPECT_THAT(OpenAndValidate(path), ErrorNaming(path, "/sensors/cam/points row 5", "non-finite"));
}

TEST(ScanValidateTest, MagnetometerNonFinite) {
  const std::string path = WriteGoodScan();
  Hid mem = h5::MagnetometerMemType();
  EditRow<MagnetometerRecord>(path, "/magnetometer", mem.get(), 0, 1,
                              [](MagnetometerRecord& m) { m.mz = kNaN; });
  EXPECT_THAT(OpenAndValidate(path), ErrorNaming(path, "/magnetometer row 1", "non-finite"));
}

// --- A foreign writer ----------------------------------------------------------------------

// Layouts another program (h5py, numpy structured arrays) might write: fields reordered,
// padded, other widths and byte orders.
struct ForeignPose {
  double qz;
  uint8_t flags;  // an extra field the reader ignores
  double t;
  float x, y;
  double z, qw, qx, qy;
};
struct ForeignFrame {
  int64_t count;
  float t;
  int32_t first;
};

void WriteFixedStringAttr(hid_t obj, const char* name, const std::string& value, H5T_str_t pad) {
  Hid type(H5Tcopy(H5T_C_S1));
  H5Tset_size(type.get(), value.size() + 3);
  H5Tset_strpad(type.get(), pad);
  std::string buffer = value + std::string(3, pad == H5T_STR_SPACEPAD ? ' ' : '\0');
  Hid space(H5Screate(H5S_SCALAR));
  Hid attr(H5Acreate2(obj, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT));
  H5Awrite(attr.get(), type.get(), buffer.data());
}

template <typename T>
void WriteAttrValues(hid_t obj, const char* name, hid_t file_type, hid_t mem_type,
                     std::vector<hsize_t> dims, const std::vector<T>& values) {
  Hid space(dims.empty() ? H5Screate(H5S_SCALAR)
                         : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr));
  Hid attr(H5Acreate2(obj, name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT));
  H5Awrite(attr.get(), mem_type, values.data());
}

void WriteDataset(hid_t loc, const char* name, hid_t type, std::vector<hsize_t> dims,
                  const void* data) {
  Hid space(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr));
  Hid dset(H5Dcreate2(loc, name, type, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  H5Dwrite(dset.get(), type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
}

void WriteForeignSensor(hid_t sensors, const char* name, const char* kind, bool vlen_kind,
                        const std::vector<ForeignFrame>& frames,
                        const std::vector<double>& points) {
  Hid group(H5Gcreate2(sensors, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  if (vlen_kind) {
    ASSERT_TRUE(h5::WriteStringAttr(group.get(), "kind", kind).ok());
  } else {
    WriteFixedStringAttr(group.get(), "kind", kind, H5T_STR_SPACEPAD);
  }
  // R as a 3x3 float32 matrix, T as int32, max_range as a one-element array.
  WriteAttrValues<float>(group.get(), "R_s2c", H5T_NATIVE_FLOAT, H5T_NATIVE_FLOAT, {3, 3},
                         {0, -1, 0, 1, 0, 0, 0, 0, 1});
  WriteAttrValues<int32_t>(group.get(), "T_s2c", H5T_STD_I32BE, H5T_NATIVE_INT32, {3}, {1, 2, 3});
  WriteAttrValues<double>(group.get(), "sigma_t", H5T_NATIVE_DOUBLE, H5T_NATIVE_DOUBLE, {},
                          {0.001});
  WriteAttrValues<double>(group.get(), "range_sigma", H5T_IEEE_F64BE, H5T_NATIVE_DOUBLE, {2},
                          {0.02, 0.001});
  WriteAttrValues<float>(group.get(), "max_range", H5T_NATIVE_FLOAT, H5T_NATIVE_FLOAT, {1}, {30});
  Hid frame_type(H5Tcreate(H5T_COMPOUND, sizeof(ForeignFrame)));
  H5Tinsert(frame_type.get(), "count", offsetof(ForeignFrame, count), H5T_NATIVE_INT64);
  H5Tinsert(frame_type.get(), "t", offsetof(ForeignFrame, t), H5T_NATIVE_FLOAT);
  H5Tinsert(frame_type.get(), "first", offsetof(ForeignFrame, first), H5T_NATIVE_INT32);
  WriteDataset(group.get(), "frames", frame_type.get(), {frames.size()}, frames.data());
  WriteDataset(group.get(), "points", H5T_NATIVE_DOUBLE, {points.size() / 3, 3}, points.data());
}

std::string WriteForeignScan() {
  h5::Init();
  const std::string path = TempPath("foreign.h5");
  Hid file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT));
  WriteFixedStringAttr(file.get(), "format", "carvemap-scan", H5T_STR_NULLPAD);
  WriteAttrValues<int32_t>(file.get(), "version", H5T_STD_I32BE, H5T_NATIVE_INT32, {}, {1});

  const std::vector<ForeignPose> poses = {{0, 7, 0.0, 1, 2, 3, 1, 0, 0},
                                          {0, 7, 2.0, 3, 2, 3, 1, 0, 0}};
  Hid pose_type(H5Tcreate(H5T_COMPOUND, sizeof(ForeignPose)));
  H5Tinsert(pose_type.get(), "qz", offsetof(ForeignPose, qz), H5T_NATIVE_DOUBLE);
  H5Tinsert(pose_type.get(), "flags", offsetof(ForeignPose, flags), H5T_NATIVE_UINT8);
  H5Tinsert(pose_type.get(), "t", offsetof(ForeignPose, t), H5T_NATIVE_DOUBLE);
  H5Tinsert(pose_type.get(), "x", offsetof(ForeignPose, x), H5T_NATIVE_FLOAT);
  H5Tinsert(pose_type.get(), "y", offsetof(ForeignPose, y), H5T_NATIVE_FLOAT);
  H5Tinsert(pose_type.get(), "z", offsetof(ForeignPose, z), H5T_NATIVE_DOUBLE);
  H5Tinsert(pose_type.get(), "qw", offsetof(ForeignPose, qw), H5T_NATIVE_DOUBLE);
  H5Tinsert(pose_type.get(), "qx", offsetof(ForeignPose, qx), H5T_NATIVE_DOUBLE);
  H5Tinsert(pose_type.get(), "qy", offsetof(ForeignPose, qy), H5T_NATIVE_DOUBLE);
  WriteDataset(file.get(), "path", pose_type.get(), {poses.size()}, poses.data());

  // No link creation order (h5py's default): sensors are listed by name.
  Hid sensors(H5Gcreate2(file.get(), "sensors", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  WriteForeignSensor(sensors.get(), "b_line", "line", /*vlen_kind=*/false,
                     {{2, 0.5f, 0}, {2, 1.5f, 2}}, {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12});
  WriteForeignSensor(sensors.get(), "a_points", "points", /*vlen_kind=*/true, {{1, 1.0f, 0}},
                     {-1, -2, -3});
  return path;
}

// A minimal scan with a 5-row contiguous /path (HDF5's oldest formats), for tests that damage
// bytes of its metadata as a bad disk or transfer would.
std::string WriteContiguousPathScan() {
  h5::Init();
  const std::string path = TempPath("contiguous.h5");
  Hid file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT));
  EXPECT_TRUE(h5::WriteStringAttr(file.get(), "format", "carvemap-scan").ok());
  EXPECT_TRUE(h5::WriteIntAttr(file.get(), "version", 1).ok());
  std::vector<PathRecord> poses;
  for (int i = 0; i < 5; ++i) poses.push_back({double(i), 0, 0, 0, 1, 0, 0, 0});
  Hid file_type = h5::PathFileType(), mem_type = h5::PathMemType();
  const hsize_t dims[1] = {5};
  Hid space(H5Screate_simple(1, dims, nullptr));
  Hid dset(H5Dcreate2(file.get(), "path", file_type.get(), space.get(), H5P_DEFAULT,
                      H5P_DEFAULT, H5P_DEFAULT));
  EXPECT_GE(H5Dwrite(dset.get(), mem_type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, poses.data()),
            0);
  return path;
}

// Replaces the one occurrence of `from` in the file's bytes by `to` (same length).
void PatchOnce(const std::string& path, const std::string& from, const std::string& to) {
  ASSERT_EQ(from.size(), to.size());
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const size_t at = bytes.find(from);
  ASSERT_NE(at, std::string::npos);
  ASSERT_EQ(bytes.find(from, at + 1), std::string::npos);
  bytes.replace(at, from.size(), to);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

std::string Bytes(std::initializer_list<int> b) {
  std::string s;
  for (int c : b) s.push_back(static_cast<char>(c));
  return s;
}

// Found by tests/fuzz (scan_reader_raw): a contiguous dataset is stored whole, but a damaged
// dataspace message can declare more rows than its storage holds; Open then asked for 2^48
// path rows.
TEST(ScanValidateTest, DamagedDataspaceDeclaringMoreThanStored) {
  const std::string path = WriteContiguousPathScan();
  ASSERT_TRUE(OpenAndValidate(path).ok()) << OpenAndValidate(path);
  // Dataspace message v1: version 1, rank 1, flags 1 (max dims follow), 5 reserved bytes,
  // then dims and max dims as 8-byte little-endian numbers: 5 rows ➜ 2^40.
  const std::string header = Bytes({1, 1, 1, 0, 0, 0, 0, 0});
  const std::string five = Bytes({5, 0, 0, 0, 0, 0, 0, 0}), huge = Bytes({0, 0, 0, 0, 0, 1, 0, 0});
  PatchOnce(path, header + five + five, header + huge + huge);
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/path", "declares 1099511627776 rows but stores 320 bytes"));
}

// Found by tests/fuzz (scan_reader_raw): HDF5 1.10 decodes a compound member's offset without
// checking it against the record size, then converts out of bounds (SEGV in
// H5T__conv_struct_opt). The reader checks the type first.
TEST(ScanValidateTest, DamagedCompoundMemberOffset) {
  const std::string path = WriteContiguousPathScan();
  // Compound member (datatype message v1): name padded to 8 bytes, then its u32 byte offset.
  PatchOnce(path, std::string("qy\0\0\0\0\0\0", 8) + Bytes({48, 0, 0, 0}),
            std::string("qy\0\0\0\0\0\0", 8) + Bytes({0x5f, 0x63, 0x6f, 0}));
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/path",
                          "field 'qy' (8 bytes at byte 7299935) lies outside the 64-byte record"));
}

// Found by tests/fuzz (scan_reader_raw): a float whose exponent overlaps its sign bit made
// HDF5's conversion copy bits out of bounds (SEGV in H5T__bit_copy).
TEST(ScanValidateTest, DamagedFloatFields) {
  const std::string path = WriteContiguousPathScan();
  // The first f64 of the file is /path's 't': offset 0, precision 64, exponent at bit 52 of
  // 11 bits, mantissa at 0 of 52, bias 1023. Move the exponent onto the sign bit.
  const std::string fields = Bytes({0, 0, 64, 0, 52, 11, 0, 52, 0xff, 3, 0, 0});
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const size_t at = bytes.find(fields);
  ASSERT_NE(at, std::string::npos);
  bytes[at + 4] = 53;
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  EXPECT_THAT(OpenAndValidate(path),
              ErrorNaming(path, "/path", "field 't': a float whose fields do not fit"));
}

TEST(ScanValidateTest, ForeignWriterOpens) {
  const std::string path = WriteForeignScan();
  auto reader = ScanReader::Open(path);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ScanReader& r = **reader;
  EXPECT_TRUE(r.Validate().ok()) << r.Validate();
  ASSERT_EQ(r.path().size(), 2u);
  EXPECT_EQ(r.path()[1].t, 2.0);
  EXPECT_EQ(r.path()[1].x, 3.0);
  EXPECT_EQ(r.path()[1].z, 3.0);
  EXPECT_EQ(r.path()[1].qw, 1.0);
  EXPECT_FALSE(r.path_covariance().has_value());
  EXPECT_FALSE(r.magnetometer().has_value());
  ASSERT_EQ(r.sensors().size(), 2u);
  EXPECT_EQ(r.sensors()[0].name, "a_points");
  EXPECT_EQ(r.sensors()[0].kind, SensorKind::kPoints);
  EXPECT_EQ(r.sensors()[1].kind, SensorKind::kLine);
  EXPECT_EQ(r.sensors()[1].R_s2c(0, 1), -1.0);
  EXPECT_EQ(r.sensors()[1].T_s2c, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(r.sensors()[1].range_sigma[0], 0.02);
  EXPECT_EQ(r.sensors()[1].max_range_m, 30.0);
  auto frame = r.ReadFrame(1, 1);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_EQ(frame->t, 1.5);
  ASSERT_EQ(frame->points_sensor.size(), 2u);
  EXPECT_EQ(frame->points_sensor[1], Eigen::Vector3f(10, 11, 12));
  // Merged stream: b_line 0.5, a_points 1.0, b_line 1.5.
  auto stream = r.StreamFrames();
  ScanFrame f;
  std::vector<int> sensors;
  while (*stream->Next(f)) sensors.push_back(f.sensor);
  EXPECT_EQ(sensors, (std::vector<int>{1, 0, 1}));
}

}  // namespace
}  // namespace carvemap
