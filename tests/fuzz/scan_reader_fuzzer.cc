// scan.h5 (storage/scan_reader.h), opened, validated and streamed. Any file gives a reader or
// an error naming the file; a file that validates streams every frame in time order.
// Two targets from this source: scan_reader builds the file from an h5_script.h script (files
// HDF5 wrote: our reader's logic), scan_reader_raw takes the input as the file's bytes (HDF5's
// own parsing of corrupt metadata too; README.md says what that finds).
#include <cstddef>
#include <cstdint>
#include <limits>

#include "storage/scan_reader.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/fuzz/h5_script.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  fuzz::KeepHdf5FreeLists();
#ifdef CARVEMAP_FUZZ_RAW_BYTES
  const std::string path = fuzz::WriteInput("scan.h5", data, size);
#else
  const std::string path = (fuzz::ScratchDir() / "scan.h5").string();
  fuzz::BuildH5FromScript({data, size}, path);
#endif
  absl::StatusOr<std::unique_ptr<ScanReader>> opened = ScanReader::Open(path);
  if (!opened.ok()) {
    fuzz::RequireNamesFile(opened.status(), path);
    return 0;
  }
  ScanReader& reader = **opened;
  // Random access before validation, as `carvemap validate` would not but a careless caller
  // might: a frame row pointing outside /points must be an error, not a read out of bounds.
  for (size_t s = 0; s < reader.sensors().size(); ++s) {
    if (reader.frame_count(s) == 0) continue;
    for (uint64_t row : {uint64_t{0}, reader.frame_count(s) - 1}) {
      absl::StatusOr<ScanFrame> frame = reader.ReadFrame(static_cast<int>(s), row);
      if (!frame.ok()) fuzz::RequireNamesFile(frame.status(), path);
    }
  }
  absl::Status valid = reader.Validate();
  if (!valid.ok()) {
    fuzz::RequireNamesFile(valid, path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  uint64_t expected = 0;
  for (size_t s = 0; s < reader.sensors().size(); ++s) expected += reader.frame_count(s);
  // A small block budget, so blocks are refilled many times even in small files.
  std::unique_ptr<ScanReader::FrameStream> stream = reader.StreamFrames(/*block_bytes=*/256);
  ScanFrame frame;
  uint64_t n = 0;
  double previous_t = -std::numeric_limits<double>::infinity();
  for (;;) {
    absl::StatusOr<bool> more = stream->Next(frame);
    if (!more.ok()) {
      // A read error after validation can only come from HDF5 (a damaged chunk).
      fuzz::RequireNamesFile(more.status(), path);
      return 0;
    }
    if (!*more) break;
    fuzz::Require(frame.t >= previous_t, "frames stream in time order");
    previous_t = frame.t;
    const Pose pose = reader.PoseAt(frame.t);
    fuzz::Require(pose.translation.allFinite(), "a validated path gives finite poses");
    ++n;
  }
  fuzz::Require(n == expected, "the stream gives every frame once");
  return 0;
}
