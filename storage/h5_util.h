// Internal helpers over the HDF5 C API for storage/: RAII handles, HDF5 error stacks turned
// into absl::Status, attributes, compound types looked up by field name, and row I/O on
// extendible datasets. Not an API outside storage/ (tests in storage/ use it to craft files).
//
// Thread safety: Debian 12's libhdf5 (the "serial" build) is compiled without
// --enable-threadsafe. The library keeps global state (error stack, id tables, caches), so even
// one file or one reader per thread is NOT safe: every HDF5 call in the process must be
// serialized (e.g. one process-wide mutex around all storage/ HDF5 use).
#pragma once

#include <hdf5.h>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace carvemap::h5 {

// Turns off HDF5's automatic error printing (once per process); errors go into Status instead.
void Init();

// Owns one HDF5 identifier (file, group, dataset, dataspace, type, property list, attribute).
class Hid {
 public:
  Hid() = default;
  explicit Hid(hid_t id) : id_(id) {}
  ~Hid() { Reset(); }
  Hid(Hid&& other) noexcept : id_(other.Release()) {}
  Hid& operator=(Hid&& other) noexcept {
    if (this != &other) {
      Reset();
      id_ = other.Release();
    }
    return *this;
  }
  Hid(const Hid&) = delete;
  Hid& operator=(const Hid&) = delete;

  [[nodiscard]] hid_t get() const { return id_; }
  [[nodiscard]] bool valid() const { return id_ >= 0; }
  void Reset();
  hid_t Release() {
    hid_t id = id_;
    id_ = H5I_INVALID_HID;
    return id;
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
};

// The useful (innermost) messages of the current HDF5 error stack, then clears the stack.
// Empty when the stack holds nothing.
std::string TakeErrorStack();
// A Status with `what`, followed by the HDF5 error stack's messages when there are any.
absl::Status Error(absl::StatusCode code, absl::string_view what);
// `id` wrapped, or an error naming `what` when HDF5 returned a negative id.
absl::StatusOr<Hid> CheckId(hid_t id, absl::string_view what);
absl::Status CheckRc(herr_t rc, absl::string_view what);
// Prepends "prefix: " to a non-ok status's message, keeping its code.
absl::Status Prefixed(absl::string_view prefix, const absl::Status& status);

// True when every link of the absolute `path` ("/sensors/h0/frames") exists.
bool Exists(hid_t loc, const std::string& path);

// Object/link creation property lists with time tracking off, so equal content gives equal
// bytes (the simulator promises determinism per seed).
Hid GroupCreatePlist(bool track_link_order);

// --- Attributes. Errors are bare ("attribute 'kind': missing"); callers prefix file/object.
absl::Status WriteStringAttr(hid_t obj, const char* name, absl::string_view value);
absl::Status WriteIntAttr(hid_t obj, const char* name, int64_t value);
absl::Status WriteDoubleAttr(hid_t obj, const char* name, double value);
absl::Status WriteDoublesAttr(hid_t obj, const char* name, std::span<const double> values);
bool HasAttr(hid_t obj, const char* name);
// Fixed- or variable-length strings.
absl::StatusOr<std::string> ReadStringAttr(hid_t obj, const char* name);
// Integer attributes only (a float "version" is an error, docs/DESIGN.md §3).
absl::StatusOr<int64_t> ReadIntAttr(hid_t obj, const char* name);
// Any numeric attribute with exactly `n` values (scalar when n == 1).
absl::StatusOr<std::vector<double>> ReadDoublesAttr(hid_t obj, const char* name, size_t n);

// --- Compound types, matched by field name so writers may pad or reorder records.
struct Field {
  const char* name;
  size_t offset;
  hid_t mem_type;  // a native type (H5T_NATIVE_DOUBLE ...), not owned
};
// OK when a type read from a file is self-consistent: numbers' bits lie inside their size, a
// float's sign, exponent and mantissa are disjoint and inside its precision, and a compound's
// members (recursively) lie inside the record. HDF5 1.10 does not check this when it decodes a
// damaged type message, and then converts out of bounds (found by fuzzing); readers check
// before any conversion. InvalidArgument naming the member otherwise.
absl::Status CheckTypeIsSane(hid_t type);
// A memory compound of `size` bytes with `fields` at their offsets.
Hid MakeCompound(size_t size, std::span<const Field> fields);
// A packed little-endian file compound with the fields in order, each of its `file_types`.
Hid MakePackedCompound(std::span<const Field> fields, std::span<const hid_t> file_types);
// OK when `file_type` is a compound holding every field of `fields`, each integer or float,
// and CheckTypeIsSane.
absl::Status CheckCompoundFields(hid_t file_type, std::span<const Field> fields);

// Memory layouts of the records of storage/scan_types.h.
std::span<const Field> PathFields();
std::span<const Field> FrameFields();
std::span<const Field> MagnetometerFields();
Hid PathMemType();
Hid FrameMemType();
Hid MagnetometerMemType();
// The matching file types (packed, standard little-endian types; readable by h5py).
Hid PathFileType();
Hid FrameFileType();
Hid MagnetometerFileType();

// --- Datasets of rows: rank 1 (records) or rank 2 with `cols` values per row.
absl::StatusOr<std::vector<hsize_t>> Dims(hid_t dataset);
// An empty, chunked dataset that grows along rows. `cols` = 0 for rank 1.
absl::StatusOr<Hid> CreateRows(hid_t loc, const char* name, hid_t file_type, hsize_t cols,
                               hsize_t chunk_rows);
// OK when `dataset` stores all the elements its dataspace declares. HDF5 reads what was never
// written (unallocated chunks, an unallocated contiguous dataset) as fill values, so a file of
// a few KiB can declare 2^40 rows; readers check this before allocating for a dataset or
// streaming through it. Chunked: every chunk the extent needs is allocated; contiguous and
// compact: the storage holds every element (a damaged dataspace may declare more). DataLoss
// otherwise, e.g.
// "declares 1099511627776 rows but stores 1 of its 536870912 chunks: rows were never written".
absl::Status CheckDataStored(hid_t dataset);
// Rows [first, first+n) into `out` (n rows of `mem_type`, times `cols` when rank 2).
absl::Status ReadRows(hid_t dataset, hid_t mem_type, hsize_t cols, uint64_t first, uint64_t n,
                      void* out);
// Writes rows [first, first+n), extending the dataset when they pass its end.
absl::Status WriteRows(hid_t dataset, hid_t mem_type, hsize_t cols, uint64_t first, uint64_t n,
                       const void* data);

}  // namespace carvemap::h5
