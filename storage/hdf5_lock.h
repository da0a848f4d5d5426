// The one lock of every HDF5 call in a process: Debian 12's libhdf5 is built without
// --enable-threadsafe and keeps global state, so even one file per thread is unsafe
// (storage/h5_util.h). Tile I/O takes it inside (tile_store.h); a thread that reads a scan while
// others write tiles (a worker's slices, `carvemap carve`) takes it around each ScanReader call.
#pragma once

#include <mutex>

namespace carvemap {

[[nodiscard]] std::mutex& Hdf5Lock();

}  // namespace carvemap
