// PNG images in and out (libpng), as plain row-major pixel arrays.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace carvemap {

template <typename T>
struct Image {
  int width = 0, height = 0;  // pixels; row 0 is the top row of the file
  std::vector<T> pixels;      // row-major, width·height
  [[nodiscard]] T at(int row, int col) const { return pixels[size_t(row) * width + col]; }
  T& at(int row, int col) { return pixels[size_t(row) * width + col]; }
};

// Any PNG (gray, gray+alpha, RGB, RGBA, palette, 1–16 bit) converted to 8-bit gray, as the
// floor maps need (tests/data/SOURCES.md).
absl::StatusOr<Image<uint8_t>> ReadPngGray8(const std::string& path);
// A 16-bit single-channel PNG (depth images); raw values, no gamma conversion.
absl::StatusOr<Image<uint16_t>> ReadPngGray16(const std::string& path);
// Writes 8-bit gray (through "<path>.partial" and a rename).
absl::Status WritePngGray8(const std::string& path, const Image<uint8_t>& image);

}  // namespace carvemap
