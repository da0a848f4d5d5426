// The merge's memory budget (MergeOptions::memory_budget_bytes): the memory of the planar
// regions (§4.2.4) and of the planar mesh (§4.3.3) grows with the boundary faces they are made
// of: a slab of heights for the levels, one level's faces for its floor plan, one level's part
// of the building for mesh/building.ply. Before each, the merge checks that what it holds plus
// kPlanarBytesPerFace per face fits the budget, and fails with a message that says where the
// faces are and what to change, instead of being killed for memory partway.
#pragma once

#include <cstdint>
#include <functional>
#include <string_view>

#include "absl/status/status.h"

namespace carvemap {

// OK when budget_bytes is 0 (no budget) or held_bytes + num_faces × kPlanarBytesPerFace fits
// it; else ResourceExhausted naming `what` (the stage and where its faces are), the number of
// faces, the estimate, held_bytes and the budget.
[[nodiscard]] absl::Status CheckPlanarMemory(std::string_view what, uint64_t num_faces,
                                             uint64_t held_bytes, uint64_t budget_bytes);

// The same with what the process holds read by `held` (its resident memory) when the check is
// made. When it does not fit and `settle` is given, settle() is called once (it waits for work
// running beside the stage to end and give its memory back: the dense mesh) and the check is
// made again on a new reading. Why: such work ends on its own, so waiting for it costs only the
// overlap, where failing would cost the job.
[[nodiscard]] absl::Status CheckPlanarMemory(std::string_view what, uint64_t num_faces,
                                             const std::function<uint64_t()>& held,
                                             uint64_t budget_bytes,
                                             const std::function<void()>& settle);

}  // namespace carvemap
