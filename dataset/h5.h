#pragma once
// Thin RAII wrappers over the HDF5 C API and the checked read/write helpers the D-LAYERS-H5
// reader and writer are built from. Every HDF5 return code is checked; a failure becomes a
// DatasetError naming the file, the HDF5 object path and the problem. HDF5's own automatic
// error printing is switched off (our messages replace it).
#include "dataset/error.h"

#include <hdf5.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace layersnet::dataset::h5 {

// Owns one hid_t and closes it with the matching H5?close.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) : id_(id), close_(closer) {}
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  Handle(Handle&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = H5I_INVALID_HID; }
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      close_ = o.close_;
      o.id_ = H5I_INVALID_HID;
    }
    return *this;
  }
  ~Handle() { reset(); }
  void reset() {
    if (id_ >= 0 && close_) close_(id_);
    id_ = H5I_INVALID_HID;
  }
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }

 private:
  hid_t id_ = H5I_INVALID_HID;
  Closer close_ = nullptr;
};

// Largest number of elements one dataset may hold before the reader refuses it (guards
// against files that claim absurd extents; the fuzz target lowers it).
void set_max_elements(uint64_t n);
uint64_t max_elements();

// Element kind of a dataset or attribute as the spec sees it.
enum class Kind { kFloat, kInt, kString, kOther };

struct TypeInfo {
  Kind kind = Kind::kOther;
  size_t size = 0;       // bytes per element
  bool signed_int = true;
  bool numeric = false;  // any HDF5 integer or float class (attributes accept all of them)
  std::string name;      // "float32", "int16", "uint32", "string", "enum", ...
};

struct ArrayInfo {
  TypeInfo type;
  std::vector<uint64_t> dims;  // empty for a scalar dataspace
  bool null_space = false;
};

// Where errors point to: the file name shown to the user and the HDF5 object path.
struct Where {
  std::string file;
  std::string path;
  [[noreturn]] void fail(const std::string& problem) const;
};

std::string shape_string(const std::vector<uint64_t>& dims);

// ---- files and objects
Handle open_file(const std::string& path);  // read-only; throws "cannot be opened as HDF5"
// Opens an in-memory file image (the fuzz target; no disk access).
Handle open_file_image(std::span<const uint8_t> bytes, const std::string& name);
// Builds an HDF5 file in memory with `fill(file)`, then writes its bytes to `path` through
// io::write_file_atomic. libhdf5 never touches the disk: a full disk is one error naming the
// path (a failed flush inside libhdf5 crashed the program at exit), and nothing half-written
// is left behind.
void write_file(const std::string& path, const std::function<void(hid_t file)>& fill);
bool has_link(hid_t loc, const std::string& name);
enum class ObjectType { kGroup, kDataset, kOther };
// Opens a child object; throws when it cannot be opened (e.g. a dangling link).
Handle open_object(hid_t loc, const std::string& name, const Where& where, ObjectType* type);
Handle open_group(hid_t loc, const std::string& name, const Where& where);  // must be a group
std::vector<std::string> member_names(hid_t group, const Where& where);
Handle create_group(hid_t loc, const std::string& name, const Where& where);

// ---- attributes
bool has_attr(hid_t obj, const std::string& name);
ArrayInfo attr_info(hid_t obj, const std::string& name, const Where& where);
std::string read_string_attr(hid_t obj, const std::string& name, const Where& where);
std::vector<std::string> read_string_array_attr(hid_t obj, const std::string& name,
                                                const Where& where);
// A real number (an integer attribute is accepted too), finite, scalar.
double read_float_attr(hid_t obj, const std::string& name, const Where& where);
int64_t read_int_attr(hid_t obj, const std::string& name, const Where& where);
// A 1-D numeric attribute of exactly n values, finite.
std::vector<double> read_float_vector_attr(hid_t obj, const std::string& name, size_t n,
                                           const Where& where);

void write_string_attr(hid_t obj, const std::string& name, const std::string& value);
void write_string_array_attr(hid_t obj, const std::string& name,
                             const std::vector<std::string>& values);
void write_float_attr(hid_t obj, const std::string& name, double value);
void write_int_attr(hid_t obj, const std::string& name, int64_t value);
void write_float_vector_attr(hid_t obj, const std::string& name, const std::vector<double>& v);

// ---- datasets
// Opens a dataset and checks that only the gzip and shuffle filters are used.
Handle open_dataset(hid_t loc, const std::string& name, const Where& where);
ArrayInfo dataset_info(hid_t ds, const Where& where);
// Checks kind (float32/64 or int32/64), rank, and the fixed extents (-1 = any).
void check_array(const ArrayInfo& info, Kind kind, const std::vector<int64_t>& want,
                 const Where& where);
// Reads a hyperslab [first, first+count) along axis 0 (count < 0: everything) converted to
// float; throws on non-finite values, naming the first bad index.
std::vector<float> read_floats(hid_t ds, const ArrayInfo& info, const Where& where,
                               int64_t first = 0, int64_t count = -1);
std::vector<int64_t> read_ints(hid_t ds, const ArrayInfo& info, const Where& where);

struct WriteOptions {
  bool float64 = false;  // store floats as float64 instead of float32
  bool int64 = false;    // store integers as int64 instead of int32
  int gzip = 0;          // 0 = contiguous, 1..9 = chunked + shuffle + gzip level
};
void write_floats(hid_t loc, const std::string& name, const float* data,
                  const std::vector<uint64_t>& dims, const WriteOptions& options);
void write_doubles(hid_t loc, const std::string& name, const double* data,
                   const std::vector<uint64_t>& dims);
void write_ints(hid_t loc, const std::string& name, const int32_t* data,
                const std::vector<uint64_t>& dims, const WriteOptions& options);
void write_int64_scalar(hid_t loc, const std::string& name, int64_t value);

}  // namespace layersnet::dataset::h5
