// HDF5 C API wrappers: every call's return code is checked (see h5.h).
#include "dataset/h5.h"

#include "dataset/file_io.h"
#include "dataset/h5_guard.h"

#include <H5FDcore.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <sstream>

namespace layersnet::dataset::h5 {
namespace {

std::atomic<uint64_t> g_max_elements{uint64_t{1} << 31};

// HDF5 prints its error stack to stderr by default; our messages replace it.
void silence_hdf5() {
  static const bool once = [] {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    return true;
  }();
  (void)once;
}

TypeInfo describe_type(hid_t type) {
  TypeInfo t;
  const H5T_class_t cls = H5Tget_class(type);
  t.size = H5Tget_size(type);
  t.numeric = cls == H5T_FLOAT || cls == H5T_INTEGER;
  switch (cls) {
    case H5T_FLOAT:
      t.kind = (t.size == 4 || t.size == 8) ? Kind::kFloat : Kind::kOther;
      t.name = "float" + std::to_string(8 * t.size);
      break;
    case H5T_INTEGER: {
      t.signed_int = H5Tget_sign(type) == H5T_SGN_2;
      t.kind = (t.signed_int && (t.size == 4 || t.size == 8)) ? Kind::kInt : Kind::kOther;
      t.name = std::string(t.signed_int ? "int" : "uint") + std::to_string(8 * t.size);
      break;
    }
    case H5T_STRING: t.kind = Kind::kString; t.name = "string"; break;
    case H5T_ENUM: t.name = "enum (bool?)"; break;
    case H5T_COMPOUND: t.name = "compound"; break;
    case H5T_ARRAY: t.name = "array"; break;
    case H5T_VLEN: t.name = "vlen"; break;
    default: t.name = "unsupported type"; break;
  }
  return t;
}

ArrayInfo describe_space(hid_t space, TypeInfo type, const Where& where) {
  ArrayInfo info;
  info.type = std::move(type);
  const H5S_class_t cls = H5Sget_simple_extent_type(space);
  if (cls == H5S_NULL) {
    info.null_space = true;
    return info;
  }
  if (cls != H5S_SCALAR && cls != H5S_SIMPLE) where.fail("has an unreadable dataspace");
  const int rank = H5Sget_simple_extent_ndims(space);
  if (rank < 0 || rank > 32) where.fail("has an unreadable dataspace");
  std::vector<hsize_t> d(rank);
  if (rank > 0 && H5Sget_simple_extent_dims(space, d.data(), nullptr) < 0)
    where.fail("has an unreadable dataspace");
  info.dims.assign(d.begin(), d.end());
  return info;
}

uint64_t element_count(const ArrayInfo& info, const Where& where) {
  uint64_t n = 1;
  for (uint64_t d : info.dims) {
    if (d != 0 && n > g_max_elements.load() / d)
      where.fail("shape " + shape_string(info.dims) + " is too large to read (limit " +
                 std::to_string(g_max_elements.load()) + " elements)");
    n *= d;
  }
  if (n > g_max_elements.load())
    where.fail("shape " + shape_string(info.dims) + " is too large to read");
  return n;
}

std::string index_string(uint64_t flat, const std::vector<uint64_t>& dims) {
  std::vector<uint64_t> idx(dims.size());
  for (size_t a = dims.size(); a-- > 0;) {
    idx[a] = dims[a] ? flat % dims[a] : 0;
    flat = dims[a] ? flat / dims[a] : 0;
  }
  return shape_string(idx);
}

Handle make_string_type(bool variable, size_t size, H5T_cset_t cset) {
  Handle t(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(t.get(), variable ? H5T_VARIABLE : size);
  H5Tset_cset(t.get(), cset);
  return t;
}

// Reads all strings of a string attribute (scalar or 1-D), vlen or fixed length.
std::vector<std::string> read_strings(hid_t attr, hid_t ftype, uint64_t n, const Where& where,
                                      const std::string& name) {
  std::vector<std::string> out;
  const bool variable = H5Tis_variable_str(ftype) > 0;
  const H5T_cset_t cset = H5Tget_cset(ftype) == H5T_CSET_UTF8 ? H5T_CSET_UTF8 : H5T_CSET_ASCII;
  const size_t size = H5Tget_size(ftype);
  if (variable) {
    Handle mt = make_string_type(true, 0, cset);
    std::vector<char*> ptrs(n, nullptr);
    if (H5Aread(attr, mt.get(), ptrs.data()) < 0)
      where.fail("attribute '" + name + "' cannot be read");
    for (char* p : ptrs) {
      out.emplace_back(p ? p : "");
      if (p) H5free_memory(p);
    }
  } else {
    if (size == 0 || size > (1u << 20) || n * size > (uint64_t{1} << 26))
      where.fail("attribute '" + name + "' cannot be read (empty or larger than 64 MiB)");
    Handle mt = make_string_type(false, size, cset);
    H5Tset_strpad(mt.get(), H5T_STR_NULLPAD);
    std::vector<char> buf(n * size);
    if (H5Aread(attr, mt.get(), buf.data()) < 0)
      where.fail("attribute '" + name + "' cannot be read");
    for (uint64_t i = 0; i < n; ++i) {
      const char* s = buf.data() + i * size;
      out.emplace_back(s, strnlen(s, size));
    }
  }
  return out;
}

Handle open_attr(hid_t obj, const std::string& name, const Where& where) {
  if (!has_attr(obj, name)) where.fail("missing attribute '" + name + "'");
  Handle a(H5Aopen(obj, name.c_str(), H5P_DEFAULT), H5Aclose);
  if (!a.valid()) where.fail("attribute '" + name + "' cannot be opened");
  return a;
}

void check_write(herr_t status, const std::string& what) {
  if (status < 0) throw DatasetError("(writing)", what, "HDF5 write failed");
}

Handle link_create_plist() {
  Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
  H5Pset_create_intermediate_group(lcpl.get(), 1);
  return lcpl;
}

void write_array(hid_t loc, const std::string& name, hid_t file_type, hid_t mem_type,
                 const void* data, const std::vector<uint64_t>& dims, int gzip) {
  std::vector<hsize_t> d(dims.begin(), dims.end());
  Handle space(d.empty() ? H5Screate(H5S_SCALAR)
                         : H5Screate_simple(static_cast<int>(d.size()), d.data(), nullptr),
               H5Sclose);
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  uint64_t total = 1;
  for (auto x : dims) total *= x;
  if (gzip > 0 && !d.empty() && total > 0) {
    // Chunks of whole leading-axis rows, roughly 256 KiB, so frame hyperslabs stay cheap.
    std::vector<hsize_t> chunk = d;
    uint64_t row = total / std::max<uint64_t>(d[0], 1);
    chunk[0] = std::max<hsize_t>(1, std::min<hsize_t>(d[0], (1u << 16) / std::max<uint64_t>(row, 1)));
    H5Pset_chunk(dcpl.get(), static_cast<int>(chunk.size()), chunk.data());
    H5Pset_shuffle(dcpl.get());
    H5Pset_deflate(dcpl.get(), static_cast<unsigned>(gzip));
  }
  Handle lcpl = link_create_plist();
  Handle ds(H5Dcreate2(loc, name.c_str(), file_type, space.get(), lcpl.get(), dcpl.get(),
                       H5P_DEFAULT),
            H5Dclose);
  if (!ds.valid()) throw DatasetError("(writing)", name, "cannot create dataset");
  if (total > 0) check_write(H5Dwrite(ds.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), name);
}

void write_attr(hid_t obj, const std::string& name, hid_t file_type, hid_t mem_type,
                const void* data, const std::vector<hsize_t>& dims) {
  if (H5Aexists(obj, name.c_str()) > 0) H5Adelete(obj, name.c_str());
  Handle space(dims.empty() ? H5Screate(H5S_SCALAR)
                            : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr),
               H5Sclose);
  Handle a(H5Acreate2(obj, name.c_str(), file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT),
           H5Aclose);
  if (!a.valid()) throw DatasetError("(writing)", name, "cannot create attribute");
  hsize_t total = 1;
  for (auto d : dims) total *= d;
  if (total > 0) check_write(H5Awrite(a.get(), mem_type, data), name);
}

}  // namespace

void set_max_elements(uint64_t n) { g_max_elements = n; }
uint64_t max_elements() { return g_max_elements; }

void Where::fail(const std::string& problem) const {
  throw DatasetError(file, path.empty() ? "/" : path, problem);
}

std::string shape_string(const std::vector<uint64_t>& dims) {
  std::ostringstream s;
  s << "(";
  for (size_t i = 0; i < dims.size(); ++i) s << (i ? ", " : "") << dims[i];
  if (dims.size() == 1) s << ",";
  s << ")";
  return s.str();
}

Handle open_file(const std::string& path) {
  silence_hdf5();
  guard_file(path);
  Handle f;
  if (H5Fis_hdf5(path.c_str()) > 0)
    f = Handle(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!f.valid())
    throw DatasetError(path, "/", "cannot be opened as HDF5 (missing, truncated or not HDF5)");
  return f;
}

Handle open_file_image(std::span<const uint8_t> bytes, const std::string& name) {
  silence_hdf5();
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  H5Pset_fapl_core(fapl.get(), 1 << 16, 0);
  Handle f;
  if (!bytes.empty() &&
      H5Pset_file_image(fapl.get(), const_cast<uint8_t*>(bytes.data()), bytes.size()) >= 0)
    f = Handle(H5Fopen(name.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose);
  if (!f.valid()) throw DatasetError(name, "/", "cannot be opened as HDF5 (truncated or not HDF5)");
  return f;
}

void write_file(const std::string& path, const std::function<void(hid_t file)>& fill) {
  silence_hdf5();
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  H5Pset_fapl_core(fapl.get(), 1 << 20, /*backing_store=*/0);
  Handle f(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose);
  if (!f.valid()) throw DatasetError(path, "/", "cannot be created in memory");
  fill(f.get());
  if (H5Fflush(f.get(), H5F_SCOPE_GLOBAL) < 0) throw DatasetError(path, "/", "cannot be assembled in memory");
  const ssize_t size = H5Fget_file_image(f.get(), nullptr, 0);
  if (size <= 0) throw DatasetError(path, "/", "cannot be assembled in memory");
  std::string bytes(static_cast<std::size_t>(size), '\0');
  if (H5Fget_file_image(f.get(), bytes.data(), bytes.size()) != size)
    throw DatasetError(path, "/", "cannot be assembled in memory");
  f.reset();
  io::write_file_atomic(path, bytes);
}

bool has_link(hid_t loc, const std::string& name) {
  return H5Lexists(loc, name.c_str(), H5P_DEFAULT) > 0;
}

Handle open_object(hid_t loc, const std::string& name, const Where& where, ObjectType* type) {
  Handle o(H5Oopen(loc, name.c_str(), H5P_DEFAULT), H5Oclose);
  if (!o.valid()) where.fail("cannot be opened (broken link or corrupt object)");
  const H5I_type_t t = H5Iget_type(o.get());
  *type = t == H5I_GROUP ? ObjectType::kGroup : t == H5I_DATASET ? ObjectType::kDataset : ObjectType::kOther;
  return o;
}

Handle open_group(hid_t loc, const std::string& name, const Where& where) {
  if (!has_link(loc, name)) where.fail("missing group");
  ObjectType t;
  Handle o = open_object(loc, name, where, &t);
  if (t != ObjectType::kGroup) where.fail("must be a group");
  return o;
}

std::vector<std::string> member_names(hid_t group, const Where& where) {
  H5G_info_t info;
  if (H5Gget_info(group, &info) < 0) where.fail("cannot list the group's members");
  if (info.nlinks > (1u << 20)) where.fail("has too many members");
  std::vector<std::string> names;
  for (hsize_t i = 0; i < info.nlinks; ++i) {
    const ssize_t len = H5Lget_name_by_idx(group, ".", H5_INDEX_NAME, H5_ITER_INC, i, nullptr, 0,
                                           H5P_DEFAULT);
    if (len < 0 || len > 65536) where.fail("cannot list the group's members");
    std::string s(static_cast<size_t>(len) + 1, '\0');
    if (H5Lget_name_by_idx(group, ".", H5_INDEX_NAME, H5_ITER_INC, i, s.data(), s.size(),
                           H5P_DEFAULT) < 0)
      where.fail("cannot list the group's members");
    s.resize(static_cast<size_t>(len));
    names.push_back(std::move(s));
  }
  return names;
}

Handle create_group(hid_t loc, const std::string& name, const Where& where) {
  Handle lcpl = link_create_plist();
  Handle g(H5Gcreate2(loc, name.c_str(), lcpl.get(), H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
  if (!g.valid()) where.fail("cannot create group");
  return g;
}

bool has_attr(hid_t obj, const std::string& name) { return H5Aexists(obj, name.c_str()) > 0; }

ArrayInfo attr_info(hid_t obj, const std::string& name, const Where& where) {
  Handle a = open_attr(obj, name, where);
  Handle type(H5Aget_type(a.get()), H5Tclose);
  Handle space(H5Aget_space(a.get()), H5Sclose);
  if (!type.valid() || !space.valid()) where.fail("attribute '" + name + "' cannot be read");
  return describe_space(space.get(), describe_type(type.get()), where);
}

std::string read_string_attr(hid_t obj, const std::string& name, const Where& where) {
  const ArrayInfo info = attr_info(obj, name, where);
  if (info.type.kind != Kind::kString)
    where.fail("attribute '" + name + "' must be a string, got " + info.type.name);
  if (info.null_space || !info.dims.empty())
    where.fail("attribute '" + name + "' must be a scalar string, got array of shape " +
               shape_string(info.dims));
  Handle a = open_attr(obj, name, where);
  Handle type(H5Aget_type(a.get()), H5Tclose);
  return read_strings(a.get(), type.get(), 1, where, name).at(0);
}

std::vector<std::string> read_string_array_attr(hid_t obj, const std::string& name,
                                                const Where& where) {
  const ArrayInfo info = attr_info(obj, name, where);
  if (info.type.kind != Kind::kString || info.null_space || info.dims.size() != 1)
    where.fail("attribute '" + name + "' must be a 1-D array of strings");
  if (info.dims[0] > (1u << 20)) where.fail("attribute '" + name + "' is too long");
  Handle a = open_attr(obj, name, where);
  Handle type(H5Aget_type(a.get()), H5Tclose);
  return read_strings(a.get(), type.get(), info.dims[0], where, name);
}

double read_float_attr(hid_t obj, const std::string& name, const Where& where) {
  const ArrayInfo info = attr_info(obj, name, where);
  if (!info.type.numeric)
    where.fail("attribute '" + name + "' must be a float, got " + info.type.name);
  if (info.null_space || !info.dims.empty())
    where.fail("attribute '" + name + "' must be a scalar float, got array of shape " +
               shape_string(info.dims));
  Handle a = open_attr(obj, name, where);
  double v = 0;
  if (H5Aread(a.get(), H5T_NATIVE_DOUBLE, &v) < 0)
    where.fail("attribute '" + name + "' cannot be read");
  if (!std::isfinite(v)) where.fail("attribute '" + name + "' is not finite (" + std::to_string(v) + ")");
  return v;
}

int64_t read_int_attr(hid_t obj, const std::string& name, const Where& where) {
  const ArrayInfo info = attr_info(obj, name, where);
  if (!info.type.numeric || info.type.name.rfind("float", 0) == 0)
    where.fail("attribute '" + name + "' must be an integer, got " + info.type.name);
  if (info.null_space || !info.dims.empty())
    where.fail("attribute '" + name + "' must be a scalar integer, got array of shape " +
               shape_string(info.dims));
  Handle a = open_attr(obj, name, where);
  int64_t v = 0;
  if (H5Aread(a.get(), H5T_NATIVE_INT64, &v) < 0)
    where.fail("attribute '" + name + "' cannot be read");
  return v;
}

std::vector<double> read_float_vector_attr(hid_t obj, const std::string& name, size_t n,
                                           const Where& where) {
  const ArrayInfo info = attr_info(obj, name, where);
  if (!info.type.numeric || info.null_space ||
      info.dims.size() != 1 || info.dims[0] != n)
    where.fail("attribute '" + name + "' must be float[" + std::to_string(n) + "], got " +
               info.type.name + " of shape " + shape_string(info.dims));
  Handle a = open_attr(obj, name, where);
  std::vector<double> v(n);
  if (H5Aread(a.get(), H5T_NATIVE_DOUBLE, v.data()) < 0)
    where.fail("attribute '" + name + "' cannot be read");
  for (double x : v)
    if (!std::isfinite(x)) where.fail("attribute '" + name + "' is not finite");
  return v;
}

void write_string_attr(hid_t obj, const std::string& name, const std::string& value) {
  Handle t = make_string_type(true, 0, H5T_CSET_UTF8);
  const char* p = value.c_str();
  write_attr(obj, name, t.get(), t.get(), &p, {});
}

void write_string_array_attr(hid_t obj, const std::string& name,
                             const std::vector<std::string>& values) {
  Handle t = make_string_type(true, 0, H5T_CSET_UTF8);
  std::vector<const char*> p;
  for (const auto& s : values) p.push_back(s.c_str());
  write_attr(obj, name, t.get(), t.get(), p.data(), {values.size()});
}

void write_float_attr(hid_t obj, const std::string& name, double value) {
  write_attr(obj, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value, {});
}

void write_int_attr(hid_t obj, const std::string& name, int64_t value) {
  write_attr(obj, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value, {});
}

void write_float_vector_attr(hid_t obj, const std::string& name, const std::vector<double>& v) {
  write_attr(obj, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, v.data(), {v.size()});
}

Handle open_dataset(hid_t loc, const std::string& name, const Where& where) {
  if (!has_link(loc, name)) where.fail("missing dataset");
  ObjectType t;
  Handle o = open_object(loc, name, where, &t);
  if (t != ObjectType::kDataset) where.fail("must be a dataset, found a group or other object");
  Handle dcpl(H5Dget_create_plist(o.get()), H5Pclose);
  if (!dcpl.valid()) where.fail("cannot read dataset creation properties");
  const int n = H5Pget_nfilters(dcpl.get());
  if (n < 0) where.fail("cannot read dataset creation properties");
  for (int i = 0; i < n; ++i) {
    unsigned flags = 0, cd[8];
    size_t ncd = 8;
    char fname[64] = {0};
    const H5Z_filter_t id = H5Pget_filter2(dcpl.get(), static_cast<unsigned>(i), &flags, &ncd, cd,
                                           sizeof fname, fname, nullptr);
    if (id != H5Z_FILTER_DEFLATE && id != H5Z_FILTER_SHUFFLE) {
      const std::string label = id == H5Z_FILTER_FLETCHER32 ? "fletcher32"
                                : id == H5Z_FILTER_SZIP     ? "szip"
                                : id == H5Z_FILTER_NBIT     ? "nbit"
                                : id == H5Z_FILTER_SCALEOFFSET ? "scaleoffset"
                                : id == 32000               ? "lzf"
                                                            : "filter id " + std::to_string(id);
      where.fail("uses HDF5 filter '" + label + "'; only gzip and shuffle are allowed");
    }
  }
  return o;
}

ArrayInfo dataset_info(hid_t ds, const Where& where) {
  Handle type(H5Dget_type(ds), H5Tclose);
  Handle space(H5Dget_space(ds), H5Sclose);
  if (!type.valid() || !space.valid()) where.fail("cannot be read (no type or dataspace)");
  return describe_space(space.get(), describe_type(type.get()), where);
}

void check_array(const ArrayInfo& info, Kind kind, const std::vector<int64_t>& want,
                 const Where& where) {
  if (info.type.kind != kind)
    where.fail("dtype " + info.type.name + " is not allowed; must be " +
               (kind == Kind::kFloat ? "float32 or float64" : "int32 or int64"));
  if (info.null_space || info.dims.size() != want.size())
    where.fail("must have " + std::to_string(want.size()) + " dimensions, has shape " +
               shape_string(info.dims));
  for (size_t a = 0; a < want.size(); ++a) {
    if (want[a] >= 0 && info.dims[a] != static_cast<uint64_t>(want[a])) {
      std::string w = "(";
      for (size_t b = 0; b < want.size(); ++b)
        w += (b ? ", " : "") + (want[b] >= 0 ? std::to_string(want[b]) : std::string("*"));
      where.fail("shape " + shape_string(info.dims) + " does not match " + w + (want.size() == 1 ? ",)" : ")"));
    }
  }
}

std::vector<float> read_floats(hid_t ds, const ArrayInfo& info, const Where& where,
                               int64_t first, int64_t count) {
  ArrayInfo slab = info;
  const bool partial = count >= 0;
  if (partial) {
    if (info.dims.empty() || first < 0 || first + count > static_cast<int64_t>(info.dims[0]))
      where.fail("frame range out of bounds");
    slab.dims[0] = static_cast<uint64_t>(count);
  }
  const uint64_t n = element_count(slab, where);
  std::vector<float> out(n);
  if (n == 0) return out;
  herr_t status;
  if (partial) {
    Handle fspace(H5Dget_space(ds), H5Sclose);
    std::vector<hsize_t> start(info.dims.size(), 0), cnt(slab.dims.begin(), slab.dims.end());
    start[0] = static_cast<hsize_t>(first);
    H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start.data(), nullptr, cnt.data(), nullptr);
    Handle mspace(H5Screate_simple(static_cast<int>(cnt.size()), cnt.data(), nullptr), H5Sclose);
    status = H5Dread(ds, H5T_NATIVE_FLOAT, mspace.get(), fspace.get(), H5P_DEFAULT, out.data());
  } else {
    status = H5Dread(ds, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data());
  }
  if (status < 0) where.fail("cannot be read (truncated or corrupt data)");
  uint64_t bad = 0, first_bad = 0;
  for (uint64_t i = 0; i < n; ++i)
    if (!std::isfinite(out[i]) && bad++ == 0) first_bad = i;
  if (bad) {
    std::string idx = index_string(first_bad, slab.dims);
    if (partial && !slab.dims.empty()) {  // report the index in the whole dataset
      std::vector<uint64_t> full(slab.dims.size());
      uint64_t f = first_bad;
      for (size_t a = slab.dims.size(); a-- > 0;) { full[a] = f % slab.dims[a]; f /= slab.dims[a]; }
      full[0] += static_cast<uint64_t>(first);
      idx = shape_string(full);
    }
    where.fail(std::to_string(bad) + " non-finite values (NaN or inf" +
               std::string(info.type.size == 8 ? ", or beyond float32 range" : "") +
               "), first at index " + idx);
  }
  return out;
}

std::vector<int64_t> read_ints(hid_t ds, const ArrayInfo& info, const Where& where) {
  const uint64_t n = element_count(info, where);
  std::vector<int64_t> out(n);
  if (n == 0) return out;
  if (H5Dread(ds, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
    where.fail("cannot be read (truncated or corrupt data)");
  return out;
}

void write_floats(hid_t loc, const std::string& name, const float* data,
                  const std::vector<uint64_t>& dims, const WriteOptions& options) {
  if (options.float64) {
    uint64_t n = 1;
    for (auto d : dims) n *= d;
    std::vector<double> tmp(data, data + n);
    write_array(loc, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, tmp.data(), dims, options.gzip);
  } else {
    write_array(loc, name, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, data, dims, options.gzip);
  }
}

void write_doubles(hid_t loc, const std::string& name, const double* data,
                   const std::vector<uint64_t>& dims) {
  write_array(loc, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, data, dims, 0);
}

void write_ints(hid_t loc, const std::string& name, const int32_t* data,
                const std::vector<uint64_t>& dims, const WriteOptions& options) {
  write_array(loc, name, options.int64 ? H5T_STD_I64LE : H5T_STD_I32LE, H5T_NATIVE_INT32, data,
              dims, options.gzip);
}

void write_int64_scalar(hid_t loc, const std::string& name, int64_t value) {
  write_array(loc, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value, {}, 0);
}

}  // namespace layersnet::dataset::h5
