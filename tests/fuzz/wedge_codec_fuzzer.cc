// Wedge records (storage/wedge_codec.h): the payload a worker receives over RPC and the body
// of the coordinator's spill files. Any bytes decode or give DataLoss; what decodes encodes
// back to the same bytes (the format is byte-exact).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "storage/wedge_codec.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<std::vector<Wedge>> wedges = DecodeWedges(bytes);
  if (!wedges.ok()) {
    fuzz::Require(wedges.status().code() == absl::StatusCode::kDataLoss,
                  "decode errors are DataLoss: " + wedges.status().ToString());
    return 0;
  }
  for (const Wedge& w : *wedges) fuzz::Require(ValidateWedge(w).ok(), "decoded wedge is valid");
  fuzz::Require(EncodeWedges(*wedges) == bytes, "decode then encode gives the input back");
  return 0;
}
