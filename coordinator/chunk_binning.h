// Binning wedges into the 2 m chunks they touch (§4.3.1, docs/DESIGN.md §5). A chunk gets a wedge
// iff HullIntersectsBox(hull, ChunkBox(chunk)); the test is monotone in the box, so every leaf the
// worker finds intersecting the hull lies in a chunk that got the wedge.
#pragma once

#include <vector>

#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"
#include "geometry/wedge_geometry.h"

namespace carvemap {

// Coordinates beyond this are rejected (a wedge 1000 km away is a broken pose, not a building).
inline constexpr double kMaxWorldCoordinateM = 1e6;

// The chunks whose boxes the hull intersects, sorted by ChunkKeyLess, without duplicates.
// Descends halves of the chunk range of the hull's box, so long wedges cost about their length,
// not their box's volume. An empty or non-finite hull box, or one reaching beyond
// ±kMaxWorldCoordinateM, gives no chunks (ValidateWedge rejects such wedges first).
[[nodiscard]] std::vector<ChunkKey> ChunksOfWedge(const WedgeHull& hull);
// Same, for the wedge's hull with `sigmas` extension (MakeWedgeHull).
[[nodiscard]] std::vector<ChunkKey> ChunksOfWedge(const Wedge& wedge, double sigmas = 3.0);

}  // namespace carvemap
