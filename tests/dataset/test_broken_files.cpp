// At least 30 broken files, each rejected with an error naming the file,
// the HDF5 object path and the problem. Each broken file starts as a valid synthetic
// sequence (2 garments "g0_tee", "g1_jacket", wind, T = 8) and is changed with the HDF5 C
// API. When /usr/bin/python3 has h5py, the Python validator must reject every one too
// (proving that each case really breaks the spec).
#include "dataset/h5.h"
#include "dataset/manifest.h"
#include "dataset/sequence.h"
#include "dataset/synthetic.h"
#include "test_util.h"

#include <filesystem>
#include <fstream>
#include <functional>

namespace layersnet::dataset {
namespace {

namespace fs = std::filesystem;
using Mutation = std::function<void(hid_t file)>;

struct BrokenCase {
  std::string name;
  Mutation mutate;
  std::string object;   // expected substring of the error's object path
  std::string message;  // expected substring of the problem
};

// ---- mutation helpers (raw HDF5 so that any type or shape can be produced)
void remove(hid_t f, const std::string& path) { ASSERT_GE(H5Ldelete(f, path.c_str(), H5P_DEFAULT), 0) << path; }

void put(hid_t f, const std::string& path, hid_t file_type, hid_t mem_type, const void* data,
         std::vector<hsize_t> dims, hid_t dcpl = H5P_DEFAULT) {
  if (H5Lexists(f, path.c_str(), H5P_DEFAULT) > 0) remove(f, path);
  hid_t space = dims.empty() ? H5Screate(H5S_SCALAR) : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  hid_t ds = H5Dcreate2(f, path.c_str(), file_type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << path;
  hsize_t n = 1;
  for (auto d : dims) n *= d;
  if (n) H5Dwrite(ds, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
  H5Dclose(ds);
  H5Sclose(space);
}

void put_floats(hid_t f, const std::string& path, std::vector<float> v, std::vector<hsize_t> dims) {
  put(f, path, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, v.data(), std::move(dims));
}

void put_ints(hid_t f, const std::string& path, std::vector<int32_t> v, std::vector<hsize_t> dims,
              hid_t file_type = H5T_STD_I32LE) {
  put(f, path, file_type, H5T_NATIVE_INT32, v.data(), std::move(dims));
}

// Reads a float dataset, lets `edit` change it (and its dims), writes it back as float32.
void edit_floats(hid_t f, const std::string& path, const std::function<void(std::vector<float>&, std::vector<hsize_t>&)>& edit) {
  hid_t ds = H5Dopen2(f, path.c_str(), H5P_DEFAULT);
  hid_t space = H5Dget_space(ds);
  std::vector<hsize_t> dims(H5Sget_simple_extent_ndims(space));
  H5Sget_simple_extent_dims(space, dims.data(), nullptr);
  hsize_t n = 1;
  for (auto d : dims) n *= d;
  std::vector<float> v(n);
  H5Dread(ds, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
  H5Sclose(space);
  H5Dclose(ds);
  edit(v, dims);
  put_floats(f, path, v, dims);
}

void edit_ints(hid_t f, const std::string& path, const std::function<void(std::vector<int32_t>&, std::vector<hsize_t>&)>& edit) {
  hid_t ds = H5Dopen2(f, path.c_str(), H5P_DEFAULT);
  hid_t space = H5Dget_space(ds);
  std::vector<hsize_t> dims(H5Sget_simple_extent_ndims(space));
  H5Sget_simple_extent_dims(space, dims.data(), nullptr);
  hsize_t n = 1;
  for (auto d : dims) n *= d;
  std::vector<int32_t> v(n);
  H5Dread(ds, H5T_NATIVE_INT32, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
  H5Sclose(space);
  H5Dclose(ds);
  edit(v, dims);
  put_ints(f, path, v, dims);
}

hid_t object(hid_t f, const std::string& path) { return H5Oopen(f, path.c_str(), H5P_DEFAULT); }

void with_object(hid_t f, const std::string& path, const std::function<void(hid_t)>& fn) {
  hid_t o = object(f, path);
  ASSERT_GE(o, 0) << path;
  fn(o);
  H5Oclose(o);
}

Mutation set_string_attr(std::string obj, std::string key, std::string value) {
  return [=](hid_t f) { with_object(f, obj, [&](hid_t o) { h5::write_string_attr(o, key, value); }); };
}
Mutation set_float_attr(std::string obj, std::string key, double value) {
  return [=](hid_t f) { with_object(f, obj, [&](hid_t o) { h5::write_float_attr(o, key, value); }); };
}
Mutation del_attr(std::string obj, std::string key) {
  return [=](hid_t f) { with_object(f, obj, [&](hid_t o) { H5Adelete(o, key.c_str()); }); };
}
Mutation del(std::string path) {
  return [=](hid_t f) { remove(f, path); };
}

const std::string kG0 = "/garments/g0_tee";
const std::string kG1 = "/garments/g1_jacket";
constexpr int kT = 8;

std::vector<BrokenCase> sequence_cases() {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<BrokenCase> c;
  // ---- root attributes
  c.push_back({"wrong_format", set_string_attr("/", "format", "dlayers"), "/", "'format' is 'dlayers'"});
  c.push_back({"unknown_version", [](hid_t f) { with_object(f, "/", [](hid_t o) { h5::write_int_attr(o, "version", 2); }); },
               "/", "'version' is 2, must be 1"});
  c.push_back({"version_is_float", set_float_attr("/", "version", 1.0), "/", "'version' must be an integer"});
  c.push_back({"missing_scale", del_attr("/", "scale"), "/", "missing attribute 'scale'"});
  c.push_back({"bad_up_axis", set_string_attr("/", "up_axis", "x"), "/", "'up_axis' is 'x'"});
  c.push_back({"gravity_sideways", [](hid_t f) { with_object(f, "/", [](hid_t o) {
                 h5::write_float_vector_attr(o, "gravity", {0, -9.8, 0}); }); },
               "/", "does not point along -z"});
  c.push_back({"gravity_two_values", [](hid_t f) { with_object(f, "/", [](hid_t o) {
                 h5::write_float_vector_attr(o, "gravity", {0, -9.8}); }); },
               "/", "'gravity' must be float[3]"});
  c.push_back({"fps_zero", set_float_attr("/", "fps", 0.0), "/", "'fps' must be > 0"});
  c.push_back({"fps_nan", set_float_attr("/", "fps", nan), "/", "'fps' is not finite"});
  c.push_back({"format_is_array", [](hid_t f) { with_object(f, "/", [](hid_t o) {
                 h5::write_string_array_attr(o, "format", {"dlayers-h5"}); }); },
               "/", "'format' must be a scalar string"});
  // ---- body
  c.push_back({"missing_body", del("/body"), "/body", "missing group"});
  c.push_back({"missing_body_faces", del("/body/faces"), "/body/faces", "missing dataset"});
  c.push_back({"body_vertices_rank2", [](hid_t f) { edit_floats(f, "/body/vertices", [](auto&, auto& d) {
                 d = {d[0], d[1] * 3}; }); },
               "/body/vertices", "must have 3 dimensions"});
  c.push_back({"body_vertices_last_dim_2", [](hid_t f) { edit_floats(f, "/body/vertices", [](auto& v, auto& d) {
                 v.resize(d[0] * d[1] * 2); d[2] = 2; }); },
               "/body/vertices", "does not match (*, *, 3)"});
  c.push_back({"body_faces_inward", [](hid_t f) { edit_ints(f, "/body/faces", [](auto& v, auto&) {
                 for (size_t i = 0; i < v.size(); i += 3) std::swap(v[i], v[i + 2]); }); },
               "/body/faces", "oriented inward"});
  c.push_back({"body_faces_empty", [](hid_t f) { put_ints(f, "/body/faces", {}, {0, 3}); }, "/body/faces", "has no faces"});
  c.push_back({"missing_body_friction", del_attr("/body", "friction"), "/body", "missing attribute 'friction'"});
  c.push_back({"too_few_frames", [](hid_t f) {
                 edit_floats(f, "/body/vertices", [](auto& v, auto& d) { v.resize(2 * d[1] * 3); d[0] = 2; }); },
               "/body/vertices", "T = 2 frames, must be >= 3"});
  c.push_back({"translation_T_mismatch", [](hid_t f) {
                 edit_floats(f, "/body/translation", [](auto& v, auto& d) { v.resize(5 * 3); d[0] = 5; }); },
               "/body/translation", "does not match (8, 3)"});
  c.push_back({"body_inf_position", [](hid_t f) { edit_floats(f, "/body/vertices", [](auto& v, auto&) {
                 v[3 * 98 * 5 + 7] = std::numeric_limits<float>::infinity(); }); },
               "/body/vertices", "non-finite"});
  c.push_back({"body_position_beyond_extent", [](hid_t f) { edit_floats(f, "/body/vertices", [](auto& v, auto&) {
                 v[3 * 98 * 4 + 3 * 2 + 1] = 3e38f; }); },
               "/body/vertices", "holds the coordinate 3e+38 at frame 4, vertex 2, beyond the scene extent"});
  c.push_back({"body_friction_negative", set_float_attr("/body", "friction", -5.0), "/body",
               "attribute 'friction' = -5 is negative"});
  c.push_back({"body_faces_uint32", [](hid_t f) { edit_ints(f, "/body/faces", [](auto&, auto&) {});
                 hid_t ds = H5Dopen2(f, "/body/faces", H5P_DEFAULT); hid_t sp = H5Dget_space(ds);
                 hsize_t d[2]; H5Sget_simple_extent_dims(sp, d, nullptr);
                 std::vector<int32_t> v(d[0] * 3); H5Dread(ds, H5T_NATIVE_INT32, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
                 H5Sclose(sp); H5Dclose(ds); put_ints(f, "/body/faces", v, {d[0], 3}, H5T_STD_U32LE); },
               "/body/faces", "dtype uint32 is not allowed"});
  // ---- garments
  c.push_back({"garment_T_mismatch", [](hid_t f) {
                 edit_floats(f, kG0 + "/vertices", [](auto& v, auto& d) { v.resize(4 * d[1] * 3); d[0] = 4; }); },
               kG0 + "/vertices", "has 4 frames but /body/vertices has 8"});
  c.push_back({"garment_no_vertices", [](hid_t f) { put_floats(f, kG1 + "/vertices", {}, {kT, 0, 3}); },
               kG1 + "/vertices", "has no vertices"});
  c.push_back({"face_index_too_large", [](hid_t f) { edit_ints(f, kG0 + "/faces", [](auto& v, auto&) { v[5] = 96; }); },
               kG0 + "/faces", "1 face indices out of range [0, 96)"});
  c.push_back({"face_index_negative", [](hid_t f) { edit_ints(f, kG1 + "/faces", [](auto& v, auto&) { v[0] = -1; }); },
               kG1 + "/faces", "out of range"});
  c.push_back({"garment_nan_position", [](hid_t f) { edit_floats(f, kG1 + "/vertices", [](auto& v, auto&) {
                 v[96 * 3 * 6 + 3 * 10 + 2] = std::numeric_limits<float>::quiet_NaN(); }); },
               kG1 + "/vertices", "1 non-finite values (NaN or inf), first at index (6, 10, 2)"});
  c.push_back({"uv_nan", [](hid_t f) { edit_floats(f, kG0 + "/uv", [](auto& v, auto&) {
                 v[1] = std::numeric_limits<float>::quiet_NaN(); }); },
               kG0 + "/uv", "non-finite"});
  c.push_back({"uv_rank2", [](hid_t f) { edit_floats(f, kG1 + "/uv", [](auto&, auto& d) { d = {d[0], 6}; }); },
               kG1 + "/uv", "must have 3 dimensions"});
  c.push_back({"uv_F_mismatch", [](hid_t f) { edit_floats(f, kG1 + "/uv", [](auto& v, auto& d) {
                 d[0] -= 1; v.resize(d[0] * 6); }); },
               kG1 + "/uv", "does not match (160, 3, 2)"});
  c.push_back({"faces_int16", [](hid_t f) {
                 std::vector<int32_t> v(160 * 3, 0); put_ints(f, kG0 + "/faces", v, {160, 3}, H5T_STD_I16LE); },
               kG0 + "/faces", "dtype int16 is not allowed"});
  c.push_back({"panel_float", [](hid_t f) { put_floats(f, kG0 + "/panel", std::vector<float>(160, 0.f), {160}); },
               kG0 + "/panel", "dtype float32 is not allowed"});
  c.push_back({"panel_negative", [](hid_t f) { edit_ints(f, kG0 + "/panel", [](auto& v, auto&) { v[3] = -1; }); },
               kG0 + "/panel", "1 negative panel ids"});
  c.push_back({"rest_N_mismatch", [](hid_t f) { put_floats(f, kG1 + "/rest", std::vector<float>(12, 0.f), {4, 3}); },
               kG1 + "/rest", "does not match (96, 3)"});
  c.push_back({"pin_N_mismatch", [](hid_t f) { put_floats(f, kG1 + "/pin", std::vector<float>(4, 1.f), {4}); },
               kG1 + "/pin", "shape (4,) does not match (96,)"});
  c.push_back({"pin_weight_above_one", [](hid_t f) {
                 std::vector<float> w(96, 0.f);
                 w[7] = 1.5f;
                 put_floats(f, kG0 + "/pin", w, {96}); },
               kG0 + "/pin", "weight 1.500000 of vertex 7 is outside [0, 1]"});
  c.push_back({"garment_missing_mass", del_attr(kG0, "mass"), kG0, "missing attribute 'mass'"});
  c.push_back({"garment_inf_bending", set_float_attr(kG1, "bending_stiffness", std::numeric_limits<double>::infinity()),
               kG1, "'bending_stiffness' is not finite"});
  c.push_back({"garment_mass_1e300", set_float_attr(kG0, "mass", 1e300), kG0,
               "attribute 'mass' = 1e+300 is not finite in float32"});
  c.push_back({"garment_empty_type", set_string_attr(kG0, "type", ""), kG0, "attribute 'type' is empty"});
  c.push_back({"order_names_missing_garment", [](hid_t f) { with_object(f, "/garments", [](hid_t o) {
                 h5::write_string_array_attr(o, "order", {"g0_tee", "middle", "g1_jacket"}); }); },
               "/garments", "names ['middle'] which are not garment groups"});
  c.push_back({"garment_not_in_order", [](hid_t f) { with_object(f, "/garments", [](hid_t o) {
                 h5::write_string_array_attr(o, "order", {"g0_tee"}); }); },
               "/garments", "['g1_jacket'] are not listed"});
  c.push_back({"order_duplicate", [](hid_t f) { with_object(f, "/garments", [](hid_t o) {
                 h5::write_string_array_attr(o, "order", {"g0_tee", "g1_jacket", "g0_tee"}); }); },
               "/garments", "lists 'g0_tee' more than once"});
  c.push_back({"missing_order", del_attr("/garments", "order"), "/garments", "missing attribute 'order'"});
  c.push_back({"empty_garment_list", [](hid_t f) { remove(f, kG0); remove(f, kG1);
                 with_object(f, "/garments", [](hid_t o) { h5::write_string_array_attr(o, "order", {}); }); },
               "/garments", "has no garment"});
  c.push_back({"dataset_under_garments", [](hid_t f) { put_floats(f, "/garments/junk", {1, 2, 3}, {3}); },
               "/garments/junk", "must be a group"});
  c.push_back({"fletcher32_filter", [](hid_t f) {
                 hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE); hsize_t chunk[1] = {160};
                 H5Pset_chunk(dcpl, 1, chunk); H5Pset_fletcher32(dcpl);
                 std::vector<int32_t> v(160, 0);
                 put(f, kG1 + "/panel", H5T_STD_I32LE, H5T_NATIVE_INT32, v.data(), {160}, dcpl); H5Pclose(dcpl); },
               kG1 + "/panel", "filter 'fletcher32'"});
  // ---- wind
  c.push_back({"wind_T_mismatch", [](hid_t f) { put_floats(f, "/wind/strength", std::vector<float>(5, 0.f), {5}); },
               "/wind/strength", "does not match (8,)"});
  c.push_back({"wind_non_unit_quaternion", [](hid_t f) { edit_floats(f, "/wind/rotation", [](auto& v, auto&) { v[2 * 4] = 0.5f; }); },
               "/wind/rotation", "not unit within 0.001 (first at frame 2"});
  c.push_back({"wind_is_a_dataset", [](hid_t f) { remove(f, "/wind"); put_floats(f, "/wind", {0, 0, 0}, {3}); },
               "/wind", "must be a group"});
  c.push_back({"wind_missing_strength", del("/wind/strength"), "/wind/strength", "missing dataset"});
  return c;
}

class BrokenFiles : public ::testing::Test {
 protected:
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  void SetUp() override {
    dir_ = testing::temp_path("broken");
    SyntheticOptions o;
    o.frames = kT;
    o.garments = 2;
    o.wind = true;
    valid_ = make_synthetic_sequence(o);
  }
  std::string make_case(const BrokenCase& c) {
    const std::string path = (dir_ / (c.name + ".h5")).string();
    write_sequence(path, valid_);
    hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(f, 0);
    c.mutate(f);
    H5Fclose(f);
    return path;
  }
  fs::path dir_;
  Sequence valid_;
};

void expect_rejected(const std::string& path, const std::string& object, const std::string& message,
                     const std::function<void()>& read) {
  try {
    read();
    ADD_FAILURE() << path << ": accepted, expected '" << object << ": " << message << "'";
  } catch (const DatasetError& e) {
    EXPECT_EQ(e.file(), path);
    EXPECT_NE(e.object().find(object), std::string::npos) << "got: " << e.what();
    EXPECT_NE(e.problem().find(message), std::string::npos) << "got: " << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos);
  } catch (const std::exception& e) {
    ADD_FAILURE() << path << ": wrong exception type: " << e.what();
  }
}

TEST_F(BrokenFiles, EveryBrokenSequenceIsRejectedWithTheRightMessage) {
  const auto cases = sequence_cases();
  ASSERT_GE(cases.size(), 30u);
  std::vector<std::string> paths;
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = make_case(c);
    paths.push_back(path);
    expect_rejected(path, c.object, c.message, [&] { read_sequence(path); });
  }
  // The Python validator must reject every one of them, too.
  std::string all;
  for (const auto& p : paths) all += (all.empty() ? "" : "' '") + p;
  std::string out;
  EXPECT_EQ(testing::run_validator(all, &out), 1) << out;
  for (const auto& p : paths) EXPECT_NE(out.find(p + ": /"), std::string::npos) << p << " passed the validator";
}

TEST_F(BrokenFiles, UnreadableFilesAreRejected) {
  const std::string good = (dir_ / "good.h5").string();
  write_sequence(good, valid_);
  const auto size = fs::file_size(good);
  for (double frac : {0.0, 0.001, 0.3, 0.6, 0.95}) {
    const std::string p = (dir_ / ("truncated_" + std::to_string(frac) + ".h5")).string();
    fs::copy_file(good, p, fs::copy_options::overwrite_existing);
    fs::resize_file(p, static_cast<uintmax_t>(frac * size));
    expect_rejected(p, "/", "cannot be opened as HDF5", [&] { read_sequence(p); });
  }
  const std::string text = (dir_ / "text.h5").string();
  std::ofstream(text) << "this is not an HDF5 file\n";
  expect_rejected(text, "/", "cannot be opened as HDF5", [&] { read_sequence(text); });
  const std::string missing = (dir_ / "missing.h5").string();
  expect_rejected(missing, "/", "cannot be opened as HDF5", [&] { read_sequence(missing); });
}

TEST_F(BrokenFiles, CorruptedBytesNeverCrashOrPassSilently) {
  // Flip bytes inside the data region: either the read fails with a DatasetError, or the
  // values it returns still satisfy the spec (then the corruption hit padding or metadata
  // HDF5 does not use).
  const std::string good = (dir_ / "good.h5").string();
  write_sequence(good, valid_);
  std::string bytes;
  {
    std::ifstream in(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  int rejected = 0;
  for (int k = 0; k < 40; ++k) {
    std::string b = bytes;
    const size_t pos = (static_cast<size_t>(k) * 7919u * 13u) % b.size();
    for (size_t i = pos; i < std::min(b.size(), pos + 8); ++i) b[i] = static_cast<char>(0xff);
    const std::string p = (dir_ / ("corrupt_" + std::to_string(k) + ".h5")).string();
    std::ofstream(p, std::ios::binary) << b;
    try {
      const Sequence s = read_sequence(p);
      EXPECT_NO_THROW(validate_sequence(s, p));
    } catch (const DatasetError& e) {
      ++rejected;
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos);
    }
  }
  RecordProperty("rejected", rejected);
}

// ---- dataset.json and folders
TEST_F(BrokenFiles, BrokenManifestsAreRejected) {
  struct ManifestCase {
    std::string json, object, message;
  };
  const std::vector<ManifestCase> cases = {
      {R"({"format":"dlayers-h5","version":1,"source":"t","splits":{"train":["a","b"],"val":["b"]}})",
       "/splits/val", "sequence id 'b' appears also in split 'train'"},
      {R"({"format":"dlayers-h5","version":1,"source":"t","splits":{"train":["a","a"]}})",
       "/splits/train", "appears twice in this split"},
      {R"({"format":"dlayers-h5","version":1,"source":"t","splits":{"training":[]}})",
       "/splits/training", "unknown split name"},
      {R"({"format":"dlayers-h5","version":"1","source":"t","splits":{}})", "/version", "must be the integer 1"},
      {R"({"format":"dlayers-h5","version":1.0,"source":"t","splits":{}})", "/version", "must be the integer 1"},
      {R"({"format":"dlayers","version":1,"source":"t","splits":{}})", "/format", "must be 'dlayers-h5'"},
      {R"({"format":"dlayers-h5","version":1,"splits":{}})", "/source", "missing"},
      {R"({"format":"dlayers-h5","version":1,"source":"t","splits":{"test":["x/y"]}})", "/splits/test",
       "invalid sequence id \"x/y\""},
      {R"({"format":"dlayers-h5","version":1,"source":"t","splits":{"test":[3]}})", "/splits/test", "invalid sequence id 3"},
      {R"({"format":"dlayers-h5","version":1,"source":"t","splits":[]})", "/splits", "missing or not an object"},
      {R"({"format":"dlayers-h5", "version":1,)", "/", "is not valid JSON"},
      {R"([1,2])", "/", "must be a JSON object"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.json);
    expect_rejected("m.json", c.object, c.message, [&] { parse_manifest(c.json, "m.json"); });
  }
  // A listed sequence whose file is missing.
  const fs::path root = dir_ / "ds";
  fs::create_directories(root);
  std::ofstream(root / "dataset.json")
      << R"({"format":"dlayers-h5","version":1,"source":"t","splits":{"train":["zz"]}})";
  expect_rejected((root / "dataset.json").string(), "/splits/train", "sequence 'zz': file",
                  [&] { read_manifest(root.string()); });
  expect_rejected((dir_ / "nowhere" / "dataset.json").string(), "/", "missing dataset.json",
                  [&] { read_manifest((dir_ / "nowhere").string()); });
}

}  // namespace
}  // namespace layersnet::dataset
