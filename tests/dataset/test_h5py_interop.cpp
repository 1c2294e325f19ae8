// Files written by h5py (the generator's own writer, generate/write_h5.py, then edited in place
// the way other generators might write them) are read by the C++ reader; h5py-written broken
// files are rejected.
#include "dataset/sequence.h"
#include "test_util.h"

#include <fstream>

namespace layersnet::dataset {
namespace {

const char* kScript = R"PY(
import shutil, sys, h5py, numpy as np
sys.path.insert(0, sys.argv[1])
from write_h5 import write_sequence
d = sys.argv[2]
T = 4
body = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
fan = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
def garment(name, kind, z):
    x = np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z], [-1, 0, z]], float)
    return {"name": name, "type": kind, "vertices": np.stack([x] * T), "faces": fan,
            "uv": np.zeros((3, 3, 2)), "panel": np.zeros(3, int), "rest": x,
            "attrs": {"tension_stiffness": 50, "bending_stiffness": 60, "mass": 0.3, "self_friction": 50}}
seq = {"fps": 30, "gravity": (0, 0, -98), "scale": 10,
       "body": {"vertices": np.stack([body + [0.01 * t, 0, 0] for t in range(T)]),
                "faces": np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
                "translation": np.zeros((T, 3)), "friction": 50},
       "garments": [garment("inner", "tee", 0.5), garment("outer", "skirt_2_panels", 0.6)],
       "wind": {"rotation": np.tile([1.0, 0, 0, 0], (T, 1)), "strength": np.full(T, 100.0)}}
def variant(name, edit=None):
    write_sequence(d + "/" + name, seq)
    if edit:
        with h5py.File(d + "/" + name, "r+") as f:
            edit(f)
def recreate(f, path, data, **kw):
    del f[path]
    f.create_dataset(path, data=data, **kw)
variant("valid.h5")
variant("valid_nowind.h5", lambda f: f.__delitem__("wind"))
variant("valid_gzip64.h5", lambda f: recreate(f, "body/vertices", f["body/vertices"][()].astype(np.float64), compression="gzip"))
variant("bad_version_float.h5", lambda f: f.attrs.__setitem__("version", 1.0))
variant("bad_bool_fps.h5", lambda f: f.attrs.__setitem__("fps", np.bool_(True)))
variant("bad_order_scalar.h5", lambda f: f["garments"].attrs.__setitem__("order", "inner"))
variant("bad_lzf.h5", lambda f: recreate(f, "garments/inner/vertices", f["garments/inner/vertices"][()], compression="lzf"))
variant("bad_uint_faces.h5", lambda f: recreate(f, "garments/inner/faces", f["garments/inner/faces"][()].astype(np.uint32)))
def nan_uv(f):
    uv = f["garments/outer/uv"][()]
    uv[0, 1, 1] = np.nan
    f["garments/outer/uv"][...] = uv
variant("bad_nan_uv.h5", nan_uv)
)PY";

TEST(H5pyInterop, ReadsH5pyFilesAndRejectsBrokenOnes) {
  const auto dir = testing::temp_dir("h5py");
  const std::string script = (dir / "write.py").string();
  std::ofstream(script) << kScript;
  const std::string tools = std::string(LAYERSNET_SOURCE_DIR) + "/generate";
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
  std::string out;
  EXPECT_EQ(testing::run_validator((dir / "valid.h5").string() + "' '" + (dir / "valid_nowind.h5").string() + "' '" +
                                       (dir / "valid_gzip64.h5").string(),
                                   &out),
            0)
      << out;
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
    std::string why;
    EXPECT_EQ(testing::run_validator((dir / name).string(), &why), 1) << "the Python validator passed it: " << why;
  }
}

}  // namespace
}  // namespace layersnet::dataset
