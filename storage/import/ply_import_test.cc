#include "storage/import/ply_import.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include "storage/import/import_writer.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

using ::testing::HasSubstr;

std::string WriteTemp(const std::string& name, const std::string& bytes) {
  const std::string path = (std::filesystem::path(::testing::TempDir()) / name).string();
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

// One row: world point, sensor origin, time.
struct Row {
  double x, y, z, ox, oy, oz, t;
};

// Two frames from origin (1,2,3), one from (0,0,5).
const std::vector<Row> kRows = {
    {2, 2, 3, 1, 2, 3, 0.5}, {1, 4, 3, 1, 2, 3, 0.5}, {1, 2, 2, 1, 2, 3, 0.5},
    {0, 0, 0, 0, 0, 5, 0.7}, {1, 1, 5, 0, 0, 5, 0.7},
};

std::string AsciiPly(const std::vector<Row>& rows, const std::string& origin_prefix,
                     bool with_time, bool with_face) {
  std::string s = "ply\nformat ascii 1.0\ncomment made by ply_import_test\n";
  s += "element vertex " + std::to_string(rows.size()) + "\n";
  s += "property float x\nproperty float y\nproperty float z\nproperty uchar red\n";
  for (const char* c : {"x", "y", "z"}) s += "property double " + origin_prefix + c + "\n";
  if (with_time) s += "property double time\n";
  if (with_face) s += "element face 1\nproperty list uchar int vertex_indices\n";
  s += "end_header\n";
  for (const Row& r : rows) {
    s += std::to_string(r.x) + " " + std::to_string(r.y) + " " + std::to_string(r.z) + " 255 " +
         std::to_string(r.ox) + " " + std::to_string(r.oy) + " " + std::to_string(r.oz);
    if (with_time) s += " " + std::to_string(r.t);
    s += "\n";
  }
  if (with_face) s += "3 0 1 2\n";
  return s;
}

template <typename T>
void Put(std::string& s, T v, bool big) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big != (std::endian::native == std::endian::big)) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

// A face element BEFORE the vertices, to check that it is skipped.
std::string BinaryPly(const std::vector<Row>& rows, bool big) {
  std::string s = "ply\nformat ";
  s += big ? "binary_big_endian" : "binary_little_endian";
  s += " 1.0\nelement face 1\nproperty list uchar int vertex_indices\n";
  s += "element vertex " + std::to_string(rows.size()) + "\n";
  s += "property double timestamp\nproperty float x\nproperty float y\nproperty float z\n";
  s += "property float vp_x\nproperty float vp_y\nproperty float vp_z\nend_header\n";
  Put<uint8_t>(s, 3, big);
  for (int i : {0, 1, 2}) Put<int32_t>(s, i, big);
  for (const Row& r : rows) {
    Put<double>(s, r.t, big);
    for (double v : {r.x, r.y, r.z, r.ox, r.oy, r.oz}) Put<float>(s, float(v), big);
  }
  return s;
}

void ExpectFrames(const ImportedScan& scan, bool times) {
  ASSERT_EQ(scan.frames.size(), 2u);
  ASSERT_EQ(scan.path.size(), 2u);
  EXPECT_EQ(scan.point_count, 5u);
  EXPECT_EQ(scan.sensor.name, "ply");
  EXPECT_EQ(scan.sensor.kind, SensorKind::kPoints);
  EXPECT_EQ(scan.frames[0].points_sensor.size(), 3u);
  EXPECT_EQ(scan.frames[0].points_sensor[1], Eigen::Vector3f(0, 2, 0));  // (1,4,3) − (1,2,3)
  EXPECT_EQ(scan.frames[1].points_sensor[0], Eigen::Vector3f(0, 0, -5));
  EXPECT_DOUBLE_EQ(scan.frames[0].t, times ? 0.5 : 0.0);
  EXPECT_DOUBLE_EQ(scan.frames[1].t, times ? 0.7 : 1.0);
  const PathRecord& p = scan.path[0];
  EXPECT_EQ(p.t, scan.frames[0].t);
  EXPECT_EQ(Eigen::Vector3d(p.x, p.y, p.z), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(Eigen::Vector4d(p.qw, p.qx, p.qy, p.qz), Eigen::Vector4d(1, 0, 0, 0));
  EXPECT_EQ(scan.path[1].z, 5.0);
}

TEST(PlyImportTest, AsciiWithTimeAndFaces) {
  for (const char* prefix : {"sensor_", "origin_", "vp_"}) {
    auto scan = ImportPly(WriteTemp("a.ply", AsciiPly(kRows, prefix, true, true)));
    ASSERT_TRUE(scan.ok()) << prefix << ": " << scan.status();
    ExpectFrames(*scan, true);
  }
}

TEST(PlyImportTest, AsciiWithoutTimeUsesFrameIndex) {
  std::string ply = AsciiPly(kRows, "sensor_", false, false);
  auto scan = ImportPly(WriteTemp("b.ply", ply));
  ASSERT_TRUE(scan.ok()) << scan.status();
  ExpectFrames(*scan, false);
}

TEST(PlyImportTest, ShortOriginNames) {
  std::string ply = AsciiPly(kRows, "s", true, false);  // sx sy sz
  auto scan = ImportPly(WriteTemp("s.ply", ply));
  ASSERT_TRUE(scan.ok()) << scan.status();
  ExpectFrames(*scan, true);
}

TEST(PlyImportTest, BinaryLittleAndBigEndian) {
  for (bool big : {false, true}) {
    auto scan = ImportPly(WriteTemp("c.ply", BinaryPly(kRows, big)));
    ASSERT_TRUE(scan.ok()) << big << ": " << scan.status();
    ExpectFrames(*scan, true);
  }
}

TEST(PlyImportTest, SinkStreamsFrames) {
  std::vector<double> times;
  auto scan = ImportPly(WriteTemp("d.ply", BinaryPly(kRows, false)), {},
                        [&](double t, std::span<const Eigen::Vector3f>) {
                          times.push_back(t);
                          return absl::OkStatus();
                        });
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_TRUE(scan->frames.empty());
  EXPECT_EQ(times, (std::vector<double>{0.5, 0.7}));
  EXPECT_EQ(scan->frame_count, 2u);
}

TEST(PlyImportTest, MissingOriginIsNamed) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nproperty float sensor_x\nend_header\n1 2 3 4\n";
  const std::string path = WriteTemp("noorigin.ply", ply);
  auto scan = ImportPly(path);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr(path));
  EXPECT_THAT(scan.status().message(), HasSubstr("no sensor origin"));
  EXPECT_THAT(scan.status().message(), HasSubstr("sensor_x sensor_y sensor_z"));
}

TEST(PlyImportTest, TruncatedBinaryBodyIsNamed) {
  std::string ply = BinaryPly(kRows, false);
  // Declared 5 vertices; cutting one row's worth makes the count not fit.
  auto scan = ImportPly(WriteTemp("cut1.ply", ply.substr(0, ply.size() - 10)));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("truncated"));
  // ASCII: a row ends early.
  std::string ascii = AsciiPly(kRows, "sensor_", true, false);
  scan = ImportPly(WriteTemp("cut2.ply", ascii.substr(0, ascii.size() - 20)));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 4"));
}

TEST(PlyImportTest, AsciiRowWithWrongValueCountIsNamed) {
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nproperty float vp_x\nproperty float vp_y\nproperty float vp_z\n"
      "end_header\n";
  auto scan = ImportPly(WriteTemp("short.ply", head + "1 2 3 0 0 0\n1 2 3 0 0\n1 2 3 0 0 0\n"));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 1"));
  scan = ImportPly(WriteTemp("long.ply", head + "1 2 3 0 0 0 \r\n1 2 3 0 0 0 7\n1 2 3 0 0 0"));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 1"));
}

TEST(PlyImportTest, BadHeaderIsNamed) {
  auto scan = ImportPly(WriteTemp("h1.ply", "ply\nformat ascii 2.0\nend_header\n"));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("header line 2"));
  scan = ImportPly(WriteTemp("h2.ply", "PLY\n"));
  EXPECT_THAT(scan.status().message(), HasSubstr("not a PLY file"));
  scan = ImportPly(WriteTemp("h3.ply", "ply\nformat ascii 1.0\nelement vertex 3\n"));
  EXPECT_THAT(scan.status().message(), HasSubstr("no end_header"));
  scan = ImportPly(WriteTemp("h4.ply", "ply\nformat ascii 1.0\nproperty float x\nend_header\n"));
  EXPECT_THAT(scan.status().message(), HasSubstr("property before any element"));
}

TEST(PlyImportTest, NonFiniteValueIsNamed) {
  std::vector<Row> rows = kRows;
  rows[3].x = std::numeric_limits<double>::quiet_NaN();
  auto scan = ImportPly(WriteTemp("nan.ply", BinaryPly(rows, false)));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 3: non-finite"));
}

// Found by tests/fuzz (ply_import): a finite double beyond float range became ±inf in the f32
// points, so the import "succeeded" with a scan that fails validation.
TEST(PlyImportTest, PointBeyondFloatRangeIsNamed) {
  std::vector<Row> rows = kRows;
  rows[2].z = 1e39;  // finite as double, not as float (the binary file keeps x y z as float)
  auto scan = ImportPly(WriteTemp("far.ply", AsciiPly(rows, "sensor_", true, false)));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 2: point minus sensor origin"));
  rows = kRows;
  rows[4].ox = -4e38;  // the origin far out: the point relative to it overflows
  rows[3].ox = -4e38;
  scan = ImportPly(WriteTemp("far_origin.ply", AsciiPly(rows, "sensor_", true, false)));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 3: point minus sensor origin"));
}

// Found with the fuzz target (ply_import): an element without properties holds no bytes, so
// skipping its 10^14 rows before the vertices looped 10^14 times (a hang).
TEST(PlyImportTest, ElementWithoutPropertiesIsSkippedAtOnce) {
  for (const std::string format : {"ascii", "binary_little_endian"}) {
    std::string ply = "ply\nformat " + format + " 1.0\nelement empty 100000000000000\n";
    ply += "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
    ply += "property float sx\nproperty float sy\nproperty float sz\nend_header\n";
    if (format == "ascii") {
      ply += "1 2 3 0 0 1\n";
    } else {
      for (float v : {1.0f, 2.0f, 3.0f, 0.0f, 0.0f, 1.0f}) Put<float>(ply, v, false);
    }
    auto scan = ImportPly(WriteTemp("empty_element.ply", ply));
    ASSERT_TRUE(scan.ok()) << scan.status();
    ASSERT_EQ(scan->frames.size(), 1u);
    EXPECT_EQ(scan->frames[0].points_sensor[0], Eigen::Vector3f(1, 2, 2));
  }
}

// Found by tests/fuzz (ply_import, UBSan): a list counted by a float read 3.8e19 as its count
// and converted it to an integer byte count (undefined behaviour).
TEST(PlyImportTest, FloatListCountIsAnError) {
  const std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement face 1\n"
      "property list float int vertex_indices\nelement vertex 0\nend_header\n";
  auto scan = ImportPly(WriteTemp("float_count.ply", ply));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(),
              HasSubstr("header line 4 'property list float int vertex_indices': a list's count "
                        "type must be an integer type"));
}

TEST(PlyImportTest, TimeGoingBackIsAnError) {
  std::vector<Row> rows = kRows;
  rows[3].t = rows[4].t = 0.5;  // a different origin at the same time
  auto scan = ImportPly(WriteTemp("time.ply", BinaryPly(rows, false)));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("vertex row 3"));
  EXPECT_THAT(scan.status().message(), HasSubstr("times must increase"));
}

TEST(PlyImportTest, WritesAScanThatValidates) {
  for (bool ascii : {true, false}) {
    const std::string in = WriteTemp("w.ply", ascii ? AsciiPly(kRows, "sensor_", false, true)
                                                  : BinaryPly(kRows, false));
    const std::string out = (std::filesystem::path(::testing::TempDir()) / "ply.h5").string();
    auto summary = WriteImport(out, PlySensor(), [&](const FrameSink& sink) {
      return ImportPly(in, {}, sink);
    });
    ASSERT_TRUE(summary.ok()) << summary.status();
    auto reader = ScanReader::Open(out);
    ASSERT_TRUE(reader.ok()) << reader.status();
    ASSERT_TRUE((*reader)->Validate().ok()) << (*reader)->Validate();
    EXPECT_EQ((*reader)->frame_count(0), 2u);
    EXPECT_EQ((*reader)->point_count(0), 5u);
    // The world point comes back as pose(t) × sensor point.
    auto frame = (*reader)->ReadFrame(0, 1);
    ASSERT_TRUE(frame.ok()) << frame.status();
    const Pose pose = (*reader)->PoseAt(frame->t);
    EXPECT_TRUE((pose * frame->points_sensor[1].cast<double>()).isApprox(Eigen::Vector3d(1, 1, 5)));
  }
}

}  // namespace
}  // namespace carvemap
