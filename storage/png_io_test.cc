// PNG input: the real floor maps and depth images read; a header declaring more pixels than
// the file can hold is a clear error, not an allocation.
#include "storage/png_io.h"

#include <zlib.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using ::testing::HasSubstr;

const std::string kData = std::string(CARVEMAP_TEST_DATA_DIR);

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(PngIoTest, RealFloorMapsAndDepthImagesRead) {
  int maps = 0, depths = 0;
  for (const auto& e : std::filesystem::directory_iterator(kData + "/floormaps")) {
    auto image = ReadPngGray8(e.path().string());
    ASSERT_TRUE(image.ok()) << image.status();
    EXPECT_EQ(image->pixels.size(), size_t(image->width) * image->height);
    ++maps;
  }
  for (const auto& e : std::filesystem::directory_iterator(kData + "/tum_fr2_pioneer_slam2/depth")) {
    auto image = ReadPngGray16(e.path().string());
    ASSERT_TRUE(image.ok()) << image.status();
    EXPECT_EQ(image->width, 640);
    EXPECT_EQ(image->height, 480);
    ++depths;
  }
  EXPECT_EQ(maps, 27);
  EXPECT_EQ(depths, 10);
}

TEST(PngIoTest, WriteThenReadGray8) {
  Image<uint8_t> img;
  img.width = 5;
  img.height = 3;
  for (int i = 0; i < 15; ++i) img.pixels.push_back(static_cast<uint8_t>(17 * i));
  const std::string path = testing::TempDir() + "/gray.png";
  ASSERT_TRUE(WritePngGray8(path, img).ok());
  auto back = ReadPngGray8(path);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->pixels, img.pixels);
}

// Found by tests/fuzz (png): a 100-byte PNG whose header declares 524352 × 2081 16-bit pixels
// made ReadPngGray16 allocate 2 GB (and ReadPngGray8 1 GB) before libpng found the data missing.
TEST(PngIoTest, HeaderDeclaringMorePixelsThanTheFileHoldsIsAnError) {
  Image<uint8_t> img;
  img.width = 4;
  img.height = 4;
  img.pixels.assign(16, 200);
  const std::string path = testing::TempDir() + "/huge.png";
  ASSERT_TRUE(WritePngGray8(path, img).ok());
  std::string bytes = ReadAll(path);
  // IHDR is the first chunk: length, "IHDR", width, height, bit depth, colour type, ... CRC.
  ASSERT_EQ(bytes.substr(12, 4), "IHDR");
  auto put32 = [&bytes](size_t at, uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>(v >> (24 - 8 * i));
  };
  put32(16, 524352);  // width
  put32(20, 2081);    // height
  for (int bit_depth : {8, 16}) {
    bytes[24] = static_cast<char>(bit_depth);
    put32(29, static_cast<uint32_t>(
                  crc32(0, reinterpret_cast<const Bytef*>(bytes.data() + 12), 17)));
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
    const absl::Status s8 = ReadPngGray8(path).status();
    EXPECT_EQ(s8.code(), absl::StatusCode::kInvalidArgument) << s8;
    EXPECT_THAT(s8.message(), HasSubstr(path + ": PNG declares 524352×2081 pixels"));
    if (bit_depth == 16) {
      const absl::Status s16 = ReadPngGray16(path).status();
      EXPECT_EQ(s16.code(), absl::StatusCode::kInvalidArgument) << s16;
      EXPECT_THAT(s16.message(), HasSubstr("more than its " + std::to_string(bytes.size()) +
                                           " bytes can hold"));
    }
  }
}

}  // namespace
}  // namespace carvemap
