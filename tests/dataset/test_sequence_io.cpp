// Reader/writer round trips, data-set folders, and agreement with the Python validator.
#include "dataset/h5.h"
#include "dataset/manifest.h"
#include "dataset/sequence.h"
#include "dataset/synthetic.h"
#include "dataset/neighbours.h"
#include "dataset/wind.h"
#include "test_util.h"

#include <fstream>

namespace layersnet::dataset {
namespace {

using testing::temp_dir;

void expect_same(const Sequence& a, const Sequence& b, float tol) {
  ASSERT_EQ(a.info.num_frames, b.info.num_frames);
  ASSERT_EQ(a.info.num_body_vertices, b.info.num_body_vertices);
  EXPECT_EQ(a.info.body_faces, b.info.body_faces);
  EXPECT_TRUE(a.frames.body.isApprox(b.frames.body, tol));
  EXPECT_TRUE(a.info.translation.isApprox(b.info.translation, tol) ||
              (a.info.translation.norm() == 0 && b.info.translation.norm() == 0));
  EXPECT_FLOAT_EQ(a.info.fps, b.info.fps);
  EXPECT_EQ(a.info.up_axis, b.info.up_axis);
  EXPECT_TRUE(a.info.gravity.isApprox(b.info.gravity));
  EXPECT_FLOAT_EQ(a.info.body_friction, b.info.body_friction);
  ASSERT_EQ(a.info.num_garments(), b.info.num_garments());
  for (int g = 0; g < a.info.num_garments(); ++g) {
    const auto &ga = a.info.garments[g], &gb = b.info.garments[g];
    EXPECT_EQ(ga.name, gb.name);
    EXPECT_EQ(ga.type, gb.type);
    EXPECT_EQ(ga.faces, gb.faces);
    EXPECT_EQ(ga.panel, gb.panel);
    EXPECT_TRUE(ga.uv.isApprox(gb.uv, tol));
    EXPECT_TRUE(ga.rest.isApprox(gb.rest, tol));
    EXPECT_EQ(ga.pin, gb.pin);
    EXPECT_FLOAT_EQ(ga.attributes.mass, gb.attributes.mass);
    EXPECT_FLOAT_EQ(ga.attributes.tension_stiffness, gb.attributes.tension_stiffness);
    EXPECT_TRUE(a.frames.garments[g].isApprox(b.frames.garments[g], tol));
  }
  ASSERT_EQ(a.info.has_wind, b.info.has_wind);
  if (a.info.has_wind) {
    EXPECT_TRUE(a.info.wind_rotation.isApprox(b.info.wind_rotation));
    EXPECT_TRUE(a.info.wind_strength.isApprox(b.info.wind_strength));
  }
}

TEST(SequenceIo, SyntheticSceneHasTheAdvertisedShape) {
  SyntheticOptions o;
  o.frames = 5;
  o.garments = 2;
  o.rings = 4;
  o.segments = 8;
  o.wind = true;
  const Sequence s = make_synthetic_sequence(o);
  EXPECT_EQ(s.info.num_frames, 5);
  ASSERT_EQ(s.info.num_garments(), 2);
  EXPECT_EQ(s.info.garments[0].num_vertices, 32);
  EXPECT_EQ(s.info.garments[0].num_faces(), 2 * 3 * 8);
  EXPECT_EQ(s.frames.garments[1].rows(), 5 * 32);
  // Two panels, half of the faces each.
  int p1 = 0;
  for (int p : s.info.garments[0].panel) p1 += p;
  EXPECT_EQ(p1, 24);
  // Body: 4 rings... default body_rings 6 x 16 + 2 cap centres.
  EXPECT_EQ(s.info.num_body_vertices, 6 * 16 + 2);
  EXPECT_NO_THROW(validate_sequence(s, "synthetic"));
}

TEST(SequenceIo, RoundTripFloat32Int32) {
  const auto dir = temp_dir("rt");
  SyntheticOptions o;
  o.garments = 2;
  o.wind = true;
  const Sequence s = make_synthetic_sequence(o);
  write_sequence((dir / "a.h5").string(), s);
  const Sequence r = read_sequence((dir / "a.h5").string());
  expect_same(s, r, 0.f);
  EXPECT_TRUE(r.info.has_translation);
}

TEST(SequenceIo, RestAndRampFramesRoundTripAndDefaultToZero) {
  const auto dir = temp_dir("ramp");
  Sequence s = make_synthetic_sequence();
  write_sequence((dir / "none.h5").string(), s);
  EXPECT_EQ(read_sequence((dir / "none.h5").string()).info.settled_frame(), 0);
  s.info.rest_frames = 3;
  s.info.ramp_frames = 2;
  write_sequence((dir / "ramp.h5").string(), s);
  const SequenceInfo r = read_sequence((dir / "ramp.h5").string()).info;
  EXPECT_EQ(r.rest_frames, 3);
  EXPECT_EQ(r.ramp_frames, 2);
  EXPECT_EQ(r.settled_frame(), 5);
}

// How Blender was driven (physics loss): absent means field factor 1 and the older stiffness rule.
TEST(SequenceIo, WindFieldFactorAndStiffnessGroupsRoundTrip) {
  const auto dir = temp_dir("driven");
  Sequence s = make_synthetic_sequence();
  write_sequence((dir / "none.h5").string(), s);
  const SequenceInfo none = read_sequence((dir / "none.h5").string()).info;
  EXPECT_EQ(none.wind_field_factor, 1.f);
  EXPECT_FALSE(none.stiffness_per_layer);
  s.info.wind_field_factor = 2.5f;
  s.info.stiffness_per_layer = true;
  write_sequence((dir / "set.h5").string(), s);
  const SequenceInfo set = read_sequence((dir / "set.h5").string()).info;
  EXPECT_EQ(set.wind_field_factor, 2.5f);
  EXPECT_TRUE(set.stiffness_per_layer);
  std::string out;
  EXPECT_EQ(testing::run_validator((dir / "set.h5").string(), &out), 0) << out;
  // An unknown rule is refused by file and attribute.
  {
    h5::Handle f(H5Fopen((dir / "set.h5").c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose);
    H5Adelete(f.get(), "stiffness_groups");
    h5::write_string_attr(f.get(), "stiffness_groups", "outer");
  }
  out.clear();
  EXPECT_NE(testing::run_validator((dir / "set.h5").string(), &out), 0) << out;
  EXPECT_NE(out.find("'stiffness_groups' is 'outer'"), std::string::npos) << out;
  try {
    (void)read_sequence((dir / "set.h5").string());
    FAIL() << "an unknown stiffness_groups value was accepted";
  } catch (const DatasetError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("set.h5"), std::string::npos) << what;
    EXPECT_NE(what.find("stiffness_groups"), std::string::npos) << what;
  }
}

TEST(SequenceIo, PinWeightsRoundTripAndAreOptional) {
  const auto dir = temp_dir("pin");
  Sequence s = make_synthetic_sequence();
  write_sequence((dir / "none.h5").string(), s);
  const Sequence none = read_sequence((dir / "none.h5").string());
  EXPECT_TRUE(none.info.garments[0].pin.empty());
  EXPECT_FALSE(none.info.garments[0].pinned(0));
  GarmentMesh& g = s.info.garments[0];
  g.pin.assign(static_cast<size_t>(g.num_vertices), 0.f);
  g.pin[0] = 1.f;
  g.pin[1] = 0.25f;
  write_sequence((dir / "pins.h5").string(), s);
  const Sequence r = read_sequence((dir / "pins.h5").string());
  expect_same(s, r, 0.f);
  EXPECT_TRUE(r.info.garments[0].pinned(0));
  EXPECT_FALSE(r.info.garments[0].pinned(1));  // a partial weight is a spring in Blender, not a pin
  std::string out;
  EXPECT_EQ(testing::run_validator((dir / "pins.h5").string(), &out), 0) << out;
  g.pin.resize(3);
  EXPECT_THROW(write_sequence((dir / "bad.h5").string(), s), std::exception);
}

TEST(SequenceIo, RoundTripFloat64Int64GzipWithoutWindOrTranslation) {
  const auto dir = temp_dir("rt64");
  SyntheticOptions o;
  o.garments = 1;
  const Sequence s = make_synthetic_sequence(o);
  SequenceWriteOptions w;
  w.float64 = true;
  w.int64 = true;
  w.gzip = 4;
  w.write_translation = false;
  write_sequence((dir / "b.h5").string(), s, w);
  const Sequence r = read_sequence((dir / "b.h5").string());
  EXPECT_FALSE(r.info.has_translation);
  EXPECT_EQ(r.info.translation.rows(), s.info.num_frames);
  EXPECT_EQ(r.info.translation.norm(), 0.f);
  EXPECT_FALSE(r.info.has_wind);
  EXPECT_TRUE(s.frames.body.isApprox(r.frames.body, 1e-7f));
  EXPECT_EQ(s.info.garments[0].faces, r.info.garments[0].faces);
}

TEST(SequenceIo, FrameWindowsMatchTheWholeSequence) {
  const auto dir = temp_dir("win");
  SyntheticOptions o;
  o.frames = 10;
  o.garments = 2;
  const Sequence s = make_synthetic_sequence(o);
  SequenceWriteOptions w;
  w.gzip = 1;
  write_sequence((dir / "c.h5").string(), s, w);
  SequenceFile f((dir / "c.h5").string());
  const FrameWindow win = f.read_frames(4, 3);
  EXPECT_EQ(win.first, 4);
  EXPECT_EQ(win.count, 3);
  for (int t = 4; t < 7; ++t) {
    EXPECT_EQ(win.body_at(t, s.info.num_body_vertices), s.body_at(t));
    EXPECT_EQ(win.garment_at(1, t, s.info.garments[1].num_vertices), s.garment_at(1, t));
  }
  EXPECT_THROW(f.read_frames(8, 3), DatasetError);
}

TEST(SequenceIo, WrittenFilesPassThePythonValidator) {
  const auto dir = temp_dir("val");
  SyntheticOptions o;
  o.garments = 2;
  o.wind = true;
  SequenceWriteOptions w;
  w.gzip = 2;
  write_synthetic_dataset(dir.string(), 2, 1, 1, o, w);
  std::string out;
  EXPECT_EQ(testing::run_validator(dir.string(), &out), 0) << out;
  EXPECT_NE(out.find("0 problems"), std::string::npos) << out;
}

TEST(Manifest, RoundTripAndSplits) {
  const auto dir = temp_dir("man");
  const DatasetManifest m = write_synthetic_dataset(dir.string(), 3, 1, 2);
  const DatasetManifest r = read_manifest(dir.string());
  EXPECT_EQ(r.train, m.train);
  EXPECT_EQ(r.val, m.val);
  EXPECT_EQ(r.test, m.test);
  EXPECT_EQ(r.all_ids().size(), 6u);
  EXPECT_EQ(r.sequence_path("s0000"), (dir / "s0000.h5").string());
  EXPECT_THROW(r.split("training"), DatasetError);
}

TEST(Manifest, AcceptsMissingSplitsAndExtraKeys) {
  const DatasetManifest m = parse_manifest(
      R"({"format":"dlayers-h5","version":1,"source":"x","splits":{"train":["a","b"]},"extra":3})", "m.json");
  EXPECT_EQ(m.train.size(), 2u);
  EXPECT_TRUE(m.test.empty());
}

// The mirror image (x → −x) is a valid sequence: its faces still face outward (the reader
// refuses inward bodies), its normals and wind are the mirrored ones, every corner keeps its UV,
// and mirroring twice gives the original back bit for bit.
TEST(SequenceIo, MirrorImageIsAValidSequenceAndTwiceTheOriginal) {
  const auto dir = temp_dir("mirror");
  SyntheticOptions o;
  o.garments = 2;
  o.wind = true;
  o.offset = {0.7f, 0.3f, 0.f};  // off the mirror plane: no vertex is its own image
  const Sequence s = make_synthetic_sequence(o);
  Sequence m{mirrored(s.info), s.frames};
  mirror_positions(m.frames);
  write_sequence((dir / "m.h5").string(), m);
  const Sequence r = read_sequence((dir / "m.h5").string());
  expect_same(m, r, 0.f);

  const Eigen::Matrix3f M = Eigen::Vector3f(-1.f, 1.f, 1.f).asDiagonal();
  EXPECT_EQ(m.body_at(3), s.body_at(3) * M);
  const auto& g = s.info.garments[1];
  const auto& gm = m.info.garments[1];
  const auto normals_differ = [&](const Points& image, const Points& original) {
    return (image - original * M).cwiseAbs().maxCoeff();  // a rounding apart: the cross products' order differs
  };
  EXPECT_LT(normals_differ(vertex_normals(m.body_at(3), m.info.body_faces), vertex_normals(s.body_at(3), s.info.body_faces)), 1e-6f);
  EXPECT_LT(normals_differ(vertex_normals(m.garment_at(1, 3), gm.faces), vertex_normals(s.garment_at(1, 3), g.faces)), 1e-6f);
  for (Eigen::Index f = 0; f < g.faces.rows(); ++f)
    for (int c = 0; c < 3; ++c) {  // every corner keeps its UV
      const int mc = c == 0 ? 0 : 3 - c;
      EXPECT_EQ(gm.faces(f, mc), g.faces(f, c));
      EXPECT_EQ(gm.uv.row(3 * f + mc), g.uv.row(3 * f + c));
    }
  ASSERT_GT(s.info.wind_strength.maxCoeff(), 0.f);
  for (int t = 0; t < s.info.num_frames; ++t) {
    const Eigen::Vector3f d = wind_direction(s.info.wind_rotation.row(t).transpose());
    EXPECT_LT((wind_direction(m.info.wind_rotation.row(t).transpose()) - M * d).norm(), 1e-6f) << "frame " << t;
  }
  EXPECT_EQ(m.info.translation, s.info.translation * M);
  EXPECT_EQ(m.info.gravity, s.info.gravity);  // along z

  Sequence back{mirrored(m.info), m.frames};
  mirror_positions(back.frames);
  expect_same(s, back, 0.f);
  EXPECT_EQ(back.frames.body, s.frames.body);
  for (int k = 0; k < s.info.num_garments(); ++k) {
    EXPECT_EQ(back.frames.garments[k], s.frames.garments[k]);
    EXPECT_EQ(back.info.garments[k].faces, s.info.garments[k].faces);
    EXPECT_EQ(back.info.garments[k].uv, s.info.garments[k].uv);
    EXPECT_EQ(back.info.garments[k].rest, s.info.garments[k].rest);
  }
  EXPECT_EQ(back.info.wind_rotation, s.info.wind_rotation);
}

}  // namespace
}  // namespace layersnet::dataset
