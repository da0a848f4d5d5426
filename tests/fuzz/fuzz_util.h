// Shared by the fuzz targets: a per-process scratch directory for the files the readers open
// (our readers take paths), and invariant checks that turn a broken promise into a crash the
// fuzzer reports. The promises checked are the readers' own contracts (their headers):
// errors name the file; what an importer accepts is a scan.h5 that validates.
#pragma once

#include <hdf5.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "storage/import/import_writer.h"
#include "storage/scan_reader.h"

namespace carvemap::fuzz {

// A directory of this process's own (so -jobs/-workers do not collide), on tmpfs when there is
// one: every input is written to a file, and the readers then open it by name.
inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    std::filesystem::path base = "/dev/shm";
    if (access(base.c_str(), W_OK) != 0) base = std::filesystem::temp_directory_path();
    std::filesystem::path d = base / ("carvemap_fuzz_" + std::to_string(getpid()));
    std::filesystem::create_directories(d);
    // Removed at a normal exit; a crash leaves it for the post-mortem.
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(ScratchDir(), ignored);
    });
    return d;
  }();
  return dir;
}

// HDF5 frees type-conversion buffers (1 MiB each, two per H5Dread that converts) back to the
// system as they exceed its default block free-list limit (1 MiB per list), and under ASan
// every such calloc maps fresh pages: most of an execution's time. 8 MiB per list (32 MiB in
// all) keeps those blocks for reuse; other limits stay HDF5's defaults. Only speed changes.
inline void KeepHdf5FreeLists() {
  static const bool once = [] {
    H5set_free_list_limits(1 << 20, 64 << 10, 4 << 20, 256 << 10, 32 << 20, 8 << 20);
    return true;
  }();
  (void)once;
}

// Writes `size` bytes to ScratchDir()/name (replacing it) and returns the path.
inline std::string WriteInput(const std::string& name, const uint8_t* data, size_t size) {
  const std::filesystem::path path = ScratchDir() / name;
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) {
    std::fprintf(stderr, "fuzz: cannot write %s\n", path.c_str());
    std::abort();
  }
  return path.string();
}

// With CARVEMAP_FUZZ_VERBOSE set, prints what a reader said about the input (to check by hand
// that the seeds are accepted: run a target on the seed files, not on a directory).
inline void Trace(const absl::Status& status) {
  static const bool verbose = std::getenv("CARVEMAP_FUZZ_VERBOSE") != nullptr;
  if (verbose) std::fprintf(stderr, "fuzz: %s\n", status.ToString().c_str());
}

// Aborts (a finding) with `what` when `ok` is false.
inline void Require(bool ok, std::string_view what) {
  if (ok) return;
  std::fprintf(stderr, "fuzz invariant broken: %.*s\n", static_cast<int>(what.size()), what.data());
  std::abort();
}

// "Bad input gets a clear error naming the file" (docs/DESIGN.md §3, COMMON): every error from a
// reader must carry the path it was given.
inline void RequireNamesFile(const absl::Status& status, const std::string& path) {
  Trace(status);
  if (status.ok()) return;
  Require(status.message().find(path) != std::string_view::npos,
          "error does not name the file: " + status.ToString());
}

// An importer's promise: what it accepts is a valid scan. The import was run again into `out`
// (a scan.h5 in the scratch directory): the write succeeded, and ScanReader opens and fully
// validates the file and streams every frame back.
inline void RequireWrittenScanValid(const std::string& out,
                                    const absl::StatusOr<ImportSummary>& summary, uint64_t frames) {
  Require(summary.ok(), "accepted input did not write: " + summary.status().ToString());
  Require(summary->frames == frames, "second import gave another frame count");
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(out);
  Require(reader.ok(), "imported scan does not open: " + reader.status().ToString());
  absl::Status valid = (*reader)->Validate();
  Require(valid.ok(), "imported scan does not validate: " + valid.ToString());
  std::unique_ptr<ScanReader::FrameStream> stream = (*reader)->StreamFrames();
  ScanFrame frame;
  uint64_t n = 0;
  for (;;) {
    absl::StatusOr<bool> more = stream->Next(frame);
    Require(more.ok(), "imported scan does not stream: " + more.status().ToString());
    if (!*more) break;
    ++n;
  }
  Require(n == frames, "imported scan streams another number of frames");
}

// Runs `import` again through WriteImport, and checks what it wrote (above).
template <typename ImportFn>
void RequireImportWritesValidScan(const SensorInfo& sensor, uint64_t frames, ImportFn import) {
  KeepHdf5FreeLists();
  const std::string out = (ScratchDir() / "imported.h5").string();
  RequireWrittenScanValid(out, WriteImport(out, sensor, import), frames);
}

// The same for an importer of several sensors (WriteImportSensors).
template <typename ImportFn>
void RequireSensorsImportWritesValidScan(std::span<const SensorInfo> sensors, uint64_t frames,
                                         ImportFn import) {
  KeepHdf5FreeLists();
  const std::string out = (ScratchDir() / "imported.h5").string();
  RequireWrittenScanValid(out, WriteImportSensors(out, sensors, import), frames);
}

}  // namespace carvemap::fuzz
