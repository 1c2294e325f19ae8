// Config files: defaults, overrides, includes, --set, and the errors a user meets.
#include "train/config.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace layersnet
