// PNG input (storage/png_io.h): floor maps (`carvemap simulate --floormap`, `floorplan
// --gridmap`) as 8-bit gray and TUM depth images as 16-bit gray. Any bytes give an image or an
// error naming the file; an image has width·height pixels.
#include <cstddef>
#include <cstdint>

#include "storage/png_io.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/fuzz/png_crc.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("image.png", data, size);
  absl::StatusOr<Image<uint8_t>> gray8 = ReadPngGray8(path);
  if (gray8.ok()) {
    fuzz::Require(gray8->pixels.size() == size_t(gray8->width) * gray8->height,
                  "8-bit image holds width × height pixels");
  } else {
    fuzz::RequireNamesFile(gray8.status(), path);
  }
  absl::StatusOr<Image<uint16_t>> gray16 = ReadPngGray16(path);
  if (gray16.ok()) {
    fuzz::Require(gray16->pixels.size() == size_t(gray16->width) * gray16->height,
                  "16-bit image holds width × height pixels");
  } else {
    fuzz::RequireNamesFile(gray16.status(), path);
  }
  return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t max_size,
                                          unsigned int /*seed*/) {
  size = LLVMFuzzerMutate(data, size, max_size);
  carvemap::fuzz::FixPngCrcs(data, size);
  return size;
}
