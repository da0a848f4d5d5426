// E57 (storage/import/e57_import.h, e57_reader.h): any bytes give a scan or an error naming the
// file; an accepted file writes a scan.h5 that validates. A page whose CRC-32C is wrong stops
// the reader at that page, so random mutations would almost never reach the XML and the
// packets: the mutator recomputes every whole page's checksum, except for one input in eight,
// which keeps the checksum's own error path fuzzed.
#include <cstddef>
#include <cstdint>
#include <string>

#include "storage/crc32c.h"
#include "storage/import/e57_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" size_t LLVMFuzzerMutate(uint8_t* data, size_t size, size_t max_size);

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("input.e57", data, size);
  absl::StatusOr<E57Import> e57 = E57Import::Open(path, E57ImportOptions{});
  if (!e57.ok()) {
    fuzz::RequireNamesFile(e57.status(), path);
    return 0;
  }
  E57Report report;
  uint64_t frames = 0;
  absl::StatusOr<std::vector<PathRecord>> path_records = e57->Run(
      [&](int, double, std::span<const Eigen::Vector3f>) {
        ++frames;
        return absl::OkStatus();
      },
      &report);
  if (!path_records.ok()) {
    fuzz::RequireNamesFile(path_records.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(frames == report.scans && path_records->size() == report.scans,
                "one frame and one /path row per scan");
  fuzz::RequireSensorsImportWritesValidScan(
      e57->sensors(), frames, [&](const SensorFrameSink& sink) { return e57->Run(sink); });
  return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t max_size,
                                          unsigned int seed) {
  size = LLVMFuzzerMutate(data, size, max_size);
  if (seed % 8 == 0) return size;
  for (size_t page = 0; page + 1024 <= size; page += 1024) {
    const uint32_t crc = carvemap::Crc32c({reinterpret_cast<const char*>(data + page), 1020});
    for (int i = 0; i < 4; ++i) data[page + 1020 + i] = static_cast<uint8_t>(crc >> (24 - 8 * i));
  }
  return size;
}
