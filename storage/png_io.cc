#include "storage/png_io.h"

#include <png.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

struct FileCloser {
  void operator()(FILE* f) const {
    if (f) std::fclose(f);
  }
};
using File = std::unique_ptr<FILE, FileCloser>;

// The header alone can declare 10^6 × 10^6 pixels (libpng's default limits). Pixel data is
// deflated, deflate expands at most 1032:1, and a row is a filter byte and at least one bit a
// pixel, so a file of n bytes holds at most 1032·n bytes of rows: checked before allocating.
absl::Status CheckDeclaredSize(const std::string& path, uint64_t width, uint64_t height,
                               uint64_t bits_per_pixel) {
  std::error_code error;
  const uint64_t file_bytes = std::filesystem::file_size(path, error);
  const uint64_t row_bytes = 1 + (width * bits_per_pixel + 7) / 8;  // width < 2^31
  if (error || height > 1032 * file_bytes / row_bytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": PNG declares ", width, "×", height, " pixels, more than its ",
                     file_bytes, " bytes can hold"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<Image<uint8_t>> ReadPngGray8(const std::string& path) {
  // The simplified API converts every colour type and bit depth for us.
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str())) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a readable PNG: ", image.message));
  }
  // At least one bit per pixel (1-bit gray and palettes).
  if (absl::Status s = CheckDeclaredSize(path, image.width, image.height, 1); !s.ok()) {
    png_image_free(&image);
    return s;
  }
  image.format = PNG_FORMAT_GRAY;
  Image<uint8_t> out;
  out.width = static_cast<int>(image.width);
  out.height = static_cast<int>(image.height);
  out.pixels.resize(PNG_IMAGE_SIZE(image));
  // Composite any alpha over white: transparent map pixels are unknown, not walls.
  png_color white{255, 255, 255};
  if (!png_image_finish_read(&image, &white, out.pixels.data(), 0, nullptr)) {
    png_image_free(&image);
    return absl::DataLossError(absl::StrCat(path, ": PNG decode failed: ", image.message));
  }
  return out;
}

absl::StatusOr<Image<uint16_t>> ReadPngGray16(const std::string& path) {
  File f(std::fopen(path.c_str(), "rb"));
  if (!f) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  unsigned char sig[8];
  if (std::fread(sig, 1, 8, f.get()) != 8 || png_sig_cmp(sig, 0, 8) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a PNG file"));
  }
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_read_struct(&png, &info, nullptr);
    return absl::ResourceExhaustedError(absl::StrCat(path, ": libpng allocation failed"));
  }
  Image<uint16_t> out;
  std::vector<png_bytep> rows;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return absl::DataLossError(absl::StrCat(path, ": corrupt or truncated PNG"));
  }
  png_init_io(png, f.get());
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  const int depth = png_get_bit_depth(png, info);
  const int type = png_get_color_type(png, info);
  if (type != PNG_COLOR_TYPE_GRAY || depth != 16) {
    png_destroy_read_struct(&png, &info, nullptr);
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": expected a 16-bit gray PNG, found colour type ", type, " depth ",
                     depth));
  }
  png_set_swap(png);  // PNG stores big-endian samples
  out.width = static_cast<int>(png_get_image_width(png, info));
  out.height = static_cast<int>(png_get_image_height(png, info));
  if (absl::Status s = CheckDeclaredSize(path, out.width, out.height, 16); !s.ok()) {
    png_destroy_read_struct(&png, &info, nullptr);
    return s;
  }
  out.pixels.resize(size_t(out.width) * out.height);
  rows.resize(out.height);
  for (int r = 0; r < out.height; ++r) {
    rows[r] = reinterpret_cast<png_bytep>(out.pixels.data() + size_t(r) * out.width);
  }
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return out;
}

absl::Status WritePngGray8(const std::string& path, const Image<uint8_t>& img) {
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  image.width = img.width;
  image.height = img.height;
  image.format = PNG_FORMAT_GRAY;
  const std::string tmp = PartialPath(path);
  if (!png_image_write_to_file(&image, tmp.c_str(), 0, img.pixels.data(), 0, nullptr)) {
    std::remove(tmp.c_str());
    return absl::InternalError(absl::StrCat(path, ": PNG write failed: ", image.message));
  }
  return CommitPartial(path);
}

}  // namespace carvemap
