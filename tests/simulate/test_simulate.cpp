// `layersnet simulate` end to end: a tiny synthetic scene written as a user would give it (body
// frames and garments as OBJ), a freshly initialised tiny model (configs/tiny.toml), the same
// answer as the internal rollout, the errors of bad inputs, and Blender reading the outputs.
#include "autodiff/bf16_gemm.h"
#include "dataset/mesh_io.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "eval/rollout.h"
#include "simulate/motion.h"
#include "simulate/simulate.h"
#include "simulate/wind.h"
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "run/config.h"
#include "run/run_dir.h"

#include "tests/eval/cli_test_util.h"

#include <Eigen/Core>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <iterator>
#include <limits>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace layersnet::eval {
namespace {

namespace fs = std::filesystem;
using cli_test::run_cli;

// Runs a shell command (stderr merged into the returned text); *code = its exit status.
std::string run_cli_command(const std::string& command, int* code) {
  std::FILE* p = popen((command + " 2>&1").c_str(), "r");
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = pclose(p);
  *code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

// A body 1.7 m tall (17 units at the x10 convention) in two tube garments.
dataset::SyntheticOptions scene_options() {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 8;
  o.rings = 4;
  o.segments = 8;
  o.body_rings = 6;
  o.body_segments = 8;
  o.height = 17.f;
  return o;
}

class Simulate : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("layersnet_simulate_test_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    const auto m = dataset::write_synthetic_dataset((root_ / "data").string(), 1, 0, 0, scene_options());
    const auto stats = dataset::compute_stats(m);
    seq_ = dataset::read_sequence(m.sequence_path(m.train.front()));
    cli_test::write_tiny_checkpoint(checkpoint(), stats);
    // The user's files: every body frame, and each garment at frame 0 with its UVs.
    fs::create_directories(root_ / "body");
    for (int t = 0; t < seq_.info.num_frames; ++t) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%04d.obj", t);
      dataset::write_obj((root_ / "body" / name).string(), seq_.body_at(t), seq_.info.body_faces);
    }
    for (int g = 0; g < seq_.info.num_garments(); ++g) {
      const auto& mesh = seq_.info.garments[g];
      dataset::write_obj(garment_obj(g), seq_.garment_at(g, 0), mesh.faces, &mesh.uv);
    }
  }
  static void TearDownTestSuite() {
    if (!std::getenv("LAYERSNET_SIMULATE_TEST_KEEP")) fs::remove_all(root_);
  }
  static std::string checkpoint() { return (root_ / "tiny.h5").string(); }
  static std::string garment_obj(int g) { return (root_ / (seq_.info.garments[g].name + ".obj")).string(); }
  // --garment options with the source's own attributes and types.
  static std::string garment_args() {
    std::string args;
    for (int g = 0; g < seq_.info.num_garments(); ++g) {
      const auto& m = seq_.info.garments[g];
      std::ostringstream s;
      s.precision(9);
      s << " --garment " << garment_obj(g) << ",type=" << m.type << ",tension=" << m.attributes.tension_stiffness
        << ",bending=" << m.attributes.bending_stiffness << ",mass=" << m.attributes.mass
        << ",friction=" << m.attributes.self_friction;
      args += s.str();
    }
    return args;
  }
  static SceneInputs inputs() {
    SceneInputs in;
    in.body.obj_folder = (root_ / "body").string();
    for (int g = 0; g < seq_.info.num_garments(); ++g) in.garments.push_back(parse_garment_spec(garment_obj(g)));
    return in;
  }
  // The message of the SimulateError or DatasetError that build_scene throws.
  static std::string scene_error(const SceneInputs& in) {
    try {
      build_scene(in);
    } catch (const std::exception& e) {
      return e.what();
    }
    return "(no error)";
  }
  static fs::path root_;
  static dataset::Sequence seq_;
};
fs::path Simulate::root_;
dataset::Sequence Simulate::seq_;

// The internal road: the source sequence started from rest by hand (its first body frame three
// times, the garments at their frame-0 positions, which are also the rest shapes), rolled out by
// eval::rollout. simulate must give the same positions from the OBJ files.
// A model chosen with recorded pins gets the collision steps of its cloth constraints in simulate
// and none of the others; the user's --set comes last and wins; other models get only the user's
// settings.
TEST(SimulateSettings, CollisionStepsOnlyWhereRecordedPinsWereChosen) {
  EvalConfig recorded;
  recorded.recorded_pins = true;
  recorded.constraints = false;
  Config c;
  c.eval = recorded;
  for (const auto& a : simulate_rollout_settings(recorded, {})) apply_rollout_override(c, a);
  EXPECT_TRUE(c.eval.constraints);
  EXPECT_GT(c.eval.collision_shell, 0);
  EXPECT_EQ(c.eval.strain_limit, 0);
  EXPECT_EQ(c.eval.fold_limit, 0);
  EXPECT_EQ(c.eval.body_friction, 0);
  EXPECT_EQ(c.eval.layer_friction, 0);
  for (const auto& a : simulate_rollout_settings(recorded, {"eval.constraints=false"})) apply_rollout_override(c, a);
  EXPECT_FALSE(c.eval.constraints);
  EXPECT_EQ(simulate_rollout_settings(EvalConfig{}, {"eval.strain_limit=0.1"}), std::vector<std::string>{"eval.strain_limit=0.1"});
}

TEST_F(Simulate, SameAnswerAsTheInternalRolloutFromRest) {
  int code = 0;
  const fs::path out = root_ / "out_roads";
  const std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --body-frames " +
                                       (root_ / "body").string() + garment_args() + " --precision float32 --out " + out.string(),
                                   &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_NE(text.find("frames per second"), std::string::npos) << text;

  const int K = seq_.info.num_frames, B = seq_.info.num_body_vertices;
  dataset::Sequence start = seq_;
  start.info.num_frames = start.frames.count = K + 2;
  start.info.body_friction = 60.f;  // simulate's default
  start.frames.body.resize(static_cast<Eigen::Index>(K + 2) * B, 3);
  for (int t = 0; t < K + 2; ++t)
    start.frames.body.middleRows(static_cast<Eigen::Index>(t) * B, B) = seq_.body_at(std::max(0, t - 2));
  start.info.translation = estimated_root_translation(start.frames.body, B);
  for (int g = 0; g < seq_.info.num_garments(); ++g) {
    const int n = seq_.info.garments[g].num_vertices;
    const dataset::Points x0 = seq_.garment_at(g, 0);
    start.info.garments[g].rest = x0;
    start.frames.garments[g].resize(static_cast<Eigen::Index>(K + 2) * n, 3);
    for (int t = 0; t < K + 2; ++t) start.frames.garments[g].middleRows(static_cast<Eigen::Index>(t) * n, n) = x0;
  }
  Eigen::setNbThreads(1);  // as the command
  auto model = load_model_predictor(checkpoint(), "tiny", nullptr);
  const Rollout internal = rollout(*model, start, 2, K - 1);
  ASSERT_EQ(internal.frames.size(), static_cast<size_t>(K - 1));

  const dataset::Sequence written = dataset::read_sequence((out / "scene.h5").string());
  ASSERT_EQ(written.info.num_frames, K + 2);
  double worst_h5 = 0, worst_pc2 = 0, worst_obj = 0;
  Eigen::Index offset = 0;
  for (int g = 0; g < seq_.info.num_garments(); ++g) {
    const auto& mesh = seq_.info.garments[g];
    const int n = mesh.num_vertices;
    const dataset::PointCache cache = dataset::read_pc2((out / (mesh.name + ".pc2")).string());
    ASSERT_EQ(cache.frames.size(), static_cast<size_t>(K));
    EXPECT_EQ(cache.frames[0], seq_.garment_at(g, 0));  // output frame 0: the start
    for (int k = 1; k < K; ++k) {
      const dataset::Points expected = internal.frames[k - 1].middleRows(offset, n);
      worst_h5 = std::max(worst_h5, static_cast<double>((written.garment_at(g, k + 2) - expected).cwiseAbs().maxCoeff()));
      worst_pc2 = std::max(worst_pc2, static_cast<double>((cache.frames[k] - expected).cwiseAbs().maxCoeff()));
      char name[64];
      std::snprintf(name, sizeof name, "%s_%04d.obj", mesh.name.c_str(), k);
      const dataset::ObjMesh obj = dataset::read_obj((out / mesh.name / name).string());
      worst_obj = std::max(worst_obj, static_cast<double>((obj.positions - expected).cwiseAbs().maxCoeff()));
      EXPECT_EQ(obj.uv, mesh.uv);
      EXPECT_EQ(obj.faces, mesh.faces);
    }
    offset += n;
  }
  EXPECT_LE(worst_h5, 1e-6);
  EXPECT_LE(worst_pc2, 1e-6);
  EXPECT_LE(worst_obj, 1e-6);
  std::printf("largest difference to the internal rollout: h5 %g, pc2 %g, obj %g\n", worst_h5, worst_pc2, worst_obj);
  EXPECT_FALSE(fs::exists(out / (".simulate-partial-" + std::to_string(::getpid()))));

  // The output is a data set the other commands read.
  const std::string check = run_cli("inspect --check " + out.string(), &code);
  EXPECT_EQ(code, 0) << check;
  const std::string scored = run_cli("eval --checkpoint " + checkpoint() + " --dataset " + out.string() +
                                         " --split test --frames 3 --speed-frames 2 --out " + (out / "eval").string(),
                                     &code);
  EXPECT_EQ(code, 0) << scored;
  const std::string exported = run_cli("export --checkpoint " + checkpoint() + " --dataset " + out.string() +
                                           " --split test --frames 3 --out " + (out / "export").string(),
                                       &code);
  EXPECT_EQ(code, 0) << exported;
  const std::string stressed = run_cli("stress --checkpoint " + checkpoint() + " --dataset " + out.string() +
                                           " --sequence scene --frames 6 --winds 0 --precision-frames 2",
                                       &code);
  EXPECT_TRUE(code == 0 || code == 4) << stressed;  // 4: a bound broke, which an untrained model may do
  EXPECT_NE(stressed.find("scene"), std::string::npos) << stressed;
}

// Without --precision the products run in bfloat16 where they out-run float32 on this CPU and in
// float32 otherwise; the bf16 rollout stays close to the float32 one.
TEST_F(Simulate, AutoPrecisionIsBf16WhereItOutrunsFloat32) {
  int code = 0;
  const fs::path f32 = root_ / "out_f32", automatic = root_ / "out_auto";
  const std::string args = " --checkpoint " + checkpoint() + " --body-frames " + (root_ / "body").string() + garment_args();
  const std::string text32 = run_cli("simulate" + args + " --precision float32 --out " + f32.string(), &code);
  ASSERT_EQ(code, 0) << text32;
  const std::string text = run_cli("simulate" + args + " --out " + automatic.string(), &code);
  ASSERT_EQ(code, 0) << text;
  const bool bf16 = ad::bf16_outruns_float32();
  EXPECT_NE(text.find(bf16 ? "bf16 products" : "float32 products"), std::string::npos) << text;
  const dataset::Sequence a = dataset::read_sequence((f32 / "scene.h5").string());
  const dataset::Sequence b = dataset::read_sequence((automatic / "scene.h5").string());
  double worst = 0;
  for (int g = 0; g < a.info.num_garments(); ++g)
    for (int t = 0; t < a.info.num_frames; ++t)
      worst = std::max(worst, static_cast<double>((a.garment_at(g, t) - b.garment_at(g, t)).cwiseAbs().maxCoeff()));
  if (bf16) EXPECT_GT(worst, 0.0);  // the products did change
  else EXPECT_EQ(worst, 0.0);
  EXPECT_LT(worst, 0.05);  // scene units: half a centimetre over the whole tiny rollout
}

// Blender imports the OBJ sequence and plays the PC2 through its Mesh Cache modifier: the same
// vertex count and positions as the D-LAYERS-H5 output.
TEST_F(Simulate, BlenderReadsTheObjSequenceAndThePc2) {
  if (std::system("blender --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "blender not installed";
  int code = 0;
  const fs::path out = root_ / "out_blender";
  const std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --body-frames " +
                                       (root_ / "body").string() + garment_args() + " --out " + out.string(),
                                   &code);
  ASSERT_EQ(code, 0) << text;
  const int K = seq_.info.num_frames, g = 1;
  const std::string garment = seq_.info.garments[g].name;
  const std::string script = std::string(LAYERSNET_SOURCE_DIR) + "/tests/simulate/blender_reads_simulation.py";
  const std::string blender = run_cli_command("blender -b --factory-startup --python-exit-code 1 --python " + script +
                                                  " -- " + out.string() + " " + garment + " 0 1 " +
                                                  std::to_string(K - 1),
                                              &code);
  ASSERT_EQ(code, 0) << blender;
  const auto at = blender.find("RESULT ");
  ASSERT_NE(at, std::string::npos) << blender;
  const auto result = nlohmann::json::parse(blender.substr(at + 7, blender.find('\n', at) - at - 7));
  EXPECT_EQ(result["uv_layers"], 1);
  const dataset::Sequence written = dataset::read_sequence((out / "scene.h5").string());
  const int n = written.info.garments[g].num_vertices;
  for (int k : {0, 1, K - 1}) {
    const dataset::Points expected = written.garment_at(g, k + kSceneRestFrames - 1);
    for (const char* road : {"cache", "obj"}) {
      const auto& positions = result[road][std::to_string(k)];
      ASSERT_EQ(static_cast<int>(positions.size()), n) << road << " frame " << k;
      double worst = 0;
      for (int v = 0; v < n; ++v)
        for (int c = 0; c < 3; ++c)
          worst = std::max(worst, std::abs(positions[v][c].get<double>() - expected(v, c)));
      EXPECT_LE(worst, 1e-6) << road << " frame " << k;
    }
  }
}

// Y-up files in metres (Blender's OBJ export) give the scene of the z-up x10 files, and the
// outputs go back to the files' axes and units.
TEST_F(Simulate, YUpMetreFilesGiveTheSameScene) {
  const auto to_y_up_metres = [](const dataset::Points& x) {
    dataset::Points y(x.rows(), 3);
    y.col(0) = x.col(0) / 10.f;
    y.col(1) = x.col(2) / 10.f;
    y.col(2) = -x.col(1) / 10.f;
    return y;
  };
  const fs::path folder = root_ / "y_up";
  fs::create_directories(folder / "body");
  for (int t = 0; t < 3; ++t)
    dataset::write_obj((folder / "body" / (std::to_string(t) + ".obj")).string(), to_y_up_metres(seq_.body_at(t)),
                       seq_.info.body_faces);
  SceneInputs in = inputs();
  in.body.obj_folder = (folder / "body").string();
  for (int g = 0; g < seq_.info.num_garments(); ++g) {
    const auto& mesh = seq_.info.garments[g];
    in.garments[g].obj = (folder / (mesh.name + ".obj")).string();
    dataset::write_obj(in.garments[g].obj, to_y_up_metres(seq_.garment_at(g, 0)), mesh.faces, &mesh.uv);
  }
  in.up_axis = 'y';
  in.scale = 1.f;
  const Scene scene = build_scene(in);
  const Scene reference = build_scene(inputs());
  EXPECT_LE((scene.sequence.body_at(4) - reference.sequence.body_at(4)).cwiseAbs().maxCoeff(), 1e-5f);
  EXPECT_LE((scene.sequence.garment_at(1, 0) - reference.sequence.garment_at(1, 0)).cwiseAbs().maxCoeff(), 1e-5f);
  EXPECT_LE((scene.to_input_units(scene.sequence.body_at(4)) - to_y_up_metres(seq_.body_at(2))).cwiseAbs().maxCoeff(),
            1e-6f);
}

// The three body sources give the same body: OBJ frames, a PC2 with its topology OBJ, the body of
// a D-LAYERS-H5 file (which also brings its root translation).
TEST_F(Simulate, Pc2AndH5BodiesGiveTheBodyOfTheObjFrames) {
  dataset::PointCache cache;
  for (int t = 0; t < seq_.info.num_frames; ++t) cache.frames.push_back(seq_.body_at(t));
  const std::string pc2 = (root_ / "body.pc2").string(), topology = (root_ / "body" / "frame_0000.obj").string();
  dataset::write_pc2(pc2, cache);
  const Scene from_obj = build_scene(inputs());
  SceneInputs in = inputs();
  in.body = {};
  in.body.pc2 = pc2;
  in.body.topology = topology;
  const Scene from_pc2 = build_scene(in);
  EXPECT_EQ(from_pc2.sequence.frames.body, from_obj.sequence.frames.body);
  EXPECT_EQ(from_pc2.sequence.info.body_faces, from_obj.sequence.info.body_faces);
  in.body = {};
  in.body.h5 = (root_ / "data" / "s0000.h5").string();
  in.max_frames = 5;
  const Scene from_h5 = build_scene(in);
  ASSERT_EQ(from_h5.body_frames, 5);
  EXPECT_EQ(from_h5.sequence.body_at(kSceneRestFrames - 1 + 4), seq_.body_at(4));
  EXPECT_EQ(from_h5.sequence.info.translation.row(kSceneRestFrames - 1 + 4), seq_.info.translation.row(4));
  EXPECT_EQ(from_h5.sequence.info.translation.row(0), seq_.info.translation.row(0));  // the rest frames
}

TEST_F(Simulate, GarmentWithoutUvsIsRefusedNamingTheFile) {
  const fs::path obj = root_ / "no_uv.obj";
  dataset::write_obj(obj.string(), seq_.garment_at(0, 0), seq_.info.garments[0].faces);
  SceneInputs in = inputs();
  in.garments[0].obj = obj.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(obj.string() + ": has no texture coordinates (vt)"), std::string::npos) << e;
  EXPECT_NE(e.find("export the OBJ with UV coordinates"), std::string::npos) << e;
}

TEST_F(Simulate, FacesThatAreNotTrianglesOrQuadsAreRefused) {
  const fs::path obj = root_ / "pentagon.obj";
  std::ofstream(obj) << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0.5 0\nvt 0 0\nf 1/1 2/1 3/1 4/1 5/1\n";
  SceneInputs in = inputs();
  in.garments[0].obj = obj.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(obj.string() + ": line 7: a face with 5 corners"), std::string::npos) << e;
  EXPECT_NE(e.find("triangulate"), std::string::npos) << e;
}

TEST_F(Simulate, QuadsAreSplitIntoTriangles) {
  const fs::path obj = root_ / "quad.obj";
  std::ofstream(obj) << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";
  const dataset::ObjMesh m = dataset::read_obj(obj.string());
  ASSERT_EQ(m.faces.rows(), 2);
  EXPECT_EQ(m.quads, 1);
  EXPECT_EQ(m.faces.row(1), (Eigen::RowVector3i(0, 2, 3)));
  EXPECT_EQ(m.uv.row(5), (Eigen::RowVector2f(0, 1)));
  EXPECT_EQ(dataset::uv_islands(m.faces, m.uv), (std::vector<int32_t>{0, 0}));
}

TEST_F(Simulate, BodyFramesWithDifferentVertexCountsAreRefused) {
  const fs::path folder = root_ / "body_uneven";
  fs::create_directories(folder);
  fs::copy_file(root_ / "body" / "frame_0000.obj", folder / "a.obj", fs::copy_options::overwrite_existing);
  const dataset::Points fewer = seq_.body_at(1).topRows(seq_.info.num_body_vertices - 2);
  dataset::write_obj((folder / "b.obj").string(), fewer, dataset::Faces(dataset::Faces::Constant(1, 3, 0)));
  SceneInputs in = inputs();
  in.body.obj_folder = folder.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find((folder / "b.obj").string() + ": has " + std::to_string(fewer.rows()) + " vertices but " +
                   (folder / "a.obj").string()),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("every body frame needs the same mesh"), std::string::npos) << e;
}

TEST_F(Simulate, GarmentFarFromTheBodyIsRefused) {
  const fs::path obj = root_ / "far.obj";
  dataset::Points x = seq_.garment_at(0, 0);
  x.col(0).array() += 40.f;  // 4 m to the side
  dataset::write_obj(obj.string(), x, seq_.info.garments[0].faces, &seq_.info.garments[0].uv);
  SceneInputs in = inputs();
  in.garments[0].obj = obj.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(obj.string() + ": the garment's centroid"), std::string::npos) << e;
  EXPECT_NE(e.find("outside the body's first frame"), std::string::npos) << e;
}

TEST_F(Simulate, OuterGarmentInsideTheInnerOneSaysTheOrderIsWrong) {
  SceneInputs in = inputs();
  std::swap(in.garments[0], in.garments[1]);
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(garment_obj(0) + ": lies inside " + garment_obj(1)), std::string::npos) << e;
  EXPECT_NE(e.find("the order is probably wrong"), std::string::npos) << e;
}

TEST_F(Simulate, BodyInMetresUnderTheX10ConventionIsRefused) {
  // The same scene in metres, given without --scale 1: 1.7 units tall.
  const fs::path folder = root_ / "body_metres";
  fs::create_directories(folder);
  for (int t = 0; t < 3; ++t)
    dataset::write_obj((folder / (std::to_string(t) + ".obj")).string(), seq_.body_at(t) / 10.f,
                       seq_.info.body_faces);
  SceneInputs in = inputs();
  in.body.obj_folder = folder.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(folder.string() + ": the body is 1.70 units tall along z, which is 0.170 m at --scale 10.000"),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("the files look like metres: pass --scale 1"), std::string::npos) << e;
}

TEST_F(Simulate, EmptyOrUnsortedWindCsvIsRefused) {
  const fs::path empty = root_ / "wind_empty.csv", unsorted = root_ / "wind_unsorted.csv";
  std::ofstream(empty) << "frame,dx,dy,dz,strength\n";
  std::ofstream(unsorted) << "frame,dx,dy,dz,strength\n0,1,0,0,100\n5,0,1,0,200\n3,0,0,1,50\n";
  SceneInputs in = inputs();
  in.wind = empty.string();
  std::string e = scene_error(in);
  EXPECT_NE(e.find(empty.string() + ": the wind CSV has no rows"), std::string::npos) << e;
  in.wind = unsorted.string();
  e = scene_error(in);
  EXPECT_NE(e.find(unsorted.string() + ": line 4: frame 3 after frame 5: frames must increase"), std::string::npos)
      << e;
}

TEST_F(Simulate, WindCsvAndPinsShapeTheScene) {
  const fs::path csv = root_ / "wind.csv";
  std::ofstream(csv) << "frame,dx,dy,dz,strength\n2,1,0,0,400\n";
  SceneInputs in = inputs();
  in.wind = csv.string();
  in.garments[1].pins = "top-ring";
  const Scene scene = build_scene(in);
  const auto& info = scene.sequence.info;
  ASSERT_TRUE(info.has_wind);
  EXPECT_EQ(info.wind_strength[kSceneRestFrames - 1 + 1], 0.f);  // body frame 1: calm
  EXPECT_EQ(info.wind_strength[kSceneRestFrames - 1 + 2], 400.f);
  const Eigen::Vector4f q = info.wind_rotation.row(kSceneRestFrames + 1).transpose();
  EXPECT_NEAR((Eigen::Quaternionf(q[0], q[1], q[2], q[3]) * Eigen::Vector3f::UnitZ() - Eigen::Vector3f::UnitX()).norm(),
              0.f, 1e-6f);
  // The top ring of the outer tube: its highest row of vertices.
  const int segments = scene_options().segments;
  ASSERT_EQ(scene.pins[1].size(), static_cast<size_t>(segments));
  EXPECT_EQ(scene.pins[1].front(), info.garments[1].num_vertices - segments);
  // They are the garment's pin weights, rigged from the body: the scene records them at every
  // frame, moved from the rest shape, while every free row keeps the rest shape.
  EXPECT_TRUE(info.garments[0].pin.empty());
  EXPECT_EQ(info.garments[1].num_pinned(), segments);
  EXPECT_TRUE(info.garments[1].pinned(info.garments[1].num_vertices - segments));
  EXPECT_TRUE(info.pins_recorded);
  const dataset::GarmentMesh& outer = info.garments[1];
  const int last = info.num_frames - 1;
  const Points first = scene.sequence.garment_at(1, 0), end = scene.sequence.garment_at(1, last);
  float pins_moved = 0;
  for (int v = 0; v < outer.num_vertices; ++v) {
    if (outer.pinned(v))
      pins_moved = std::max(pins_moved, (end.row(v) - first.row(v)).norm());
    else
      EXPECT_EQ(end.row(v), outer.rest.row(v)) << "free row " << v;
  }
  const float body_moved = (scene.sequence.body_at(last) - scene.sequence.body_at(0)).rowwise().norm().maxCoeff();
  EXPECT_GT(body_moved, 1e-3f);
  EXPECT_GT(pins_moved, 0.1f * body_moved);
}

TEST_F(Simulate, ABadInputLeavesNoOutputBehind) {
  int code = 0;
  const fs::path out = root_ / "out_refused";
  const std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --body-frames " +
                                       (root_ / "body").string() + " --garment " + garment_obj(1) + " --garment " +
                                       garment_obj(0) + " --out " + out.string(),
                                   &code);
  EXPECT_EQ(code, 1) << text;
  EXPECT_NE(text.find("layersnet simulate: error: " + garment_obj(0) + ": lies inside"), std::string::npos) << text;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(Simulate, Pc2RoundTripsExactly) {
  dataset::PointCache cache;
  cache.start_frame = 1;
  for (int t = 0; t < 3; ++t) cache.frames.push_back(seq_.garment_at(0, t));
  const std::string path = (root_ / "round.pc2").string();
  dataset::write_pc2(path, cache);
  EXPECT_EQ(fs::file_size(path), 32u + 3u * seq_.info.garments[0].num_vertices * 12u);
  const dataset::PointCache back = dataset::read_pc2(path);
  EXPECT_EQ(back.start_frame, 1.f);
  ASSERT_EQ(back.frames.size(), 3u);
  for (int t = 0; t < 3; ++t) EXPECT_EQ(back.frames[t], cache.frames[t]);
  fs::resize_file(path, fs::file_size(path) - 4);
  try {
    dataset::read_pc2(path);
    ADD_FAILURE() << "a truncated PC2 was read";
  } catch (const dataset::DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
}


// ---- every input checked where it is read

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST_F(Simulate, NanVertexInAGarmentObjIsRefusedWithTheFileAndLine) {
  std::istringstream lines(read_text(garment_obj(0)));
  const fs::path obj = root_ / "nan_vertex.obj";
  std::ofstream out(obj);
  std::string line;
  for (int n = 1; std::getline(lines, line); ++n) out << (n == 3 ? "v 0.1 nan 2" : line) << "\n";
  out.close();
  SceneInputs in = inputs();
  in.garments[0].obj = obj.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(obj.string() + ": line 3: vertex 3 is not finite"), std::string::npos) << e;
}

// Found by fuzz/fuzz_user_files.cpp: a relative index beyond the range of long.
TEST_F(Simulate, FaceIndexBeyondTheRangeOfLongIsRefusedByLine) {
  const fs::path obj = root_ / "huge_index.obj";
  std::ofstream(obj) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 -99999999999999999999999 3\n";
  try {
    dataset::read_obj(obj.string());
    ADD_FAILURE() << "an index beyond the range of long was accepted";
  } catch (const dataset::DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find(obj.string() + ": line 4: vertex index"), std::string::npos) << e.what();
  }
}

TEST_F(Simulate, GarmentWhoseVerticesAllCoincideIsRefused) {
  const auto& mesh = seq_.info.garments[0];
  dataset::Points x = seq_.garment_at(0, 0);
  x.rowwise() = x.row(0).eval();
  const fs::path obj = root_ / "point.obj";
  dataset::write_obj(obj.string(), x, mesh.faces, &mesh.uv);
  SceneInputs in = inputs();
  in.garments[0].obj = obj.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(obj.string() + ": all " + std::to_string(x.rows()) + " vertices lie at one point"), std::string::npos)
      << e;
}

TEST_F(Simulate, TheSameGarmentAsBothLayersIsRefused) {
  SceneInputs in = inputs();
  in.garments[1].obj = garment_obj(0);
  std::string e = scene_error(in);
  EXPECT_NE(e.find(garment_obj(0) + ": is the same file as " + garment_obj(0)), std::string::npos) << e;
  // A copy under another name is the same layer too.
  const fs::path copy = root_ / "copy_of_inner.obj";
  fs::copy_file(garment_obj(0), copy, fs::copy_options::overwrite_existing);
  in.garments[1].obj = copy.string();
  e = scene_error(in);
  EXPECT_NE(e.find(copy.string() + ": has the same vertices as " + garment_obj(0)), std::string::npos) << e;
}

TEST_F(Simulate, OutThatIsAnExistingFileIsRefusedAndLeftAlone) {
  const fs::path file = root_ / "a_file_not_a_folder";
  std::ofstream(file) << "keep me\n";
  int code = 0;
  const std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --body-frames " +
                                       (root_ / "body").string() + garment_args() + " --out " + file.string(),
                                   &code);
  EXPECT_EQ(code, 1) << text;
  EXPECT_NE(text.find("--out " + file.string() + ": is an existing file, not a folder"), std::string::npos) << text;
  EXPECT_EQ(read_text(file), "keep me\n");
  // A file on the way to the folder is named too.
  EXPECT_THROW(check_output_folder((file / "sub").string()), SimulateError);
  EXPECT_NO_THROW(check_output_folder((root_ / "new" / "folder").string()));
  EXPECT_FALSE(fs::exists(root_ / "new"));  // the check creates nothing
}

TEST_F(Simulate, NonFiniteBodyPointInAPc2IsRefusedWithTheSample) {
  dataset::PointCache cache;
  for (int t = 0; t < 3; ++t) cache.frames.push_back(seq_.body_at(t));
  cache.frames[1](5, 2) = std::numeric_limits<float>::infinity();
  const fs::path pc2 = root_ / "inf_body.pc2";
  dataset::write_pc2(pc2.string(), cache);
  const fs::path topology = root_ / "body_topology.obj";
  dataset::write_obj(topology.string(), seq_.body_at(0), seq_.info.body_faces);
  SceneInputs in = inputs();
  in.body = {};
  in.body.pc2 = pc2.string();
  in.body.topology = topology.string();
  const std::string e = scene_error(in);
  EXPECT_NE(e.find(pc2.string() + ": sample 1: point 5 is not finite"), std::string::npos) << e;
}

TEST_F(Simulate, WindCsvWithAnAbsurdFrameOrDirectionIsRefusedByLine) {
  const fs::path csv = root_ / "wind_absurd.csv";
  std::ofstream(csv) << "frame,dx,dy,dz,strength\n0,1,0,0,400\n1e30,1,0,0,400\n";
  try {
    read_wind(csv.string());
    ADD_FAILURE() << "a frame of 1e30 was accepted";
  } catch (const SimulateError& e) {
    EXPECT_NE(std::string(e.what()).find(csv.string() + ": line 3: the frame must be a whole number"),
              std::string::npos) << e.what();
  }
  std::ofstream(csv) << "0,3e38,3e38,0,400\n";
  try {
    read_wind(csv.string());
    ADD_FAILURE() << "a direction whose length overflows was accepted";
  } catch (const SimulateError& e) {
    EXPECT_NE(std::string(e.what()).find(csv.string() + ": line 1: the direction is too long"), std::string::npos)
        << e.what();
  }
}

// ---- motion capture (BVH)

// A BVH text: a Hips root with one leg (9 channels), `frames` motion lines (or `lines` of them).
std::string small_bvh(const std::string& root, int frames, int lines = -1, const std::string& value = "0") {
  std::string s = "HIERARCHY\nROOT " + root +
                  "\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
                  "  JOINT LeftUpLeg\n  {\n    OFFSET 1 0 0\n    CHANNELS 3 Zrotation Yrotation Xrotation\n"
                  "    End Site\n    {\n      OFFSET 0 -4 0\n    }\n  }\n}\nMOTION\nFrames: " +
                  std::to_string(frames) + "\nFrame Time: 0.0083333\n";
  for (int f = 0; f < (lines < 0 ? frames : lines); ++f) s += "0 0 0 0 0 0 0 0 " + value + "\n";
  return s;
}

std::string bvh_error(const fs::path& path, const std::string& text) {
  std::ofstream(path) << text;
  try {
    read_bvh_header(path.string());
  } catch (const SimulateError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST_F(Simulate, BvhHeaderIsReadAndBadClipsAreRefusedNamingTheFile) {
  const fs::path bvh = root_ / "clip.bvh";
  std::ofstream(bvh) << small_bvh("Hips", 4);
  const BvhHeader h = read_bvh_header(bvh.string());
  EXPECT_EQ(h.joints, (std::vector<std::string>{"Hips", "LeftUpLeg"}));
  EXPECT_EQ(h.channels, 9);
  EXPECT_EQ(h.frames, 4);
  EXPECT_NEAR(h.rate(), 120.0, 0.01);
  const fs::path bad = root_ / "bad.bvh";
  const std::string name = bad.string() + ": ";
  EXPECT_NE(bvh_error(bad, small_bvh("Pelvis", 4)).find(name + "no joint named Hips"), std::string::npos);
  EXPECT_NE(bvh_error(bad, small_bvh("Hips", 0)).find(name + "line 17: Frames: 0;"), std::string::npos)
      << bvh_error(bad, small_bvh("Hips", 0));
  EXPECT_NE(bvh_error(bad, small_bvh("Hips", 5, 3)).find("the clip ends after 3 of its 5 frames"), std::string::npos);
  EXPECT_NE(bvh_error(bad, small_bvh("Hips", 2, 2, "nan")).find(name + "line 19: 'nan' is not a finite number"),
            std::string::npos) << bvh_error(bad, small_bvh("Hips", 2, 2, "nan"));
  EXPECT_NE(bvh_error(bad, "v 0 0 0\n").find(name + "line 1: a BVH file starts with HIERARCHY"), std::string::npos);
  EXPECT_NE(bvh_error(bad, "").find(name + "is empty"), std::string::npos);
}

TEST_F(Simulate, BadBvhIsRefusedBeforeBlenderRunsAndLeavesNoOutput) {
  const fs::path bvh = root_ / "no_frames.bvh", out = root_ / "out_bad_motion";
  std::ofstream(bvh) << small_bvh("Hips", 0);
  int code = 0;
  std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --motion " + bvh.string() + garment_args() +
                                 " --blender /nonexistent/blender --out " + out.string(),
                             &code);
  EXPECT_EQ(code, 1) << text;
  EXPECT_NE(text.find("error: " + bvh.string() + ": line 17: Frames: 0;"), std::string::npos) << text;
  std::ofstream(bvh) << small_bvh("Hips", 4);
  text = run_cli("simulate --checkpoint " + checkpoint() + " --motion " + bvh.string() + " --bvh-start 4" +
                     garment_args() + " --out " + out.string(),
                 &code);
  EXPECT_EQ(code, 1) << text;
  EXPECT_NE(text.find(bvh.string() + ": --bvh-start 4 is outside its 4 frames (0..3)"), std::string::npos) << text;
  text = run_cli("simulate --checkpoint " + checkpoint() + " --motion " + bvh.string() + " --body-frames " +
                     (root_ / "body").string() + garment_args() + " --out " + out.string(),
                 &code);
  EXPECT_EQ(code, 1) << text;
  EXPECT_NE(text.find("give the body motion once"), std::string::npos) << text;
  EXPECT_FALSE(fs::exists(out));
}

constexpr const char* kCmuClip = "/usr/share/assimp/models/BVH/01_01.bvh";

// The first `frames` motion frames of the CMU clip (120 Hz), as a short file of its own.
void write_short_cmu_clip(const fs::path& path, int frames) {
  std::ifstream in(kCmuClip);
  std::ofstream out(path);
  std::string line;
  while (std::getline(in, line) && line.rfind("MOTION", 0) != 0) out << line << "\n";
  out << "MOTION\nFrames: " << frames << "\nFrame Time: .0083333\n";
  std::getline(in, line);  // Frames:
  std::getline(in, line);  // Frame Time:
  for (int f = 0; f < frames && std::getline(in, line); ++f) out << line << "\n";
}

TEST_F(Simulate, UnknownSkeletonIsRefusedByTheRetargetingNamingTheFile) {
  if (std::system("blender --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "blender not installed";
  const fs::path bvh = root_ / "two_bones.bvh";
  std::ofstream(bvh) << small_bvh("Hips", 4);
  int code = 0;
  const std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --motion " + bvh.string() +
                                       garment_args() + " --out " + (root_ / "out_unknown").string(),
                                   &code);
  EXPECT_EQ(code, 1) << text;
  EXPECT_NE(text.find(bvh.string() + ": unknown skeleton (joints Hips, LeftUpLeg)"), std::string::npos) << text;
  EXPECT_FALSE(fs::exists(root_ / "out_unknown"));
}

// A 41-frame CMU clip at 120 Hz played from BVH frame 1 at 30 fps: the rest frame, then
// 1 + (41 - 1 - 1) / 4 = 10 frames, in metres with y up; the rest of simulate runs as for a PC2.
TEST_F(Simulate, MotionFromABvhClipIsRetargetedOntoTheBodyAndSimulated) {
  if (std::system("blender --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "blender not installed";
  if (!fs::exists(kCmuClip)) GTEST_SKIP() << kCmuClip << " missing (Debian package assimp-testmodels)";
  const fs::path bvh = root_ / "cmu_short.bvh", out = root_ / "out_motion";
  write_short_cmu_clip(bvh, 41);
  // The tube garments, in metres with y up like the body Blender writes.
  std::string garments;
  for (int g = 0; g < seq_.info.num_garments(); ++g) {
    const auto& mesh = seq_.info.garments[g];
    dataset::Points x = seq_.garment_at(g, 0) / 10.f;
    x.col(1).swap(x.col(2));
    x.col(2) *= -1.f;  // model (x, y, z) -> input (x, z, -y)
    const fs::path obj = root_ / ("metre_" + mesh.name + ".obj");
    dataset::write_obj(obj.string(), x, mesh.faces, &mesh.uv);
    garments += " --garment " + obj.string();
  }
  int code = 0;
  const std::string text = run_cli("simulate --checkpoint " + checkpoint() + " --motion " + bvh.string() +
                                       " --scale 1 --up y" + garments + " --out " + out.string(),
                                   &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_NE(text.find("retargeting " + bvh.string()), std::string::npos) << text;
  const dataset::PointCache body = dataset::read_pc2((out / "body.pc2").string());
  ASSERT_EQ(body.frames.size(), 11u) << text;
  const dataset::ObjMesh topology = dataset::read_obj((out / "body.obj").string());
  EXPECT_EQ(topology.positions.rows(), body.frames[0].rows());
  // Metres, y up: the rest body stands about 1.7 m tall along y with its feet near 0.
  const float height = body.frames[0].col(1).maxCoeff() - body.frames[0].col(1).minCoeff();
  EXPECT_GT(height, 1.5f);
  EXPECT_LT(height, 1.9f);
  EXPECT_LT(std::abs(body.frames[0].col(1).minCoeff()), 0.1f);
  // The first frame is the rest pose, later frames move.
  EXPECT_GT((body.frames.back() - body.frames.front()).rowwise().norm().maxCoeff(), 0.01f);
  for (int g = 0; g < seq_.info.num_garments(); ++g) {
    const std::string name = "metre_" + seq_.info.garments[g].name;
    EXPECT_EQ(dataset::read_pc2((out / (name + ".pc2")).string()).frames.size(), 11u);
  }
  // --bvh-start and --frames: 5 frames from BVH frame 21.
  const fs::path out2 = root_ / "out_motion_start";
  const std::string text2 = run_cli("simulate --checkpoint " + checkpoint() + " --motion " + bvh.string() +
                                        " --bvh-start 21 --frames 5 --scale 1 --up y" + garments + " --out " +
                                        out2.string(),
                                    &code);
  ASSERT_EQ(code, 0) << text2;
  EXPECT_EQ(dataset::read_pc2((out2 / "body.pc2").string()).frames.size(), 5u);
}

}  // namespace
}  // namespace layersnet::eval
