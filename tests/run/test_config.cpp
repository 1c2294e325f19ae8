// Config files: defaults, overrides, includes, --set, and the errors a user meets.
#include "run/config.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <sstream>

#include <filesystem>
#include <fstream>

namespace layersnet {
namespace {

namespace fs = std::filesystem;

class ConfigTest : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("layersnet_config_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir_); }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  // The message of the ConfigError `f` throws ("" if none).
  template <class F>
  static std::string error_of(F f) {
    try {
      f();
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  }
};

TEST_F(ConfigTest, DefaultsAreTheOfficialSizes) {
  const Config c = load_config({});
  EXPECT_EQ(c.model.width, 128);
  EXPECT_EQ(c.model.heads, 8);
  EXPECT_EQ(c.model.layers, 4);
  EXPECT_EQ(c.model.body_neighbors, 16);
  EXPECT_DOUBLE_EQ(c.loss.collision_body, 1.3);
  EXPECT_EQ(c.train.rollout_steps, (std::vector<int>{0, 1, 2, 3, 4, 5, 7, 7, 8, 9}));
}

TEST_F(ConfigTest, FileOverridesAndIncludeAppliesBaseFirst) {
  write("base.toml", "[model]\nwidth = 64\nlayers = 2\n[train]\nepochs = 3\n");
  const std::string f = write("child.toml", "include = \"base.toml\"\n[model]\nlayers = 3\n");
  const Config c = load_config({f});
  EXPECT_EQ(c.model.width, 64);   // from the base
  EXPECT_EQ(c.model.layers, 3);   // the child wins
  EXPECT_EQ(c.train.epochs, 3);
  EXPECT_EQ(c.model.heads, 8);    // untouched default
}

TEST_F(ConfigTest, SetOverridesComeLastAndParseTomlValues) {
  const std::string f = write("a.toml", "[train]\nepochs = 3\n");
  const Config c = load_config({f}, {"train.epochs=5", "train.rollout_steps=[0, 2]", "data.dataset=data/x",
                                     "model.rotation_equivalent=false", "train.learning_rate=2e-4"});
  EXPECT_EQ(c.train.epochs, 5);
  EXPECT_EQ(c.train.rollout_steps, (std::vector<int>{0, 2}));
  EXPECT_EQ(c.data.dataset, "data/x");
  EXPECT_FALSE(c.model.rotation_equivalent);
  EXPECT_DOUBLE_EQ(c.train.learning_rate, 2e-4);
}

TEST_F(ConfigTest, UnknownKeyNamesFileLineAndClosestKey) {
  const std::string f = write("typo.toml", "[model]\nwidth = 64\nlayres = 2\n");
  const std::string msg = error_of([&] { load_config({f}); });
  EXPECT_NE(msg.find("typo.toml:3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("unknown key 'model.layres'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("did you mean 'model.layers'"), std::string::npos) << msg;
}

// Settings each within range that cannot build a model together are refused at load, naming
// every key involved and the file:line (or --set) that set it.
TEST_F(ConfigTest, ModelShapesThatCannotBuildNameTheirKeysAndLines) {
  const std::string f = write("shape.toml", "[model]\nheads = 4\nwidth = 18\n");
  std::string msg = error_of([&] { load_config({f}); });
  EXPECT_NE(msg.find("model.width = 18 (set at " + f + ":3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("model.heads = 4 (set at " + f + ":2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("set model.width to 16 or 20"), std::string::npos) << msg;
  msg = error_of([&] { load_config({}, {"model.heads=3", "model.width=96"}); });
  EXPECT_NE(msg.find("model.heads = 3 (set at --set model.heads=3)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("must be even"), std::string::npos) << msg;
  msg = error_of([&] { load_config({}, {"model.decoder_ret_channels=100"}); });
  EXPECT_NE(msg.find("model.decoder_ret_channels = 100"), std::string::npos) << msg;
  EXPECT_NE(msg.find("model.width = 128 (default)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("<= 42"), std::string::npos) << msg;
  // Without RET the decoder has no rotation channels: any count loads.
  EXPECT_EQ(error_of([&] { load_config({}, {"model.decoder_ret_channels=100", "model.rotation_equivalent=false"}); }), "");
  // The same checks guard a checkpoint's embedded config.
  Config bad;
  bad.model.width = 18;
  bad.model.heads = 4;
  msg = error_of([&] { parse_config_text(to_toml(bad), "run/best.h5:/config"); });
  EXPECT_NE(msg.find("run/best.h5:/config:"), std::string::npos) << msg;
}

TEST_F(ConfigTest, ABodyBlindModelAHugeBatchAndADirectoryIncludeAreRefused) {
  std::string msg = error_of([&] { load_config({}, {"model.body_neighbors=0"}); });
  EXPECT_NE(msg.find("model.body_neighbors"), std::string::npos) << msg;
  EXPECT_NE(msg.find("[1, 256]"), std::string::npos) << msg;
  msg = error_of([&] { load_config({}, {"train.batch_size=1000000000"}); });
  EXPECT_NE(msg.find("[1, 4096]"), std::string::npos) << msg;
  fs::create_directories(dir_ / "sub");
  const std::string f = write("dir.toml", "include = \"sub\"\n");
  msg = error_of([&] { load_config({f}); });
  EXPECT_NE(msg.find("is a directory, not a config file (included from"), std::string::npos) << msg;
}

TEST_F(ConfigTest, WrongTypeAndOutOfRangeAreErrors) {
  const std::string t = write("type.toml", "[train]\nepochs = \"ten\"\n");
  std::string msg = error_of([&] { load_config({t}); });
  EXPECT_NE(msg.find("type.toml:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'train.epochs' must be a integer"), std::string::npos) << msg;

  const std::string r = write("range.toml", "\n[loss]\ncollision_eps = -1.0\n");
  msg = error_of([&] { load_config({r}); });
  EXPECT_NE(msg.find("range.toml:3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("out of range"), std::string::npos) << msg;

  msg = error_of([&] { load_config({}, {"model.attention=dense"}); });
  EXPECT_NE(msg.find("--set model.attention=dense"), std::string::npos) << msg;
  EXPECT_NE(msg.find("not one of \"ria\", \"tie\""), std::string::npos) << msg;

  msg = error_of([&] { load_config({}, {"train.epochs"}); });
  EXPECT_NE(msg.find("expected key=value"), std::string::npos) << msg;
}

TEST_F(ConfigTest, SyntaxErrorsMissingFilesAndIncludeCycles) {
  const std::string s = write("syntax.toml", "[model\nwidth = 1\n");
  EXPECT_NE(error_of([&] { load_config({s}); }).find("syntax.toml:1:"), std::string::npos);
  EXPECT_NE(error_of([&] { load_config({(dir_ / "nope.toml").string()}); }).find("not found"), std::string::npos);
  write("x.toml", "include = \"y.toml\"\n");
  const std::string y = write("y.toml", "include = \"x.toml\"\n");
  EXPECT_NE(error_of([&] { load_config({y}); }).find("include cycle"), std::string::npos);
}

TEST_F(ConfigTest, ResolvedTomlRoundTrips) {
  const Config a = load_config({}, {"model.width=96", "train.learning_rate=0.000123456789", "data.dataset=a \"b\"",
                                    "train.lr_decay_epochs=[]"});
  const std::string text = to_toml(a);
  const Config b = load_config({write("resolved.toml", text)});
  EXPECT_EQ(to_toml(b), text);
  EXPECT_EQ(b.model.width, 96);
  EXPECT_EQ(b.train.learning_rate, a.train.learning_rate);  // bit-exact: 17 digits
  EXPECT_EQ(b.data.dataset, "a \"b\"");
  EXPECT_TRUE(b.train.lr_decay_epochs.empty());
}

// Runs and checkpoints saved before model.decoder_ret_channels existed used the official
// rank-3 decoder map (k = 1); they must load as such, not with today's default.
TEST_F(ConfigTest, SavedConfigWithoutDecoderChannelsMeansTheOfficialMap) {
  Config fresh;
  ASSERT_NE(fresh.model.decoder_ret_channels, 1);
  std::string text = to_toml(fresh);
  EXPECT_EQ(parse_config_text(text, "now").model.decoder_ret_channels, fresh.model.decoder_ret_channels);
  std::string old;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);)
    if (line.find("decoder_ret_channels") == std::string::npos) old += line + "\n";
  EXPECT_EQ(parse_config_text(old, "old").model.decoder_ret_channels, 1);
  EXPECT_EQ(parse_config_text(old, "old").model.width, fresh.model.width);
}

// Radii under one patch extent (patch_size * 10 scene units) warn, naming the keys and the fix.
TEST_F(ConfigTest, RadiusWarningFiresForSmallRadiiOnly) {
  Config c;
  c.model.patch_size = 0.1;  // 1 scene unit
  c.model.world_radius = 0.4;
  c.model.body_radius = 0.6;
  const auto w = config_warnings(c);
  ASSERT_EQ(w.size(), 2u);
  EXPECT_NE(w[0].find("model.world_radius = 0.4"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("model.patch_size = 0.1"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("set model.world_radius >= 1"), std::string::npos) << w[0];
  EXPECT_NE(w[1].find("set model.body_radius >= 1"), std::string::npos) << w[1];
  for (const auto& message : w)  // reach is not accuracy: the message says to measure
    EXPECT_NE(message.find("only if validation improves"), std::string::npos) << message;
  c.model.world_radius = 1.2;
  ASSERT_EQ(config_warnings(c).size(), 1u);
  EXPECT_NE(config_warnings(c)[0].find("model.body_radius"), std::string::npos);
  c.model.body_radius = 1.0;
  EXPECT_TRUE(config_warnings(c).empty());
  EXPECT_TRUE(config_warnings(Config{}).empty()) << "official 0.04 / 0.4 / 0.6 sit on or above the line";
  EXPECT_EQ(config_warnings(load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/quick.toml"})).size(), 2u);
}

// `config` prints each warning once, on stderr: stdout stays the resolved TOML.
TEST_F(ConfigTest, ConfigCommandWarnsOnStderrOnce) {
  if (!fs::exists(LAYERSNET_BINARY)) GTEST_SKIP() << "layersnet binary not built";
  const fs::path out = dir_ / "out.toml", err = dir_ / "err.txt";
  const std::string cmd = std::string(LAYERSNET_BINARY) + " config -c " + LAYERSNET_SOURCE_DIR +
                          "/configs/quick.toml --set model.body_radius=2 > " + out.string() + " 2> " + err.string();
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::stringstream e, o;
  e << std::ifstream(err).rdbuf();
  o << std::ifstream(out).rdbuf();
  const std::string text = e.str();
  const auto first = text.find("warning: model.world_radius = 0.4");
  ASSERT_NE(first, std::string::npos) << text;
  EXPECT_EQ(text.find("warning: model.world_radius", first + 1), std::string::npos) << text;
  EXPECT_EQ(text.find("model.body_radius"), std::string::npos) << text;
  EXPECT_EQ(o.str().find("warning"), std::string::npos);
  EXPECT_EQ(parse_config_text(o.str(), "stdout").model.world_radius, 0.4);
}

// best.h5 follows a validation rollout unless a config asks for the one-step error; runs saved
// before the key existed keep the one-step error.
TEST_F(ConfigTest, ValidationIsByRolloutByDefault) {
  EXPECT_GT(TrainConfig{}.val_rollout_frames, 0);
  EXPECT_EQ(load_config({}, {"train.val_rollout_frames=0"}).train.val_rollout_frames, 0);
  EXPECT_EQ(load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/paper.toml"}).train.val_rollout_frames, 0);
  std::string old;
  std::istringstream lines(to_toml(Config{}));
  for (std::string line; std::getline(lines, line);)
    if (line.find("val_rollout_frames") == std::string::npos) old += line + "\n";
  EXPECT_EQ(parse_config_text(old, "old").train.val_rollout_frames, 0);
  EXPECT_GT(parse_config_text(to_toml(Config{}), "new").train.val_rollout_frames, 0);
}

TEST_F(ConfigTest, EveryShippedConfigLoads) {
  int n = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(LAYERSNET_SOURCE_DIR) / "configs")) {
    if (entry.path().extension() != ".toml") continue;
    SCOPED_TRACE(entry.path().string());
    EXPECT_NO_THROW(load_config({entry.path().string()}));
    ++n;
  }
  EXPECT_GE(n, 3);
}

// Pretraining scores Blender's energy alone, on every step, and trains the very model the default
// recipe fine-tunes (a checkpoint of one starts the other).
TEST_F(ConfigTest, PretrainingIsTheEnergyAloneOnTheDefaultModel) {
  const std::string configs = std::string(LAYERSNET_SOURCE_DIR) + "/configs/";
  const Config pre = load_config({configs + "pretrain.toml"});
  const Config fine = load_config({configs + "default.toml"});
  for (const double w : {pre.loss.vertex, pre.loss.patch, pre.loss.normal, pre.loss.collision_body,
                         pre.loss.collision_layer, pre.loss.edge_strain})
    EXPECT_EQ(w, 0.0);
  EXPECT_GT(pre.physics.weight, 0.0);
  EXPECT_FALSE(pre.physics.self_fed_only);
  EXPECT_FALSE(pre.train.validate);
  EXPECT_GT(pre.train.max_steps, 0);
  auto section = [](const Config& c, const std::string& name) {
    const std::string text = to_toml(c);
    const std::size_t begin = text.find("[" + name + "]");
    return text.substr(begin, text.find("\n[", begin + 1) - begin);
  };
  EXPECT_EQ(section(pre, "model"), section(fine, "model"));
}

// The kept share of the swing belongs to the body_inertia base; elsewhere it would do nothing.
TEST_F(ConfigTest, SwingKeptNeedsTheBodyInertiaBase) {
  EXPECT_EQ(load_config({}, {"model.velocity_base=body_inertia", "model.swing_kept=0.5"}).model.swing_kept, 0.5);
  try {
    load_config({}, {"model.velocity_base=body", "model.swing_kept=0.5"});
    ADD_FAILURE() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("model.swing_kept = 0.5 (set at --set"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_config({}, {"model.velocity_base=body_inertia", "model.swing_kept=1.5"}), ConfigError);
}

// The base inputs are the carried base (patch mean, per vertex); the official base has none.
TEST_F(ConfigTest, BaseInputsNeedACarriedBase) {
  EXPECT_TRUE(load_config({}, {"model.velocity_base=body", "model.patch_base_input=true"}).model.patch_base_input);
  EXPECT_TRUE(load_config({}, {"model.velocity_base=physics", "model.vertex_base_input=true"}).model.vertex_base_input);
  for (const std::string name : {"model.patch_base_input", "model.vertex_base_input"}) {
    try {
      load_config({}, {name + "=true"});
      ADD_FAILURE() << "no ConfigError for " << name;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(name + " = true (set at --set"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("model.velocity_base = \"inertia\" (default)"), std::string::npos) << e.what();
    }
  }
}

// The energy's friction holds cloth where the physics step carries it: no physics base, no friction.
TEST_F(ConfigTest, PhysicsFrictionNeedsThePhysicsBase) {
  EXPECT_EQ(load_config({}, {"model.velocity_base=physics", "physics.friction=1"}).physics.friction, 1.0);
  EXPECT_EQ(load_config({}, {}).physics.friction, 0.0);
  try {
    load_config({}, {"physics.friction=1"});
    ADD_FAILURE() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("physics.friction = 1 (set at --set"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("model.velocity_base = \"inertia\" (default)"), std::string::npos) << e.what();
  }
}

TEST_F(ConfigTest, SolvedCorrectionNeedsOnePhysicsStepAndNoSmoothing) {
  EXPECT_EQ(load_config({}, {"model.velocity_base=physics", "model.physics_step_correction=solved"}).model.physics_step_correction,
            "solved");
  EXPECT_EQ(load_config({}, {}).model.physics_step_correction, "added");
  const std::vector<std::pair<std::vector<std::string>, std::string>> refused = {
      {{"model.physics_step_correction=solved"}, "model.velocity_base = \"inertia\" (default)"},
      {{"model.velocity_base=physics", "model.physics_step_correction=solved", "model.physics_step_substeps=2"},
       "model.physics_step_substeps = 2 (set at --set"},
      {{"model.velocity_base=physics", "model.physics_step_correction=solved", "model.output_smoothing=1"},
       "model.output_smoothing = 1 (set at --set"},
  };
  for (const auto& [sets, named] : refused) {
    try {
      load_config({}, sets);
      ADD_FAILURE() << "no ConfigError for " << named;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("model.physics_step_correction = \"solved\""), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
    }
  }
}

TEST_F(ConfigTest, SelfFedTruthOffNeedsThePhysicsEnergy) {
  const Config c = load_config({}, {"loss.self_fed_truth=0", "physics.weight=0.1"});
  EXPECT_EQ(c.loss.self_fed_truth, 0.0);
  EXPECT_EQ(load_config({}, {}).loss.self_fed_truth, 1.0);
  try {
    load_config({}, {"loss.self_fed_truth=0"});
    ADD_FAILURE() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("physics.weight = 0 (default)"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("loss.self_fed_truth = 0 (set at --set"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_config({}, {"loss.self_fed_truth=1.5"}), ConfigError);
}

// A trained model's rollout may change its eval.* settings, the step's conjugate-gradient count
// (the solver's, not the weights') and where the step's pins come from (the scene's); any other
// model key is refused, naming the ones allowed.
TEST(RolloutOverride, TakesEvalKeysTheStepsSolverIterationsAndPinsOnly) {
  Config c;
  apply_rollout_override(c, "eval.strain_limit=0.2");
  EXPECT_DOUBLE_EQ(c.eval.strain_limit, 0.2);
  apply_rollout_override(c, "model.physics_step_cg_iterations = 40");
  EXPECT_EQ(c.model.physics_step_cg_iterations, 40);
  apply_rollout_override(c, "model.physics_step_pins=recorded");
  EXPECT_EQ(c.model.physics_step_pins, "recorded");
  EXPECT_THROW(apply_rollout_override(c, "model.physics_step_pins=rigid"), ConfigError);  // not a choice
  for (const char* fixed : {"model.width=64", "model.physics_step_bending=0.5", "model.physics_step_cg_iterations_x=1"}) {
    try {
      apply_rollout_override(c, fixed);
      ADD_FAILURE() << fixed << ": no ConfigError";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("eval.*, model.physics_step_cg_iterations and model.physics_step_pins"),
                std::string::npos)
          << e.what();
    }
  }
  EXPECT_EQ(c.model.width, Config{}.model.width);
  EXPECT_THROW(apply_rollout_override(c, "model.physics_step_cg_iterations=0"), ConfigError);  // the key's own range
}

}  // namespace
}  // namespace layersnet
