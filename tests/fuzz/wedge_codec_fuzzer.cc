// Wedge payloads (storage/wedge_codec.h, version 2): the bytes a worker receives over RPC and
// the body of the coordinator's spill files. Any bytes decode or give DataLoss, and
// CountWedgeRecords (structure only) agrees with the full decode. A payload's own bytes need not
// be the canonical ones (a ray may be written twice, a frame record go unused, and a hull hint
// does not survive DecodeWedges), so the round trip checked is of what the payload holds: its
// wedges encode, decode back bit for bit, and encode again to the same bytes.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include "storage/wedge_codec.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

bool SameRay(const carvemap::RayModel& a, const carvemap::RayModel& b) {
  return std::memcmp(a.sensor_mean.data(), b.sensor_mean.data(), 12) == 0 &&
         std::memcmp(a.point_mean.data(), b.point_mean.data(), 12) == 0 &&
         std::memcmp(a.sensor_cov.data(), b.sensor_cov.data(), 24) == 0 &&
         std::memcmp(a.point_cov.data(), b.point_cov.data(), 24) == 0;
}

bool SameWedges(const std::vector<carvemap::Wedge>& a, const std::vector<carvemap::Wedge>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].num_rays != b[i].num_rays) return false;
    for (int r = 0; r < a[i].num_rays; ++r) {
      if (!SameRay(a[i].rays[r], b[i].rays[r])) return false;
    }
  }
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const absl::StatusOr<IndexedWedges> payload = DecodeWedgePayload(bytes);
  const absl::StatusOr<uint64_t> count = CountWedgeRecords(bytes);
  if (!payload.ok()) {
    fuzz::Require(payload.status().code() == absl::StatusCode::kDataLoss,
                  "decode errors are DataLoss: " + payload.status().ToString());
    // The count skips the floats: past a non-finite value it may pass or fail later on;
    // otherwise it fails with the decode's own error.
    if (payload.status().message().find("non-finite") == std::string_view::npos) {
      fuzz::Require(!count.ok() && count.status() == payload.status(),
                    "count and decode disagree on: " + payload.status().ToString());
    }
    return 0;
  }
  fuzz::Require(count.ok() && *count == payload->wedges.size(), "count agrees with decode");
  for (const WedgeRef& w : payload->wedges) {
    fuzz::Require(w.num_rays >= 1 && w.num_rays <= 4, "wedge of 1 to 4 rays");
    for (int r = 0; r < w.num_rays; ++r) {
      fuzz::Require(w.ray[r] < payload->rays.size(), "wedge's ray is in the payload");
    }
    if (w.num_rays == 1) fuzz::Require(w.facets == 0, "single-ray wedge has no hull hint");
  }

  const absl::StatusOr<std::vector<Wedge>> wedges = DecodeWedges(bytes);
  fuzz::Require(wedges.ok() && wedges->size() == payload->wedges.size(),
                "DecodeWedges agrees with DecodeWedgePayload");
  for (const Wedge& w : *wedges) fuzz::Require(ValidateWedge(w).ok(), "decoded wedge is valid");
  const std::string canonical = EncodeWedges(*wedges);
  const absl::StatusOr<std::vector<Wedge>> again = DecodeWedges(canonical);
  fuzz::Require(again.ok(), "encoded wedges decode");
  fuzz::Require(SameWedges(*wedges, *again), "encode then decode gives the wedges back");
  fuzz::Require(EncodeWedges(*again) == canonical, "the encoding is byte-exact");
  return 0;
}
