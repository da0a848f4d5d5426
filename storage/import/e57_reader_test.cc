#include "storage/import/e57_reader.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "storage/crc32c.h"

namespace carvemap {
namespace {

// Three setups of a scanner in a box room, written by tests/tools/e57/make_e57.py, whose
// structure and points an independent reader from the npm registry (web-e57) agrees with;
// truth.json holds what the generator meant.
const std::string kDir = std::string(CARVEMAP_TEST_DATA_DIR) + "/e57";

nlohmann::json Truth() {
  std::ifstream in(kDir + "/truth.json");
  return nlohmann::json::parse(in);
}

std::vector<char> Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

std::string Write(const std::vector<char>& b, const std::string& name) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path, std::ios::binary).write(b.data(), static_cast<std::streamsize>(b.size()));
  return path;
}

// Sets the byte at physical offset `at` and gives its page a correct checksum again, so that
// only the byte's meaning is wrong.
void SetByte(std::vector<char>& b, uint64_t at, uint8_t value) {
  b[at] = static_cast<char>(value);
  const uint64_t page = at / 1024 * 1024;
  const uint32_t crc = Crc32c({b.data() + page, 1020});
  for (int i = 0; i < 4; ++i) b[page + 1020 + i] = static_cast<char>(crc >> (24 - 8 * i));
}

// A physical offset of the logical byte `logical`.
uint64_t Physical(uint64_t logical) { return logical / 1020 * 1024 + logical % 1020; }

class E57ReaderFixtures : public ::testing::TestWithParam<const char*> {};

TEST_P(E57ReaderFixtures, ScansPosesAndRecordCountsAsWritten) {
  const std::string file = kDir + "/" + GetParam();
  absl::StatusOr<E57Reader> reader = E57Reader::Open(file);
  ASSERT_TRUE(reader.ok()) << reader.status();
  EXPECT_EQ(reader->header().version_major, 1u);
  EXPECT_EQ(reader->header().page_size, 1024u);
  EXPECT_EQ(reader->header().file_length, Bytes(file).size());
  const nlohmann::json truth = Truth()["files"][GetParam()]["scans"];
  ASSERT_EQ(reader->scans().size(), truth.size());
  for (size_t i = 0; i < truth.size(); ++i) {
    const E57Scan& s = reader->scans()[i];
    const nlohmann::json& t = truth[i];
    EXPECT_EQ(s.name, t["name"].get<std::string>());
    EXPECT_EQ(s.guid, t["guid"].get<std::string>());
    EXPECT_EQ(s.record_count, t["records"].get<uint64_t>());
    const nlohmann::json& p = t["pose"];
    EXPECT_NEAR(s.translation.x(), p["translation"]["x"].get<double>(), 1e-9);
    EXPECT_NEAR(s.translation.y(), p["translation"]["y"].get<double>(), 1e-9);
    EXPECT_NEAR(s.translation.z(), p["translation"]["z"].get<double>(), 1e-9);
    EXPECT_NEAR(s.rotation.w(), p["rotation"]["w"].get<double>(), 1e-12);
    EXPECT_NEAR(s.rotation.x(), p["rotation"]["x"].get<double>(), 1e-12);
    EXPECT_NEAR(s.rotation.y(), p["rotation"]["y"].get<double>(), 1e-12);
    EXPECT_NEAR(s.rotation.z(), p["rotation"]["z"].get<double>(), 1e-12);
    const bool structured = t["structured"].get<bool>();
    EXPECT_EQ(s.FieldIndex("rowIndex") >= 0, structured);
    EXPECT_EQ(s.FieldIndex("columnIndex") >= 0, structured);
  }
}

INSTANTIATE_TEST_SUITE_P(Files, E57ReaderFixtures,
                         ::testing::Values("room_scaled.e57", "room_spherical.e57",
                                           "room_points.e57"));

TEST(E57Reader, PrototypeFieldsWithTheirEncodings) {
  absl::StatusOr<E57Reader> scaled = E57Reader::Open(kDir + "/room_scaled.e57");
  ASSERT_TRUE(scaled.ok()) << scaled.status();
  const E57Scan& a = scaled->scans()[0];
  const E57Field& x = a.prototype[static_cast<size_t>(a.FieldIndex("cartesianX"))];
  EXPECT_EQ(x.kind, E57Field::Kind::kScaledInteger);
  EXPECT_EQ(x.minimum, -200000);
  EXPECT_EQ(x.maximum, 200000);
  EXPECT_DOUBLE_EQ(x.scale, 1e-4);
  EXPECT_EQ(x.bits(), 19);  // ⌈log2(400001)⌉
  const E57Field& row = a.prototype[static_cast<size_t>(a.FieldIndex("rowIndex"))];
  EXPECT_EQ(row.kind, E57Field::Kind::kInteger);
  EXPECT_EQ(row.bits(), 7);  // 0–69
  const E57Field& intensity = a.prototype[static_cast<size_t>(a.FieldIndex("intensity"))];
  EXPECT_EQ(intensity.kind, E57Field::Kind::kFloat);
  EXPECT_EQ(intensity.bits(), 32);
  ASSERT_TRUE(a.index_bounds.has_value());
  EXPECT_EQ(a.index_bounds->row_max, 69);
  EXPECT_EQ(a.index_bounds->col_max, 159);

  absl::StatusOr<E57Reader> spherical = E57Reader::Open(kDir + "/room_spherical.e57");
  ASSERT_TRUE(spherical.ok()) << spherical.status();
  const E57Scan& b = spherical->scans()[0];
  EXPECT_FALSE(b.index_bounds.has_value());
  const E57Field& range = b.prototype[static_cast<size_t>(b.FieldIndex("sphericalRange"))];
  EXPECT_EQ(range.kind, E57Field::Kind::kFloat);
  EXPECT_EQ(range.bits(), 64);

  E57Field full;
  full.kind = E57Field::Kind::kInteger;
  full.minimum = std::numeric_limits<int64_t>::min();
  full.maximum = std::numeric_limits<int64_t>::max();
  EXPECT_EQ(full.bits(), 64);
  full.maximum = full.minimum;
  EXPECT_EQ(full.bits(), 0);  // a constant field takes no bits
}

// The records of one scan, every field, decoded in batches of `batch`.
std::vector<std::vector<double>> AllRecords(const E57Reader& reader, int scan, size_t batch) {
  const size_t n = reader.scans()[static_cast<size_t>(scan)].prototype.size();
  std::vector<int> fields;
  for (size_t i = 0; i < n; ++i) fields.push_back(static_cast<int>(i));
  std::vector<std::vector<double>> out(n);
  absl::Status s = reader.ReadRecords(
      scan, fields,
      [&](std::span<const std::vector<double>> c, size_t m) {
        EXPECT_LE(m, batch);
        for (size_t k = 0; k < n; ++k) out[k].insert(out[k].end(), c[k].begin(), c[k].begin() + m);
        return absl::OkStatus();
      },
      batch);
  EXPECT_TRUE(s.ok()) << s;
  return out;
}

TEST(E57Reader, RecordsAreTheSameInAnyBatchSizeAndHitTheRoom) {
  absl::StatusOr<E57Reader> reader = E57Reader::Open(kDir + "/room_scaled.e57");
  ASSERT_TRUE(reader.ok()) << reader.status();
  // Setup B's bit-packed values run across many small packets and pages.
  const std::vector<std::vector<double>> whole = AllRecords(*reader, 1, 65536);
  EXPECT_EQ(whole, AllRecords(*reader, 1, 7));
  const E57Scan& b = reader->scans()[1];
  ASSERT_EQ(whole[0].size(), b.record_count);
  const int x = b.FieldIndex("cartesianX"), state = b.FieldIndex("cartesianInvalidState");
  const int row = b.FieldIndex("rowIndex"), col = b.FieldIndex("columnIndex");
  const nlohmann::json truth = Truth();
  const nlohmann::json& room = truth["room_box"];
  int hits = 0;
  for (size_t j = 0; j < b.record_count; ++j) {
    EXPECT_GE(whole[static_cast<size_t>(row)][j], 0);
    EXPECT_LT(whole[static_cast<size_t>(col)][j], 160);
    if (whole[static_cast<size_t>(state)][j] != 0) continue;
    const Eigen::Vector3d local(whole[static_cast<size_t>(x)][j],
                                whole[static_cast<size_t>(x) + 1][j],
                                whole[static_cast<size_t>(x) + 2][j]);
    const Eigen::Vector3d p = b.rotation * local + b.translation;
    bool inside = true;
    for (int d = 0; d < 3; ++d) {
      inside = inside && p[d] > room["min"][d].get<double>() - 1e-3 &&
               p[d] < room["max"][d].get<double>() + 1e-3;
    }
    hits += inside;
  }
  EXPECT_EQ(hits, truth["files"]["room_scaled.e57"]["scans"][1]["returns"].get<int>());
}

TEST(E57Reader, DamagedFilesNameTheFileAndTheFault) {
  struct Case {
    const char* file;
    const char* says;
  };
  for (const Case& c :
       {Case{"bad_crc.e57", "CRC-32C is 0x"}, Case{"truncated.e57", "it is cut short"},
        Case{"bad_signature.e57", "not an E57 file"},
        Case{"bad_offset.e57", "points fileOffset"}}) {
    const std::string file = kDir + "/" + c.file;
    absl::StatusOr<E57Reader> reader = E57Reader::Open(file);
    absl::Status s = reader.status();
    if (reader.ok()) {  // damage past the XML shows when the records are read
      for (size_t i = 0; s.ok() && i < reader->scans().size(); ++i) {
        s = reader->ReadRecords(static_cast<int>(i), std::vector<int>{0},
                                [](auto, size_t) { return absl::OkStatus(); });
      }
    }
    ASSERT_FALSE(s.ok()) << c.file;
    EXPECT_NE(s.message().find(file), std::string::npos) << s;
    EXPECT_NE(s.message().find(c.says), std::string::npos) << s;
  }
  EXPECT_EQ(E57Reader::Open(kDir + "/none.e57").status().code(), absl::StatusCode::kNotFound);
}

TEST(E57Reader, PacketsAndSectionsWithWrongMeaningsAreNamed) {
  const std::string good = kDir + "/room_scaled.e57";
  absl::StatusOr<E57Reader> reader = E57Reader::Open(good);
  ASSERT_TRUE(reader.ok()) << reader.status();
  const uint64_t section = reader->scans()[0].section_offset;
  const std::vector<char> bytes = Bytes(good);
  uint64_t data = 0;
  for (int i = 0; i < 8; ++i) {
    data |= uint64_t{static_cast<uint8_t>(
                bytes[Physical(section / 1024 * 1020 + section % 1024 + 16 + i)])}
            << (8 * i);
  }
  const auto first_error = [](const std::string& file) {
    absl::StatusOr<E57Reader> r = E57Reader::Open(file);
    if (!r.ok()) return r.status();
    return r->ReadRecords(0, std::vector<int>{0}, [](auto, size_t) { return absl::OkStatus(); });
  };

  std::vector<char> b = bytes;
  SetByte(b, section, 0);  // a blob section's id
  absl::Status s = first_error(Write(b, "e57_section_id.e57"));
  EXPECT_NE(s.message().find("has id 0, not a compressed vector's"), std::string::npos) << s;

  b = bytes;
  SetByte(b, data, 7);  // the first data packet's type
  s = first_error(Write(b, "e57_packet_type.e57"));
  EXPECT_NE(s.message().find("the packet at byte " + std::to_string(data) + " has type 7"),
            std::string::npos)
      << s;

  b = bytes;
  SetByte(b, data + 4, 2);  // its byte-stream count
  s = first_error(Write(b, "e57_streams.e57"));
  EXPECT_NE(s.message().find("has 2 byte streams; the prototype has"), std::string::npos) << s;
  EXPECT_NE(s.message().find("data3D 0 (\"setup A\") points"), std::string::npos) << s;
}

}  // namespace
}  // namespace carvemap
