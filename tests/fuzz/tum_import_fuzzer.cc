// TUM RGB-D depth images with poses (storage/import/tum_import.h). An input is an association
// file, a NUL byte, then the bytes of a 16-bit depth PNG, which is stored as depth/1.png and
// depth/2.png (the seeds' association lines name those). Any input gives a scan or an error
// naming the association file or the image; an accepted directory writes a scan.h5 that
// validates.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>

#include "storage/import/tum_import.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/fuzz/png_crc.h"

namespace {

// The seeds' images are real TUM fr2 depth images shrunk 40× (16 × 12 pixels), so the
// intrinsics are the fr2 ones scaled by 1/40.
carvemap::TumOptions Options() {
  carvemap::TumOptions o;
  o.width = 16;
  o.height = 12;
  o.fx = 520.9 / 40;
  o.fy = 521.0 / 40;
  o.cx = 325.1 / 40;
  o.cy = 249.7 / 40;
  return o;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const uint8_t* nul = static_cast<const uint8_t*>(std::memchr(data, 0, size));
  const size_t text_size = nul ? static_cast<size_t>(nul - data) : size;
  const uint8_t* png = nul ? nul + 1 : data + size;
  const size_t png_size = size - text_size - (nul ? 1 : 0);

  const std::string dir = (fuzz::ScratchDir() / "tum").string();
  std::filesystem::remove_all(fuzz::ScratchDir() / "tum" / "depth");
  fuzz::WriteInput("tum/my_association.txt", data, text_size);
  if (nul) {
    fuzz::WriteInput("tum/depth/1.png", png, png_size);
    fuzz::WriteInput("tum/depth/2.png", png, png_size);
  }
  const TumOptions options = Options();
  absl::StatusOr<ImportedScan> scan = ImportTum(dir, options);
  if (!scan.ok()) {
    fuzz::RequireNamesFile(scan.status(), dir);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(scan->frame_count == scan->frames.size(), "frames kept without a sink");
  for (const ImportedFrame& f : scan->frames) {
    fuzz::Require(f.points_sensor.size() == size_t(options.width) * options.height,
                  "a grid frame holds rows × cols rays");
  }
  fuzz::RequireImportWritesValidScan(TumSensor(options), scan->frame_count,
                                     [&](const FrameSink& sink) {
                                       return ImportTum(dir, options, sink);
                                     });
  return 0;
}

// The depth image after the NUL keeps valid chunk CRCs (png_crc.h).
extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t max_size,
                                          unsigned int /*seed*/) {
  size = LLVMFuzzerMutate(data, size, max_size);
  if (const void* nul = std::memchr(data, 0, size)) {
    const size_t at = static_cast<const uint8_t*>(nul) - data + 1;
    carvemap::fuzz::FixPngCrcs(data + at, size - at);
  }
  return size;
}
