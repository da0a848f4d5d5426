// Byte shuffling: n elements of `width` bytes laid out as `width` planes, byte 0 of every
// element, then byte 1, ... Bytes of equal rank (an integer's high bytes, a float's sign and
// exponent) then line up, which the compressors after it exploit. HDF5's shuffle filter
// (H5Zshuffle.c) is this with the plane a chunk long; the tile store applies it outside
// HDF5's lock (tile_store.cc) and the partial sums to their sections (PARTIAL_FORMAT.md).
#pragma once

#include <cstddef>

namespace carvemap {

// out[j · plane + i] = in[i · width + j] for i < n, j < width. `plane` ≥ n is each plane's
// length in `out`; the bytes of a plane past n are left as they are.
inline void ShuffleBytes(const unsigned char* in, size_t n, size_t width, size_t plane,
                         unsigned char* out) {
  for (size_t j = 0; j < width; ++j) {
    unsigned char* to = out + j * plane;
    for (size_t i = 0; i < n; ++i) to[i] = in[i * width + j];
  }
}

// ShuffleBytes undone: out[i · width + j] = in[j · plane + i] for i < n, j < width.
inline void UnshuffleBytes(const unsigned char* in, size_t n, size_t width, size_t plane,
                           unsigned char* out) {
  for (size_t j = 0; j < width; ++j) {
    const unsigned char* from = in + j * plane;
    for (size_t i = 0; i < n; ++i) out[i * width + j] = from[i];
  }
}

}  // namespace carvemap
