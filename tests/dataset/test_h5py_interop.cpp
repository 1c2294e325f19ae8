// Files written by h5py (the shared validator's own writer, as the Python generator would
// write them) are read by the C++ reader; h5py-written broken files are rejected.
#include "dataset/sequence.h"
#include "test_util.h"

#include <fstream>

namespace layersnet::dataset {
namespace {

const char* kScript = R"PY(
import sys, numpy as np
sys.path.insert(0, sys.argv[1])
import check_dlayers_h5 as c
d = sys.argv[2]
c._write_valid(d + "/valid.h5")
c._write_valid(d + "/valid_nowind.h5", with_wind=False)
c._write_valid(d + "/valid_gzip64.h5", mutate=lambda m: (m.__setitem__("_compression", {"body/vertices": "gzip", "garments/inner/vertices": "gzip"}),
    m.__setitem__("body/vertices", m["body/vertices"].astype(np.float64))))
def attr(k, v):
    def f(m): m["attrs"][k] = v
    return f
def put(k, v):
    def f(m): m[k] = v
    return f
c._write_valid(d + "/bad_version_float.h5", mutate=attr("version", 1.0))
c._write_valid(d + "/bad_bool_fps.h5", mutate=attr("fps", True))
c._write_valid(d + "/bad_order_scalar.h5", mutate=lambda m: (m.__setitem__("order", None),
    m.__setitem__("_post", {"o": lambda h: h["garments"].attrs.__setitem__("order", "inner")})))
c._write_valid(d + "/bad_lzf.h5", mutate=put("_compression", {"garments/inner/vertices": "lzf"}))
c._write_valid(d + "/bad_uint_faces.h5", mutate=lambda m: m.__setitem__("garments/inner/faces", m["garments/inner/faces"].astype(np.uint32)))
c._write_valid(d + "/bad_nan_uv.h5", mutate=lambda m: m["garments/outer/uv"].__setitem__((0, 1, 1), np.nan))
)PY";

TEST(H5pyInterop, ReadsH5pyFilesAndRejectsBrokenOnes) {
  if (!testing::validator_available()) GTEST_SKIP() << "/usr/bin/python3 with h5py is missing";
  const auto dir = testing::temp_dir("h5py");
  const std::string script = (dir / "write.py").string();
  std::ofstream(script) << kScript;
  const std::string tools = std::filesystem::path(testing::validator_path()).parent_path().string();
  ASSERT_EQ(std::system(("/usr/bin/python3 '" + script + "' '" + tools + "' '" + dir.string() + "'").c_str()), 0);
  for (const char* name : {"valid.h5", "valid_nowind.h5", "valid_gzip64.h5"}) {
    SCOPED_TRACE(name);
    Sequence s;
    ASSERT_NO_THROW(s = read_sequence((dir / name).string()));
    EXPECT_EQ(s.info.num_frames, 4);
    ASSERT_EQ(s.info.num_garments(), 2);
    EXPECT_EQ(s.info.garments[0].name, "inner");  // layer order from attr 'order'
    EXPECT_EQ(s.info.garments[1].type, "skirt_2_panels");
    EXPECT_EQ(s.info.garments[0].num_vertices, 5);
    EXPECT_FLOAT_EQ(s.info.gravity.z(), -98.f);
    EXPECT_FLOAT_EQ(s.info.body_friction, 50.f);
    EXPECT_EQ(s.info.has_wind, std::string(name) != "valid_nowind.h5");
    EXPECT_FLOAT_EQ(s.body_at(3)(1, 0), 1.03f);
  }
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"bad_version_float.h5", "'version' must be an integer"},
      {"bad_bool_fps.h5", "'fps' must be a float"},
      {"bad_order_scalar.h5", "'order' must be a 1-D array of strings"},
      {"bad_lzf.h5", "filter 'lzf'"},
      {"bad_uint_faces.h5", "dtype uint32 is not allowed"},
      {"bad_nan_uv.h5", "non-finite"},
  };
  for (const auto& [name, message] : bad) {
    SCOPED_TRACE(name);
    try {
      read_sequence((dir / name).string());
      ADD_FAILURE() << "accepted";
    } catch (const DatasetError& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace layersnet::dataset
