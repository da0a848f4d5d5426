// The wedge payload (storage/WEDGE_FORMAT.md, version 2): the bytes of a chunk's spill file
// after its header and of the wedges sent to a worker. Neighbouring wedges share rays (each ray
// of a line or grid sensor belongs to up to four wedges) and the rays of a frame share their
// sensor Gaussian, so the payload stores each frame's sensor Gaussian and each ray once, the
// first time a wedge of the chunk needs it, and a wedge as four back-references to its rays.
// Little-endian, float32, byte-exact: the same wedges always give the same bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/geometry/carving_types.h"

namespace carvemap {

inline constexpr uint8_t kWedgePayloadMagic = 0xC7;
inline constexpr uint8_t kWedgePayloadVersion = 2;
inline constexpr size_t kFrameRecordBytes = 37;  // tag, sensor mean and covariance
inline constexpr size_t kRayRecordBytes = 38;    // tag, frame back-reference, point mean and cov

// OK iff num_rays is in [1, 4] and every value of its rays is finite.
[[nodiscard]] absl::Status ValidateWedge(const Wedge& wedge);

// Writes one chunk's payload, wedge by wedge, in the order given. Not thread-safe; one per
// chunk. Memory: the ids of the rays written for the last two frames of each sensor (a wedge
// only joins rays of consecutive frames of one sensor, or of one frame).
class WedgePayloadWriter {
 public:
  // Appends the wedge's records to `out` (and the payload header before the first wedge):
  // a frame record for each frame of its rays not yet written (or written more than 255 frame
  // records ago), a ray record for each of its rays not yet written, then the wedge record.
  // `ids[r]` names wedge.rays[r] (RayId: equal ids must mean bit-identical rays). A ray whose
  // frame is older than its sensor's last two frames here is written again, as a new ray.
  // `facets` is the hull hint the wedge's hull was built with (MakeWedgeHull; 0: none),
  // stored with multi-ray wedges so the worker rebuilds the same hull without a search.
  // REQUIRES: ValidateWedge(wedge).ok(), ids.size() >= wedge.num_rays.
  void Add(const Wedge& wedge, std::span<const RayId> ids, std::string& out,
           uint64_t facets = 0);
  // Appends the end record (the number of wedges): a payload is complete only with it, so a
  // truncated one is always detected. Nothing when no wedge was added (the empty payload).
  // Call once, last.
  void Finish(std::string& out) const;

  [[nodiscard]] uint64_t wedges() const { return wedges_; }

 private:
  struct FrameState {
    uint64_t frame = 0;
    int64_t local = -1;  // frame number in this payload
    absl::flat_hash_map<uint32_t, uint32_t> rays;  // index in frame → ray number here
  };
  struct SensorState {
    FrameState frames[2];  // the last two frames of the sensor seen here (either order)
  };
  FrameState& Frame(const RayId& id, const RayModel& ray, std::string& out);

  absl::flat_hash_map<uint32_t, SensorState> sensors_;
  FrameState stale_;
  int64_t frames_ = 0;  // frame records written
  uint32_t rays_ = 0;   // ray records written
  uint64_t wedges_ = 0;
};

// A whole payload (ended) for wedges without ids: rays are the same when bit-identical, and so are
// sensor Gaussians (for tests and tools; memory ∝ the input).
[[nodiscard]] std::string EncodeWedges(std::span<const Wedge> wedges);

// The payload's rays (each once) and wedges (as ray indices), in payload order: the worker's
// input. Errors: DataLoss naming the record and its byte offset for a missing or wrong header
// (an older payload version is named as such), an unknown record tag, a truncated record, a
// reference to a frame or ray not written before it, a non-finite value, or a missing end
// record or one whose count disagrees. An empty payload holds no wedges.
[[nodiscard]] absl::StatusOr<IndexedWedges> DecodeWedgePayload(std::string_view bytes);
// The number of wedge records, checking the structure (not the float values) as above.
[[nodiscard]] absl::StatusOr<uint64_t> CountWedgeRecords(std::string_view bytes);
// The wedges with copies of their rays (rays beyond num_rays zero), for tests and tools.
[[nodiscard]] absl::StatusOr<std::vector<Wedge>> DecodeWedges(std::string_view bytes);

}  // namespace carvemap
