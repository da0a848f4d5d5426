#include "storage/h5_util.h"

#include "storage/hdf5_lock.h"

#include <array>
#include <cmath>
#include <cstddef>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "storage/scan_types.h"

namespace carvemap::h5 {

void Init() {
  static std::once_flag once;
  std::call_once(once, [] {
    H5open();
    // Errors are reported through Status; HDF5's own printing would only add noise to stderr.
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  });
}

void Hid::Reset() {
  if (id_ >= 0) H5Idec_ref(id_);
  id_ = H5I_INVALID_HID;
}

namespace {

herr_t CollectMessage(unsigned /*n*/, const H5E_error2_t* err, void* data) {
  auto* messages = static_cast<std::vector<std::string>*>(data);
  if (err->desc != nullptr && err->desc[0] != '\0') messages->emplace_back(err->desc);
  return 0;
}

}  // namespace

std::string TakeErrorStack() {
  std::vector<std::string> messages;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, CollectMessage, &messages);
  H5Eclear2(H5E_DEFAULT);
  // The innermost messages say what went wrong ("truncated file: eof = ..."); the outer ones
  // only name the API calls that failed on the way up.
  std::vector<std::string> useful;
  for (auto it = messages.rbegin(); it != messages.rend() && useful.size() < 2; ++it) {
    if (useful.empty() || useful.back() != *it) useful.push_back(*it);
  }
  return absl::StrJoin(useful, "; ");
}

absl::Status Error(absl::StatusCode code, absl::string_view what) {
  const std::string stack = TakeErrorStack();
  if (stack.empty()) return absl::Status(code, what);
  return absl::Status(code, absl::StrCat(what, " (HDF5: ", stack, ")"));
}

absl::StatusOr<Hid> CheckId(hid_t id, absl::string_view what) {
  if (id < 0) return Error(absl::StatusCode::kDataLoss, what);
  return Hid(id);
}

absl::Status CheckRc(herr_t rc, absl::string_view what) {
  if (rc < 0) return Error(absl::StatusCode::kDataLoss, what);
  return absl::OkStatus();
}

absl::Status Prefixed(absl::string_view prefix, const absl::Status& status) {
  if (status.ok()) return status;
  return absl::Status(status.code(), absl::StrCat(prefix, ": ", status.message()));
}

bool Exists(hid_t loc, const std::string& path) {
  std::string prefix;
  for (absl::string_view part : absl::StrSplit(path, '/', absl::SkipEmpty())) {
    absl::StrAppend(&prefix, "/", part);
    if (H5Lexists(loc, prefix.c_str(), H5P_DEFAULT) <= 0) {
      H5Eclear2(H5E_DEFAULT);
      return false;
    }
  }
  return true;
}

Hid GroupCreatePlist(bool track_link_order) {
  Hid gcpl(H5Pcreate(H5P_GROUP_CREATE));
  H5Pset_obj_track_times(gcpl.get(), 0);
  if (track_link_order) {
    // Readers list sensors in the order they were added, so sensor indices agree.
    H5Pset_link_creation_order(gcpl.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
  }
  return gcpl;
}

// --- Attributes ---------------------------------------------------------------------------

namespace {

absl::Status WriteAttr(hid_t obj, const char* name, hid_t file_type, hid_t space, hid_t mem_type,
                       const void* data) {
  auto attr = CheckId(H5Acreate2(obj, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT),
                      absl::StrCat("cannot create attribute '", name, "'"));
  if (!attr.ok()) return attr.status();
  return CheckRc(H5Awrite(attr->get(), mem_type, data),
                 absl::StrCat("cannot write attribute '", name, "'"));
}

absl::StatusOr<Hid> OpenAttr(hid_t obj, const char* name) {
  if (!HasAttr(obj, name)) {
    return absl::InvalidArgumentError(absl::StrCat("missing attribute '", name, "'"));
  }
  return CheckId(H5Aopen(obj, name, H5P_DEFAULT),
                 absl::StrCat("cannot open attribute '", name, "'"));
}

hssize_t AttrPoints(hid_t attr) {
  Hid space(H5Aget_space(attr));
  return H5Sget_simple_extent_npoints(space.get());
}

}  // namespace

absl::Status WriteStringAttr(hid_t obj, const char* name, absl::string_view value) {
  // Variable-length UTF-8, as h5py writes them, so Python reads a str and not bytes.
  Hid type(H5Tcopy(H5T_C_S1));
  H5Tset_size(type.get(), H5T_VARIABLE);
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  Hid space(H5Screate(H5S_SCALAR));
  const std::string copy(value);
  const char* ptr = copy.c_str();
  return WriteAttr(obj, name, type.get(), space.get(), type.get(), &ptr);
}

absl::Status WriteIntAttr(hid_t obj, const char* name, int64_t value) {
  Hid space(H5Screate(H5S_SCALAR));
  return WriteAttr(obj, name, H5T_STD_I64LE, space.get(), H5T_NATIVE_INT64, &value);
}

absl::Status WriteDoubleAttr(hid_t obj, const char* name, double value) {
  Hid space(H5Screate(H5S_SCALAR));
  return WriteAttr(obj, name, H5T_IEEE_F64LE, space.get(), H5T_NATIVE_DOUBLE, &value);
}

absl::Status WriteDoublesAttr(hid_t obj, const char* name, std::span<const double> values) {
  const hsize_t dims[1] = {values.size()};
  Hid space(H5Screate_simple(1, dims, nullptr));
  return WriteAttr(obj, name, H5T_IEEE_F64LE, space.get(), H5T_NATIVE_DOUBLE, values.data());
}

bool HasAttr(hid_t obj, const char* name) {
  const htri_t exists = H5Aexists(obj, name);
  if (exists < 0) H5Eclear2(H5E_DEFAULT);
  return exists > 0;
}

absl::StatusOr<std::string> ReadStringAttr(hid_t obj, const char* name) {
  auto attr = OpenAttr(obj, name);
  if (!attr.ok()) return attr.status();
  Hid type(H5Aget_type(attr->get()));
  if (H5Tget_class(type.get()) != H5T_STRING || AttrPoints(attr->get()) != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("attribute '", name, "' is not a single string"));
  }
  if (H5Tis_variable_str(type.get()) > 0) {
    Hid mem(H5Tcopy(H5T_C_S1));
    H5Tset_size(mem.get(), H5T_VARIABLE);
    H5Tset_cset(mem.get(), H5Tget_cset(type.get()));  // HDF5 does not convert charsets
    char* str = nullptr;
    if (H5Aread(attr->get(), mem.get(), &str) < 0) {
      return Error(absl::StatusCode::kDataLoss, absl::StrCat("cannot read attribute '", name, "'"));
    }
    std::string value = str != nullptr ? str : "";
    H5free_memory(str);
    return value;
  }
  std::string buffer(H5Tget_size(type.get()), '\0');
  if (H5Aread(attr->get(), type.get(), buffer.data()) < 0) {
    return Error(absl::StatusCode::kDataLoss, absl::StrCat("cannot read attribute '", name, "'"));
  }
  buffer.resize(std::min(buffer.size(), buffer.find('\0')));
  if (H5Tget_strpad(type.get()) == H5T_STR_SPACEPAD) {
    buffer.erase(buffer.find_last_not_of(' ') + 1);
  }
  return buffer;
}

absl::StatusOr<int64_t> ReadIntAttr(hid_t obj, const char* name) {
  auto attr = OpenAttr(obj, name);
  if (!attr.ok()) return attr.status();
  Hid type(H5Aget_type(attr->get()));
  if (H5Tget_class(type.get()) != H5T_INTEGER || AttrPoints(attr->get()) != 1 ||
      !CheckTypeIsSane(type.get()).ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("attribute '", name, "' is not a single integer"));
  }
  int64_t value = 0;
  if (H5Aread(attr->get(), H5T_NATIVE_INT64, &value) < 0) {
    return Error(absl::StatusCode::kDataLoss, absl::StrCat("cannot read attribute '", name, "'"));
  }
  return value;
}

absl::StatusOr<std::vector<double>> ReadDoublesAttr(hid_t obj, const char* name, size_t n) {
  auto attr = OpenAttr(obj, name);
  if (!attr.ok()) return attr.status();
  Hid type(H5Aget_type(attr->get()));
  const H5T_class_t cls = H5Tget_class(type.get());
  const hssize_t points = AttrPoints(attr->get());
  if ((cls != H5T_INTEGER && cls != H5T_FLOAT) || points != static_cast<hssize_t>(n) ||
      !CheckTypeIsSane(type.get()).ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("attribute '", name, "' must hold ", n, " number", n == 1 ? "" : "s"));
  }
  std::vector<double> values(n);
  if (H5Aread(attr->get(), H5T_NATIVE_DOUBLE, values.data()) < 0) {
    return Error(absl::StatusCode::kDataLoss, absl::StrCat("cannot read attribute '", name, "'"));
  }
  return values;
}

// --- Compound types ----------------------------------------------------------------------

absl::Status CheckTypeIsSane(hid_t type) {
  const size_t size = H5Tget_size(type);
  if (size == 0) return absl::InvalidArgumentError("a type of size 0");
  switch (H5Tget_class(type)) {
    case H5T_INTEGER:
    case H5T_FLOAT: {
      const size_t precision = H5Tget_precision(type);
      const int offset = H5Tget_offset(type);
      if (precision == 0 || offset < 0 || offset + precision > 8 * size) {
        return absl::InvalidArgumentError(absl::StrCat("a number of ", size, " bytes with ",
                                                       precision, " bits at bit ", offset));
      }
      if (H5Tget_class(type) == H5T_INTEGER) return absl::OkStatus();
      size_t spos = 0, epos = 0, esize = 0, mpos = 0, msize = 0;
      if (H5Tget_fields(type, &spos, &epos, &esize, &mpos, &msize) < 0) {
        return Error(absl::StatusCode::kInvalidArgument, "a float without fields");
      }
      // Sign, exponent and mantissa: non-empty (but the sign), inside the precision, disjoint.
      const auto overlap = [](size_t a, size_t na, size_t b, size_t nb) {
        return a < b + nb && b < a + na;
      };
      if (esize == 0 || msize == 0 || spos >= precision || epos + esize > precision ||
          mpos + msize > precision || overlap(epos, esize, mpos, msize) ||
          overlap(spos, 1, epos, esize) || overlap(spos, 1, mpos, msize)) {
        return absl::InvalidArgumentError(absl::StrCat(
            "a float whose fields do not fit (sign ", spos, ", exponent ", epos, "+", esize,
            ", mantissa ", mpos, "+", msize, " in ", precision, " bits)"));
      }
      return absl::OkStatus();
    }
    case H5T_COMPOUND: {
      const int n = H5Tget_nmembers(type);
      if (n < 0) return Error(absl::StatusCode::kInvalidArgument, "a compound without members");
      for (int i = 0; i < n; ++i) {
        char* name = H5Tget_member_name(type, static_cast<unsigned>(i));
        const std::string member = name != nullptr ? name : "";
        H5free_memory(name);
        Hid member_type(H5Tget_member_type(type, static_cast<unsigned>(i)));
        const size_t offset = H5Tget_member_offset(type, static_cast<unsigned>(i));
        const size_t member_size = H5Tget_size(member_type.get());
        if (!member_type.valid() || offset > size || member_size > size - offset) {
          return absl::InvalidArgumentError(
              absl::StrCat("field '", member, "' (", member_size, " bytes at byte ", offset,
                           ") lies outside the ", size, "-byte record"));
        }
        if (absl::Status s = CheckTypeIsSane(member_type.get()); !s.ok()) {
          return absl::InvalidArgumentError(absl::StrCat("field '", member, "': ", s.message()));
        }
      }
      return absl::OkStatus();
    }
    default:
      return absl::OkStatus();  // strings and others: no bit layout of ours to convert
  }
}

Hid MakeCompound(size_t size, std::span<const Field> fields) {
  Hid type(H5Tcreate(H5T_COMPOUND, size));
  for (const Field& f : fields) H5Tinsert(type.get(), f.name, f.offset, f.mem_type);
  return type;
}

Hid MakePackedCompound(std::span<const Field> fields, std::span<const hid_t> file_types) {
  size_t size = 0;
  for (hid_t t : file_types) size += H5Tget_size(t);
  Hid type(H5Tcreate(H5T_COMPOUND, size));
  size_t offset = 0;
  for (size_t i = 0; i < fields.size(); ++i) {
    H5Tinsert(type.get(), fields[i].name, offset, file_types[i]);
    offset += H5Tget_size(file_types[i]);
  }
  return type;
}

absl::Status CheckCompoundFields(hid_t file_type, std::span<const Field> fields) {
  if (H5Tget_class(file_type) != H5T_COMPOUND) {
    return absl::InvalidArgumentError("not a compound dataset");
  }
  if (absl::Status s = CheckTypeIsSane(file_type); !s.ok()) return s;
  for (const Field& f : fields) {
    const int index = H5Tget_member_index(file_type, f.name);
    if (index < 0) {
      H5Eclear2(H5E_DEFAULT);
      return absl::InvalidArgumentError(absl::StrCat("missing field '", f.name, "'"));
    }
    const H5T_class_t cls = H5Tget_member_class(file_type, static_cast<unsigned>(index));
    if (cls != H5T_INTEGER && cls != H5T_FLOAT) {
      return absl::InvalidArgumentError(absl::StrCat("field '", f.name, "' is not numeric"));
    }
  }
  return absl::OkStatus();
}

std::span<const Field> PathFields() {
  static const std::array<Field, 8> fields = {{
      {"t", offsetof(PathRecord, t), H5T_NATIVE_DOUBLE},
      {"x", offsetof(PathRecord, x), H5T_NATIVE_DOUBLE},
      {"y", offsetof(PathRecord, y), H5T_NATIVE_DOUBLE},
      {"z", offsetof(PathRecord, z), H5T_NATIVE_DOUBLE},
      {"qw", offsetof(PathRecord, qw), H5T_NATIVE_DOUBLE},
      {"qx", offsetof(PathRecord, qx), H5T_NATIVE_DOUBLE},
      {"qy", offsetof(PathRecord, qy), H5T_NATIVE_DOUBLE},
      {"qz", offsetof(PathRecord, qz), H5T_NATIVE_DOUBLE},
  }};
  return fields;
}

std::span<const Field> FrameFields() {
  static const std::array<Field, 3> fields = {{
      {"t", offsetof(FrameRecord, t), H5T_NATIVE_DOUBLE},
      {"first", offsetof(FrameRecord, first), H5T_NATIVE_UINT64},
      {"count", offsetof(FrameRecord, count), H5T_NATIVE_UINT32},
  }};
  return fields;
}

std::span<const Field> MagnetometerFields() {
  static const std::array<Field, 4> fields = {{
      {"t", offsetof(MagnetometerRecord, t), H5T_NATIVE_DOUBLE},
      {"mx", offsetof(MagnetometerRecord, mx), H5T_NATIVE_DOUBLE},
      {"my", offsetof(MagnetometerRecord, my), H5T_NATIVE_DOUBLE},
      {"mz", offsetof(MagnetometerRecord, mz), H5T_NATIVE_DOUBLE},
  }};
  return fields;
}

Hid PathMemType() { return MakeCompound(sizeof(PathRecord), PathFields()); }
Hid FrameMemType() { return MakeCompound(sizeof(FrameRecord), FrameFields()); }
Hid MagnetometerMemType() { return MakeCompound(sizeof(MagnetometerRecord), MagnetometerFields()); }

Hid PathFileType() {
  const std::vector<hid_t> types(PathFields().size(), H5T_IEEE_F64LE);
  return MakePackedCompound(PathFields(), types);
}
Hid FrameFileType() {
  const std::array<hid_t, 3> types = {H5T_IEEE_F64LE, H5T_STD_U64LE, H5T_STD_U32LE};
  return MakePackedCompound(FrameFields(), types);
}
Hid MagnetometerFileType() {
  const std::vector<hid_t> types(MagnetometerFields().size(), H5T_IEEE_F64LE);
  return MakePackedCompound(MagnetometerFields(), types);
}

// --- Row datasets ------------------------------------------------------------------------

absl::StatusOr<std::vector<hsize_t>> Dims(hid_t dataset) {
  Hid space(H5Dget_space(dataset));
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) return Error(absl::StatusCode::kDataLoss, "cannot read the dataspace");
  std::vector<hsize_t> dims(static_cast<size_t>(rank));
  H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr);
  return dims;
}

absl::StatusOr<Hid> CreateRows(hid_t loc, const char* name, hid_t file_type, hsize_t cols,
                               hsize_t chunk_rows) {
  const int rank = cols > 0 ? 2 : 1;
  const hsize_t dims[2] = {0, cols};
  const hsize_t max_dims[2] = {H5S_UNLIMITED, cols};
  const hsize_t chunk[2] = {chunk_rows, cols};
  Hid space(H5Screate_simple(rank, dims, max_dims));
  Hid dcpl(H5Pcreate(H5P_DATASET_CREATE));
  H5Pset_chunk(dcpl.get(), rank, chunk);
  H5Pset_obj_track_times(dcpl.get(), 0);
  // A defined (zero) fill written at allocation: the unused tail of the last chunk holds
  // zeros, not leftover memory, so equal content gives equal bytes.
  const std::vector<unsigned char> zero(H5Tget_size(file_type), 0);
  H5Pset_fill_value(dcpl.get(), file_type, zero.data());
  H5Pset_fill_time(dcpl.get(), H5D_FILL_TIME_ALLOC);
  return CheckId(
      H5Dcreate2(loc, name, file_type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
      absl::StrCat("cannot create dataset '", name, "'"));
}

absl::Status CheckDataStored(hid_t dataset) {
  auto dims = Dims(dataset);
  if (!dims.ok()) return dims.status();
  const uint64_t rows = dims->empty() ? 1 : (*dims)[0];
  Hid dcpl(H5Dget_create_plist(dataset));
  switch (H5Pget_layout(dcpl.get())) {
    case H5D_COMPACT:
    case H5D_CONTIGUOUS: {
      // Stored whole or not at all; a damaged dataspace can still declare more than is there.
      Hid type(H5Dget_type(dataset));
      Hid space(H5Dget_space(dataset));
      const hssize_t points = H5Sget_simple_extent_npoints(space.get());
      const uint64_t element_bytes = H5Tget_size(type.get());
      const uint64_t stored = H5Dget_storage_size(dataset);
      if (points <= 0 || element_bytes == 0 ||
          static_cast<uint64_t>(points) <= stored / element_bytes) {
        return absl::OkStatus();
      }
      return absl::DataLossError(absl::StrCat("declares ", rows, " rows but stores ", stored,
                                              " bytes, room for ", stored / element_bytes,
                                              " elements: rows were never written"));
    }
    case H5D_CHUNKED: {
      std::vector<hsize_t> chunk(dims->size());
      if (H5Pget_chunk(dcpl.get(), static_cast<int>(chunk.size()), chunk.data()) < 0) {
        return Error(absl::StatusCode::kDataLoss, "cannot read the chunk shape");
      }
      // Chunks the extent covers; saturating, as dims may be near 2^64.
      uint64_t needed = 1;
      for (size_t i = 0; i < dims->size(); ++i) {
        const uint64_t d = (*dims)[i];
        const uint64_t n = chunk[i] == 0 ? 0 : d / chunk[i] + (d % chunk[i] != 0);
        needed = n != 0 && needed > UINT64_MAX / n ? UINT64_MAX : needed * n;
      }
      if (needed == 0) return absl::OkStatus();
      hsize_t stored = 0;
      Hid space(H5Dget_space(dataset));  // all of it selected
      if (H5Dget_num_chunks(dataset, space.get(), &stored) < 0) {
        return Error(absl::StatusCode::kDataLoss, "cannot count the stored chunks");
      }
      if (stored >= needed) return absl::OkStatus();
      return absl::DataLossError(absl::StrCat("declares ", rows, " rows but stores ", stored,
                                              " of its ", needed,
                                              " chunks: rows were never written"));
    }
    default:
      return absl::DataLossError("unsupported storage layout");
  }
}

namespace {

// Selects rows [first, first+n) of `dataset`'s file space; returns it and a matching memory
// space.
std::pair<Hid, Hid> RowSpaces(hid_t dataset, hsize_t cols, uint64_t first, uint64_t n) {
  const int rank = cols > 0 ? 2 : 1;
  const hsize_t start[2] = {first, 0};
  const hsize_t count[2] = {n, cols};
  Hid file_space(H5Dget_space(dataset));
  H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr);
  Hid mem_space(H5Screate_simple(rank, count, nullptr));
  return {std::move(file_space), std::move(mem_space)};
}

}  // namespace

absl::Status ReadRows(hid_t dataset, hid_t mem_type, hsize_t cols, uint64_t first, uint64_t n,
                      void* out) {
  if (n == 0) return absl::OkStatus();
  auto dims = Dims(dataset);
  if (!dims.ok()) return dims.status();
  if (dims->empty() || first + n > (*dims)[0]) {
    return absl::OutOfRangeError(absl::StrCat("rows [", first, ", ", first + n, ") past the end (",
                                              dims->empty() ? 0 : (*dims)[0], " rows)"));
  }
  auto [file_space, mem_space] = RowSpaces(dataset, cols, first, n);
  return CheckRc(H5Dread(dataset, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, out),
                 absl::StrCat("cannot read rows [", first, ", ", first + n, ")"));
}

absl::Status WriteRows(hid_t dataset, hid_t mem_type, hsize_t cols, uint64_t first, uint64_t n,
                       const void* data) {
  if (n == 0) return absl::OkStatus();
  auto dims = Dims(dataset);
  if (!dims.ok()) return dims.status();
  if (first + n > (*dims)[0]) {
    std::vector<hsize_t> grown = *dims;
    grown[0] = first + n;
    absl::Status extended = CheckRc(H5Dset_extent(dataset, grown.data()), "cannot extend");
    if (!extended.ok()) return extended;
  }
  auto [file_space, mem_space] = RowSpaces(dataset, cols, first, n);
  return CheckRc(H5Dwrite(dataset, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, data),
                 absl::StrCat("cannot write rows [", first, ", ", first + n, ")"));
}

}  // namespace carvemap::h5

namespace carvemap {

std::mutex& Hdf5Lock() {
  static std::mutex mu;
  return mu;
}

}  // namespace carvemap
