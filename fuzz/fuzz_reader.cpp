// libFuzzer target over the data layer's readers (scripts/fuzz.sh builds and runs it).
// Input byte 0 selects the mode (value % 3):
//   0  raw:        the rest is an HDF5 file image -> SequenceFile (in memory, no disk);
//   1  manifest:   the rest is dataset.json text -> parse_manifest;
//   2  structured: the rest drives 1..6 edits (delete an object, replace a dataset with any
//                  type/rank/shape/bytes, set or delete an attribute of any kind) of a valid
//                  synthetic sequence written into an in-memory HDF5 file, whose image is then
//                  read. This reaches the reader's checks with well-formed HDF5, which raw
//                  byte mutations rarely produce.
// A sequence the reader accepts must pass validate_sequence, and a training sample is built
// from it (downstream code must survive any spec-valid input). Every rejection must be a
// DatasetError; anything else (crash, sanitizer report, other exception) is a finding.
#include "dataset/h5.h"
#include "dataset/manifest.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"
#include "dataset/synthetic.h"

#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <span>
#include <string_view>

using namespace layersnet::dataset;

namespace {

const char* const kPaths[] = {"/body", "/body/vertices", "/body/faces", "/body/translation", "/garments",
                              "/garments/g0_tee", "/garments/g0_tee/vertices", "/garments/g0_tee/faces",
                              "/garments/g0_tee/uv", "/garments/g0_tee/panel", "/garments/g0_tee/rest",
                              "/garments/g1_jacket", "/garments/g1_jacket/vertices", "/garments/g1_jacket/faces",
                              "/garments/g1_jacket/uv", "/garments/g1_jacket/panel", "/wind", "/wind/rotation",
                              "/wind/strength", "/garments/extra", "/body/extra"};
const char* const kObjects[] = {"/", "/body", "/garments", "/garments/g0_tee", "/garments/g1_jacket", "/wind"};
const char* const kGarmentNames[] = {"g0_tee", "g1_jacket", "extra", ""};
const char* const kAttrs[] = {"format", "version", "fps", "up_axis", "gravity", "scale", "friction", "order",
                              "type", "tension_stiffness", "bending_stiffness", "mass", "self_friction"};

template <size_t N>
const char* pick(FuzzedDataProvider& p, const char* const (&list)[N]) {
  return list[p.ConsumeIntegralInRange<size_t>(0, N - 1)];
}

void replace_dataset(hid_t f, FuzzedDataProvider& p, int T) {
  const std::string path = pick(p, kPaths);
  if (H5Lexists(f, path.c_str(), H5P_DEFAULT) > 0) H5Ldelete(f, path.c_str(), H5P_DEFAULT);
  const hid_t types[] = {H5T_IEEE_F32LE, H5T_IEEE_F64LE, H5T_STD_I16LE, H5T_STD_I32LE, H5T_STD_I64LE,
                         H5T_STD_U32LE, H5T_IEEE_F32BE, H5T_STD_I32BE};
  const hid_t type = types[p.ConsumeIntegralInRange<size_t>(0, 7)];
  const int rank = p.ConsumeIntegralInRange(0, 3);
  hsize_t dims[3];
  hsize_t n = 1;
  for (int a = 0; a < rank; ++a) {
    const hsize_t choices[] = {0, 1, 2, 3, 4, 6, static_cast<hsize_t>(T), 32};
    dims[a] = choices[p.ConsumeIntegralInRange(0, 7)];
    n *= dims[a];
  }
  const size_t bytes = n * H5Tget_size(type);
  std::vector<uint8_t> data = p.ConsumeBytes<uint8_t>(bytes);
  data.resize(bytes, static_cast<uint8_t>(p.ConsumeIntegral<uint8_t>()));
  hid_t space = rank ? H5Screate_simple(rank, dims, nullptr) : H5Screate(H5S_SCALAR);
  hid_t ds = H5Dcreate2(f, path.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (ds >= 0) {
    if (n) H5Dwrite(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data());
    H5Dclose(ds);
  }
  H5Sclose(space);
}

void set_attribute(hid_t f, FuzzedDataProvider& p) {
  const hid_t obj = H5Oopen(f, pick(p, kObjects), H5P_DEFAULT);
  if (obj < 0) return;
  const std::string name = pick(p, kAttrs);
  switch (p.ConsumeIntegralInRange(0, 5)) {
    case 0: layersnet::dataset::h5::write_string_attr(obj, name, p.ConsumeRandomLengthString(16)); break;
    case 1: layersnet::dataset::h5::write_float_attr(obj, name, p.ConsumeFloatingPoint<double>()); break;
    case 2: layersnet::dataset::h5::write_int_attr(obj, name, p.ConsumeIntegral<int64_t>()); break;
    case 3: {
      std::vector<double> v(p.ConsumeIntegralInRange(0, 4));
      for (auto& x : v) x = p.ConsumeFloatingPoint<double>();
      if (!v.empty()) layersnet::dataset::h5::write_float_vector_attr(obj, name, v);
      break;
    }
    case 4: {
      std::vector<std::string> v;
      for (int i = p.ConsumeIntegralInRange(0, 3); i > 0; --i)
        v.push_back(p.ConsumeBool() ? std::string(pick(p, kGarmentNames)) : p.ConsumeRandomLengthString(8));
      layersnet::dataset::h5::write_string_array_attr(obj, name, v);
      break;
    }
    default: H5Adelete(obj, name.c_str()); break;
  }
  H5Oclose(obj);
}

std::vector<uint8_t> structured_image(FuzzedDataProvider& p) {
  SyntheticOptions o;
  o.frames = p.ConsumeIntegralInRange(3, 5);
  o.garments = p.ConsumeIntegralInRange(1, 2);
  o.rings = 3;
  o.segments = p.ConsumeBool() ? 4 : 6;
  o.body_rings = 2;
  o.body_segments = 4;
  o.wind = p.ConsumeBool();
  SequenceWriteOptions w;
  w.float64 = p.ConsumeBool();
  w.int64 = p.ConsumeBool();
  w.gzip = p.ConsumeBool() ? 1 : 0;
  w.write_translation = p.ConsumeBool();
  const hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  H5Pset_fapl_core(fapl, 1 << 16, 0);  // in memory, never written to disk
  const hid_t f = H5Fcreate("fuzz-structured.h5", H5F_ACC_TRUNC, H5P_DEFAULT, fapl);
  H5Pclose(fapl);
  std::vector<uint8_t> image;
  if (f < 0) return image;
  write_sequence_contents(f, make_synthetic_sequence(o), w, "fuzz-structured.h5");
  for (int k = p.ConsumeIntegralInRange(1, 6); k > 0 && p.remaining_bytes() > 0; --k) {
    switch (p.ConsumeIntegralInRange(0, 2)) {
      case 0: {
        const char* path = pick(p, kPaths);
        if (H5Lexists(f, path, H5P_DEFAULT) > 0) H5Ldelete(f, path, H5P_DEFAULT);
        break;
      }
      case 1: replace_dataset(f, p, o.frames); break;
      default: set_attribute(f, p); break;
    }
  }
  H5Fflush(f, H5F_SCOPE_GLOBAL);
  const ssize_t size = H5Fget_file_image(f, nullptr, 0);
  if (size > 0) {
    image.resize(static_cast<size_t>(size));
    if (H5Fget_file_image(f, image.data(), image.size()) < 0) image.clear();
  }
  H5Fclose(f);
  return image;
}

void read_image(std::span<const uint8_t> image, const char* name) {
  const SequenceFile file(image, name);
  const Sequence seq = file.read_all();
  validate_sequence(seq, name);  // throws DatasetError = the reader accepted a bad file
  if (seq.info.total_garment_vertices() <= 4096 && seq.info.num_body_vertices <= 4096)
    (void)build_sample(seq.info, seq.frames, 2, NormalisationStats{}, nullptr);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  h5::set_max_elements(uint64_t{1} << 22);  // bounded allocations per dataset
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const std::span<const uint8_t> rest(data + 1, size - 1);
  try {
    switch (data[0] % 3) {
      case 0: read_image(rest, "fuzz.h5"); break;
      case 1: parse_manifest(std::string_view(reinterpret_cast<const char*>(rest.data()), rest.size()), "fuzz.json"); break;
      default: {
        FuzzedDataProvider p(rest.data(), rest.size());
        const std::vector<uint8_t> image = structured_image(p);
        if (!image.empty()) read_image(image, "fuzz-structured.h5");
      }
    }
  } catch (const DatasetError&) {
  }
  return 0;
}
