#include "tests/fuzz/h5_script.h"

#include <hdf5.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/h5_util.h"

namespace carvemap::fuzz {
namespace {

using h5::Hid;

constexpr size_t kMaxDataBytes = 64 << 10;  // per attribute or dataset written
constexpr uint32_t kMaxChunkRows = 64;
constexpr uint64_t kMaxChunksWritten = 16;
constexpr uint8_t kCompound = 15, kFixedString = 13, kVariableString = 14;

// Reads the script front to back; past the end every read gives zeros.
class Script {
 public:
  explicit Script(std::span<const uint8_t> bytes) : bytes_(bytes) {}
  [[nodiscard]] bool done() const { return pos_ >= bytes_.size(); }
  uint8_t U8() { return pos_ < bytes_.size() ? bytes_[pos_++] : 0; }
  uint32_t U32() {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= uint32_t{U8()} << (8 * i);
    return v;
  }
  std::string Bytes(size_t n) {
    const size_t take = std::min(n, bytes_.size() - std::min(pos_, bytes_.size()));
    std::string out(reinterpret_cast<const char*>(bytes_.data()) + pos_, take);
    pos_ += take;
    out.resize(n, '\0');
    return out;
  }
  std::string Str() { return Bytes(U8()); }

 private:
  std::span<const uint8_t> bytes_;
  size_t pos_ = 0;
};

hid_t ScalarBase(uint8_t code) {
  static const hid_t* const kTypes[] = {
      &H5T_IEEE_F32LE_g, &H5T_IEEE_F64LE_g, &H5T_IEEE_F32BE_g, &H5T_IEEE_F64BE_g,
      &H5T_STD_I8LE_g,   &H5T_STD_U8LE_g,   &H5T_STD_I16LE_g,  &H5T_STD_U16LE_g,
      &H5T_STD_I32LE_g,  &H5T_STD_U32LE_g,  &H5T_STD_I64LE_g,  &H5T_STD_U64LE_g,
      &H5T_STD_I64BE_g};
  return *kTypes[code % 13];
}

// A type read from the script; `variable` is set for variable-length strings. Invalid when
// HDF5 refuses it (the caller skips the operation).
Hid ReadType(Script& s, bool& variable) {
  variable = false;
  const uint8_t code = s.U8() % 16;
  if (code < kFixedString) return Hid(H5Tcopy(ScalarBase(code)));
  if (code == kFixedString) {
    const size_t size = std::max<uint8_t>(1, s.U8());
    const uint8_t pad = s.U8() % 3;
    Hid t(H5Tcopy(H5T_C_S1));
    H5Tset_size(t.get(), size);
    H5Tset_strpad(t.get(), pad == 0 ? H5T_STR_NULLTERM : pad == 1 ? H5T_STR_NULLPAD
                                                                  : H5T_STR_SPACEPAD);
    return t;
  }
  if (code == kVariableString) {
    variable = true;
    Hid t(H5Tcopy(H5T_C_S1));
    H5Tset_size(t.get(), H5T_VARIABLE);
    H5Tset_cset(t.get(), H5T_CSET_UTF8);
    return t;
  }
  const int members = s.U8() % 17;
  std::vector<std::pair<std::string, hid_t>> fields;
  size_t size = 0;
  for (int i = 0; i < members; ++i) {
    std::string name = s.Str();
    const hid_t base = ScalarBase(s.U8());
    fields.emplace_back(std::move(name), base);
    size += H5Tget_size(base);
  }
  size += s.U8() % 16;  // trailing padding, as writers that pad records leave
  if (size == 0) return Hid();
  Hid t(H5Tcreate(H5T_COMPOUND, size));
  size_t offset = 0;
  for (const auto& [name, base] : fields) {
    // A duplicate or empty name is refused; its bytes stay as padding.
    H5Tinsert(t.get(), name.c_str(), offset, base);
    offset += H5Tget_size(base);
  }
  return t;
}

struct Space {
  int rank = 0;
  hsize_t dims[2] = {0, 0};
  [[nodiscard]] uint64_t points() const {
    uint64_t n = 1;
    for (int i = 0; i < rank; ++i) n *= dims[i];  // ≤ 2^64 - 1: two u32 factors
    return n;
  }
};

Space ReadSpace(Script& s) {
  Space space;
  space.rank = s.U8() % 3;
  for (int i = 0; i < space.rank; ++i) space.dims[i] = s.U32();
  return space;
}

// `n` elements of data: raw bytes of `type`, or one str per element for variable strings.
struct Data {
  std::string raw;
  std::vector<std::string> strings;
  std::vector<const char*> pointers;
  [[nodiscard]] const void* get() const {
    return pointers.empty() ? static_cast<const void*>(raw.data()) : pointers.data();
  }
};

Data ReadData(Script& s, hid_t type, bool variable, uint64_t n) {
  Data d;
  if (variable) {
    for (uint64_t i = 0; i < n; ++i) d.strings.push_back(s.Str());
    for (const std::string& str : d.strings) d.pointers.push_back(str.c_str());
  } else {
    d.raw = s.Bytes(n * H5Tget_size(type));
  }
  return d;
}

// Elements that fit the data cap.
uint64_t CappedPoints(uint64_t points, hid_t type, bool variable) {
  const size_t bytes = variable ? 8 : std::max<size_t>(1, H5Tget_size(type));
  return std::min<uint64_t>(points, kMaxDataBytes / bytes);
}

Hid LinkCreatePlist() {
  Hid lcpl(H5Pcreate(H5P_LINK_CREATE));
  H5Pset_create_intermediate_group(lcpl.get(), 1);
  return lcpl;
}

void Attribute(hid_t file, Script& s) {
  const std::string object = s.Str(), name = s.Str();
  bool variable = false;
  Hid type = ReadType(s, variable);
  const Space space = ReadSpace(s);
  const uint64_t points = space.points();
  if (!type.valid() || points != CappedPoints(points, type.get(), variable)) return;
  const Data data = ReadData(s, type.get(), variable, points);
  Hid sid(space.rank == 0 ? H5Screate(H5S_SCALAR)
                          : H5Screate_simple(space.rank, space.dims, nullptr));
  Hid attr(H5Acreate_by_name(file, object.empty() ? "/" : object.c_str(), name.c_str(),
                             type.get(), sid.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  if (attr.valid() && points > 0) H5Awrite(attr.get(), type.get(), data.get());
}

void Dataset(hid_t file, Script& s, const Hid& lcpl) {
  const std::string path = s.Str();
  bool variable = false;
  Hid type = ReadType(s, variable);
  const Space space = ReadSpace(s);
  const uint8_t layout = s.U8() % 4;
  const bool chunked = layout == 1 || layout == 2;
  const uint32_t chunk_rows = chunked ? std::clamp<uint32_t>(s.U32(), 1, kMaxChunkRows) : 0;
  const uint64_t row_points = space.rank <= 1 ? 1 : space.dims[1];
  uint64_t rows = space.rank == 0 ? 1 : std::min<uint64_t>(s.U32(), space.dims[0]);
  if (!type.valid()) return;
  rows = std::min(rows, CappedPoints(rows * row_points, type.get(), variable) /
                            std::max<uint64_t>(1, row_points));
  const Data data = ReadData(s, type.get(), variable, rows * row_points);
  const size_t element_bytes = variable ? 16 : H5Tget_size(type.get());
  const uint64_t row_bytes = row_points * element_bytes;  // < 2^37
  // Writing allocates the whole of a contiguous dataset and whole chunks: keep both small so
  // that a file stays a few KiB. A large contiguous dataset is still declared (HDF5 allocates
  // nothing until a write), and a chunked one stores only the rows written.
  if (chunked && row_bytes > kMaxDataBytes) return;
  if (!chunked && space.points() > kMaxDataBytes / std::max<size_t>(1, element_bytes)) rows = 0;

  Hid dcpl(H5Pcreate(H5P_DATASET_CREATE));
  H5Pset_obj_track_times(dcpl.get(), 0);
  hsize_t max_dims[2] = {space.dims[0], space.dims[1]};
  if (layout == 3) H5Pset_layout(dcpl.get(), H5D_COMPACT);
  if (chunked && space.rank > 0) {
    const hsize_t chunk[2] = {
        std::clamp<uint64_t>(kMaxDataBytes / std::max<uint64_t>(1, row_bytes), 1, chunk_rows),
        std::max<hsize_t>(1, space.dims[1])};
    // Each chunk written costs a filter pass (zlib sets up 256 KiB of state per chunk).
    rows = std::min<uint64_t>(rows, kMaxChunksWritten * chunk[0]);
    H5Pset_chunk(dcpl.get(), space.rank, chunk);
    max_dims[0] = H5S_UNLIMITED;
    if (layout == 2) {
      H5Pset_shuffle(dcpl.get());
      H5Pset_deflate(dcpl.get(), 1);
    }
  }
  Hid sid(space.rank == 0 ? H5Screate(H5S_SCALAR)
                          : H5Screate_simple(space.rank, space.dims, max_dims));
  Hid dataset(H5Dcreate2(file, path.c_str(), type.get(), sid.get(), lcpl.get(), dcpl.get(),
                         H5P_DEFAULT));
  if (!dataset.valid() || rows == 0) return;
  if (space.rank == 0) {
    H5Dwrite(dataset.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data.get());
    return;
  }
  const hsize_t start[2] = {0, 0};
  const hsize_t count[2] = {rows, space.dims[1]};
  Hid file_space(H5Dget_space(dataset.get()));
  H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr);
  Hid mem_space(H5Screate_simple(space.rank, count, nullptr));
  H5Dwrite(dataset.get(), type.get(), mem_space.get(), file_space.get(), H5P_DEFAULT, data.get());
}

}  // namespace

void BuildH5FromScript(std::span<const uint8_t> script, const std::string& path) {
  h5::Init();
  Script s(script);
  const uint8_t flags = s.U8();
  Hid fcpl(H5Pcreate(H5P_FILE_CREATE));
  H5Pset_obj_track_times(fcpl.get(), 0);
  Hid gcpl(H5Pcreate(H5P_GROUP_CREATE));
  H5Pset_obj_track_times(gcpl.get(), 0);
  if (flags & 2) {
    H5Pset_link_creation_order(fcpl.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
    H5Pset_link_creation_order(gcpl.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
  }
  Hid fapl(H5Pcreate(H5P_FILE_ACCESS));
  if (flags & 1) H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST);
  Hid file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl.get(), fapl.get()));
  if (!file.valid()) {
    std::fprintf(stderr, "h5_script: cannot create %s: %s\n", path.c_str(),
                 h5::TakeErrorStack().c_str());
    std::abort();
  }
  const Hid lcpl = LinkCreatePlist();
  while (!s.done()) {
    switch (s.U8() % 5) {
      case 0: {
        const std::string group = s.Str();
        Hid(H5Gcreate2(file.get(), group.c_str(), lcpl.get(), gcpl.get(), H5P_DEFAULT));
        break;
      }
      case 1:
        Attribute(file.get(), s);
        break;
      case 2:
        Dataset(file.get(), s, lcpl);
        break;
      case 3: {
        const std::string link = s.Str(), target = s.Str();
        H5Lcreate_soft(target.c_str(), file.get(), link.c_str(), lcpl.get(), H5P_DEFAULT);
        break;
      }
      case 4: {
        const std::string link = s.Str(), target = s.Str();
        H5Lcreate_hard(file.get(), target.c_str(), file.get(), link.c_str(), lcpl.get(),
                       H5P_DEFAULT);
        break;
      }
    }
  }
  H5Eclear2(H5E_DEFAULT);
  if (H5Fclose(file.Release()) < 0) {
    std::fprintf(stderr, "h5_script: cannot close %s: %s\n", path.c_str(),
                 h5::TakeErrorStack().c_str());
    std::abort();
  }
}

// --- The other way: a file to its script (seeds) ---------------------------------------------

namespace {

class ScriptOut {
 public:
  void U8(uint8_t v) { out_.push_back(static_cast<char>(v)); }
  void U32(uint64_t v) {
    for (int i = 0; i < 4; ++i) U8(static_cast<uint8_t>(v >> (8 * i)));
  }
  absl::Status Str(const std::string& s) {
    if (s.size() > 255) return absl::InvalidArgumentError("name longer than 255 bytes: " + s);
    U8(static_cast<uint8_t>(s.size()));
    out_ += s;
    return absl::OkStatus();
  }
  void Raw(const void* p, size_t n) { out_.append(static_cast<const char*>(p), n); }
  std::string& bytes() { return out_; }

 private:
  std::string out_;
};

absl::StatusOr<uint8_t> ScalarCode(hid_t type) {
  for (uint8_t code = 0; code < kFixedString; ++code) {
    if (H5Tequal(type, ScalarBase(code)) > 0) return code;
  }
  return absl::InvalidArgumentError("a scalar type the script cannot express");
}

absl::Status WriteType(hid_t type, ScriptOut& out, bool& variable) {
  variable = false;
  const H5T_class_t cls = H5Tget_class(type);
  if (cls == H5T_STRING) {
    if (H5Tis_variable_str(type) > 0) {
      variable = true;
      out.U8(kVariableString);
      return absl::OkStatus();
    }
    const size_t size = H5Tget_size(type);
    if (size > 255) return absl::InvalidArgumentError("fixed string longer than 255 bytes");
    out.U8(kFixedString);
    out.U8(static_cast<uint8_t>(size));
    const H5T_str_t pad = H5Tget_strpad(type);
    out.U8(pad == H5T_STR_NULLTERM ? 0 : pad == H5T_STR_NULLPAD ? 1 : 2);
    return absl::OkStatus();
  }
  if (cls == H5T_COMPOUND) {
    const int n = H5Tget_nmembers(type);
    if (n > 16) return absl::InvalidArgumentError("compound with more than 16 members");
    out.U8(kCompound);
    out.U8(static_cast<uint8_t>(n));
    size_t offset = 0;
    for (int i = 0; i < n; ++i) {
      char* name = H5Tget_member_name(type, i);
      const std::string member = name;
      H5free_memory(name);
      Hid member_type(H5Tget_member_type(type, i));
      auto code = ScalarCode(member_type.get());
      if (!code.ok()) return code.status();
      if (H5Tget_member_offset(type, i) != offset) {
        return absl::InvalidArgumentError("compound members not packed in order");
      }
      offset += H5Tget_size(member_type.get());
      if (absl::Status st = out.Str(member); !st.ok()) return st;
      out.U8(*code);
    }
    const size_t padding = H5Tget_size(type) - offset;
    if (padding > 15) return absl::InvalidArgumentError("compound padding over 15 bytes");
    out.U8(static_cast<uint8_t>(padding));
    return absl::OkStatus();
  }
  auto code = ScalarCode(type);
  if (!code.ok()) return code.status();
  out.U8(*code);
  return absl::OkStatus();
}

absl::StatusOr<Space> WriteSpace(hid_t sid, ScriptOut& out) {
  Space space;
  space.rank = H5Sget_simple_extent_ndims(sid);
  if (space.rank < 0 || space.rank > 2) return absl::InvalidArgumentError("rank above 2");
  H5Sget_simple_extent_dims(sid, space.dims, nullptr);
  out.U8(static_cast<uint8_t>(space.rank));
  for (int i = 0; i < space.rank; ++i) {
    if (space.dims[i] > UINT32_MAX) return absl::InvalidArgumentError("dimension above 2^32");
    out.U32(space.dims[i]);
  }
  return space;
}

// Appends `n` elements read by `read(mem_type, buffer)`.
template <typename ReadFn>
absl::Status WriteData(hid_t type, bool variable, uint64_t n, ScriptOut& out, ReadFn read) {
  if (n == 0) return absl::OkStatus();
  if (variable) {
    std::vector<char*> strings(n, nullptr);
    Hid mem(H5Tcopy(type));
    if (read(mem.get(), strings.data()) < 0) return absl::DataLossError("cannot read strings");
    absl::Status st;
    for (char* str : strings) {
      if (st.ok()) st = out.Str(str ? str : "");
      H5free_memory(str);
    }
    return st;
  }
  const size_t bytes = n * H5Tget_size(type);
  if (bytes > kMaxDataBytes) return absl::InvalidArgumentError("more than 64 KiB of data");
  std::string buffer(bytes, '\0');
  Hid mem(H5Tcopy(type));  // the file's own type: raw bytes, no conversion
  if (read(mem.get(), buffer.data()) < 0) return absl::DataLossError("cannot read data");
  out.Raw(buffer.data(), bytes);
  return absl::OkStatus();
}

absl::Status WriteAttributes(hid_t object, const std::string& path, ScriptOut& out) {
  H5O_info_t info;
  if (H5Oget_info2(object, &info, H5O_INFO_NUM_ATTRS) < 0) {
    return absl::DataLossError("cannot list attributes of " + path);
  }
  for (hsize_t i = 0; i < info.num_attrs; ++i) {
    Hid attr(H5Aopen_by_idx(object, ".", H5_INDEX_NAME, H5_ITER_INC, i, H5P_DEFAULT,
                            H5P_DEFAULT));
    if (!attr.valid()) return absl::DataLossError("cannot open an attribute of " + path);
    char name[256] = {};
    if (H5Aget_name(attr.get(), sizeof(name), name) >= static_cast<ssize_t>(sizeof(name))) {
      return absl::InvalidArgumentError("attribute name too long");
    }
    out.U8(1);
    if (absl::Status st = out.Str(path); !st.ok()) return st;
    if (absl::Status st = out.Str(name); !st.ok()) return st;
    Hid type(H5Aget_type(attr.get()));
    bool variable = false;
    if (absl::Status st = WriteType(type.get(), out, variable); !st.ok()) return st;
    Hid sid(H5Aget_space(attr.get()));
    auto space = WriteSpace(sid.get(), out);
    if (!space.ok()) return space.status();
    absl::Status st = WriteData(type.get(), variable, space->points(), out,
                                [&](hid_t mem, void* buf) { return H5Aread(attr.get(), mem, buf); });
    if (!st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::Status WriteDataset(hid_t dataset, const std::string& path, ScriptOut& out) {
  out.U8(2);
  if (absl::Status st = out.Str(path); !st.ok()) return st;
  Hid type(H5Dget_type(dataset));
  bool variable = false;
  if (absl::Status st = WriteType(type.get(), out, variable); !st.ok()) return st;
  Hid sid(H5Dget_space(dataset));
  auto space = WriteSpace(sid.get(), out);
  if (!space.ok()) return space.status();
  Hid dcpl(H5Dget_create_plist(dataset));
  const H5D_layout_t layout = H5Pget_layout(dcpl.get());
  if (layout == H5D_CHUNKED) {
    out.U8(H5Pget_nfilters(dcpl.get()) > 0 ? 2 : 1);
    hsize_t chunk[2] = {1, 1};
    H5Pget_chunk(dcpl.get(), 2, chunk);
    out.U32(std::min<hsize_t>(chunk[0], kMaxChunkRows));
  } else {
    out.U8(layout == H5D_COMPACT ? 3 : 0);
  }
  if (space->rank > 0) out.U32(space->dims[0]);
  return WriteData(type.get(), variable, space->points(), out, [&](hid_t mem, void* buf) {
    return H5Dread(dataset, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
  });
}

struct VisitState {
  ScriptOut* out;
  absl::Status status;
};

herr_t VisitObject(hid_t root, const char* name, const H5O_info_t* info, void* data) {
  auto* state = static_cast<VisitState*>(data);
  const std::string path = std::string(name) == "." ? "/" : absl::StrCat("/", name);
  Hid object(H5Oopen(root, name, H5P_DEFAULT));
  absl::Status st;
  if (info->type == H5O_TYPE_GROUP && path != "/") {
    state->out->U8(0);
    st = state->out->Str(path);
  } else if (info->type == H5O_TYPE_DATASET) {
    st = WriteDataset(object.get(), path, *state->out);
  }
  if (st.ok()) st = WriteAttributes(object.get(), path, *state->out);
  state->status = st;
  return st.ok() ? 0 : -1;
}

}  // namespace

absl::StatusOr<std::string> ScriptFromH5(const std::string& path) {
  h5::Init();
  Hid file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT));
  if (!file.valid()) return absl::NotFoundError(path + ": cannot open");
  H5F_info2_t finfo;
  H5Fget_info2(file.get(), &finfo);
  uint8_t flags = finfo.super.version >= 2 ? 1 : 0;
  ScriptOut out;
  out.U8(0);  // flags, set below
  VisitState state{&out, absl::OkStatus()};
  // Link order is tracked in the file when any group tracks it (ScanWriter's /sensors does).
  auto tracks = [](hid_t group) {
    Hid gcpl(H5Gget_create_plist(group));
    unsigned order = 0;
    H5Pget_link_creation_order(gcpl.get(), &order);
    return (order & H5P_CRT_ORDER_TRACKED) != 0;
  };
  H5Ovisit2(
      file.get(), H5_INDEX_NAME, H5_ITER_INC,
      [](hid_t root, const char* name, const H5O_info_t* info, void* data) -> herr_t {
        return VisitObject(root, name, info, data);
      },
      &state, H5O_INFO_BASIC);
  if (!state.status.ok()) return h5::Prefixed(path, state.status);
  for (const std::string group : {"/", "/sensors"}) {
    if (group != "/" && !h5::Exists(file.get(), group)) continue;
    Hid g(H5Gopen2(file.get(), group.c_str(), H5P_DEFAULT));
    if (g.valid() && tracks(g.get())) flags |= 2;
  }
  H5Eclear2(H5E_DEFAULT);
  out.bytes()[0] = static_cast<char>(flags);
  return out.bytes();
}

}  // namespace carvemap::fuzz
