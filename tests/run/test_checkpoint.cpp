// Checkpoints: bit-exact round trip, atomic replacement, and refusal of what does not fit.
#include "run/checkpoint.h"

#include "model/params_layout.h"

#include <gtest/gtest.h>

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

namespace layersnet {
namespace {

namespace fs = std::filesystem;

void make_params(ad::ParamStore<float>& p, int width) {
  p.add("encoder.layers.0.attn.q_proj.weight", width, width);
  p.add("encoder.layers.0.attn.q_proj.bias", 1, width);
  p.add("decoder.proj.layers.2.weight", 3, width);
  p.finalize();
}

void fill_random(ad::ParamStore<float>& p, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> n;
  for (const auto& e : p.entries()) {
    for (int64_t k = 0; k < e.size(); ++k) {
      p.values()[e.offset + k] = n(rng);
      p.moment1()[e.offset + k] = n(rng);
      p.moment2()[e.offset + k] = std::abs(n(rng));
    }
  }
}

// Every tensor (values and both moments) equal bit for bit; padding between tensors ignored.
bool same_tensors(const ad::ParamStore<float>& a, const ad::ParamStore<float>& b) {
  for (const auto& e : a.entries()) {
    for (int64_t k = 0; k < e.size(); ++k) {
      const std::size_t i = e.offset + static_cast<std::size_t>(k);
      if (a.values()[i] != b.values()[i] || a.moment1()[i] != b.moment1()[i] || a.moment2()[i] != b.moment2()[i])
        return false;
    }
  }
  return true;
}

// A freshly initialised model of `config` (register_params, init_params with `seed`) written to
// `path` with the config embedded; `params` receives its weights.
void write_initial_model(const std::string& path, const Config& config, uint64_t seed, ad::ParamStore<float>& params,
                         Checkpoint cp = {}) {
  model::register_params(params, config.model);
  model::init_params(params, config.model, seed);
  cp.config_toml = to_toml(config);
  write_checkpoint(path, params, cp);
}

class CheckpointTest : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("layersnet_ckpt_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir_); }
  void TearDown() override { fs::remove_all(dir_); }
  Checkpoint sample_checkpoint() {
    Checkpoint cp;
    cp.config_toml = "[model]\nwidth = 8\n";
    cp.state.epoch = 3;
    cp.state.position = 17;
    cp.state.global_step = 1234;
    cp.state.best_val_error = 0.0123456789012345;
    cp.state.nonfinite_in_row = 2;
    cp.state.rng["shuffle"] = {1, 2, 3, 255, 0};
    cp.state.rng["noise"] = {};
    cp.stats["position_mean"] = {0.1, -0.2, 1.0 / 3.0};
    return cp;
  }
};

TEST_F(CheckpointTest, RoundTripIsBitExact) {
  ad::ParamStore<float> a, b;
  make_params(a, 8);
  make_params(b, 8);
  fill_random(a, 1);
  const std::string path = (dir_ / "c.h5").string();
  const Checkpoint cp = sample_checkpoint();
  write_checkpoint(path, a, cp);
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  const Checkpoint back = read_checkpoint(path, b);
  EXPECT_TRUE(same_tensors(a, b));
  EXPECT_EQ(back.config_toml, cp.config_toml);
  EXPECT_EQ(back.state.epoch, 3);
  EXPECT_EQ(back.state.position, 17);
  EXPECT_EQ(back.state.global_step, 1234);
  EXPECT_EQ(back.state.best_val_error, cp.state.best_val_error);
  EXPECT_EQ(back.state.nonfinite_in_row, 2);
  EXPECT_EQ(back.state.rng, cp.state.rng);
  EXPECT_EQ(back.stats, cp.stats);
  EXPECT_EQ(read_checkpoint_config(path), cp.config_toml);
}

TEST_F(CheckpointTest, PackedModelHoldsWeightsWithoutMomentsAndIsSmaller) {
  ad::ParamStore<float> a, b;
  make_params(a, 64);
  make_params(b, 64);
  fill_random(a, 1);
  std::fill(b.moment1().begin(), b.moment1().end(), 5.0f);
  const std::string full = (dir_ / "full.h5").string(), packed = (dir_ / "packed.h5").string();
  Checkpoint cp = sample_checkpoint();
  write_checkpoint(full, a, cp);
  cp.has_optimizer = false;
  write_checkpoint(packed, a, cp);
  const Checkpoint back = read_checkpoint(packed, b);
  EXPECT_FALSE(back.has_optimizer);
  EXPECT_TRUE(read_checkpoint(full, a).has_optimizer);
  EXPECT_TRUE(std::equal(a.values().begin(), a.values().end(), b.values().begin()));
  EXPECT_TRUE(std::all_of(b.moment1().begin(), b.moment1().end(), [](float m) { return m == 0.0f; }));
  EXPECT_EQ(back.stats, cp.stats);
  // Weights are a third of what a full checkpoint stores per parameter.
  EXPECT_LT(fs::file_size(packed), fs::file_size(full) * 6 / 10);
}

TEST_F(CheckpointTest, RewriteReplacesAtomically) {
  ad::ParamStore<float> a, b;
  make_params(a, 4);
  make_params(b, 4);
  const std::string path = (dir_ / "c.h5").string();
  fill_random(a, 1);
  write_checkpoint(path, a, sample_checkpoint());
  // A stale temporary from a crashed writer must not disturb the next write.
  std::ofstream(path + ".tmp") << "garbage";
  fill_random(a, 2);
  write_checkpoint(path, a, sample_checkpoint());
  read_checkpoint(path, b);
  EXPECT_TRUE(same_tensors(a, b));
}

TEST_F(CheckpointTest, OtherModelSizeIsRefusedWithTheDifferences) {
  ad::ParamStore<float> small, big;
  make_params(small, 4);
  make_params(big, 8);
  const std::string path = (dir_ / "c.h5").string();
  write_checkpoint(path, small, sample_checkpoint());
  try {
    read_checkpoint(path, big);
    FAIL() << "a checkpoint of another size was accepted";
  } catch (const CheckpointError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("encoder.layers.0.attn.q_proj.weight: checkpoint (4, 4), model (8, 8)"), std::string::npos) << msg;
    EXPECT_NE(msg.find("another model size"), std::string::npos) << msg;
  }
}

TEST_F(CheckpointTest, TruncatedCorruptedAndForeignFilesAreRefused) {
  ad::ParamStore<float> a;
  make_params(a, 8);
  fill_random(a, 3);
  const std::string path = (dir_ / "c.h5").string();
  write_checkpoint(path, a, sample_checkpoint());
  const auto size = fs::file_size(path);

  const std::string truncated = (dir_ / "truncated.h5").string();
  fs::copy_file(path, truncated);
  fs::resize_file(truncated, size / 2);
  EXPECT_THROW(read_checkpoint(truncated, a), CheckpointError);

  const std::string corrupted = (dir_ / "corrupted.h5").string();
  fs::copy_file(path, corrupted);
  {
    std::fstream f(corrupted, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(0);
    f.write("NOTHDF5!", 8);  // destroys the superblock signature
  }
  EXPECT_THROW(read_checkpoint(corrupted, a), CheckpointError);

  EXPECT_THROW(read_checkpoint((dir_ / "missing.h5").string(), a), CheckpointError);
}

// Expects read_checkpoint(path) to throw a CheckpointError whose message holds `needle`.
void expect_refused(const std::string& path, ad::ParamStore<float>& p, const std::string& needle) {
  try {
    read_checkpoint(path, p);
    ADD_FAILURE() << path << " was loaded";
  } catch (const CheckpointError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

TEST_F(CheckpointTest, AChangedWeightByteDamagedStatisticsAndANegativeSecondMomentAreRefused) {
  ad::ParamStore<float> a;
  make_params(a, 8);
  fill_random(a, 5);
  Checkpoint cp = sample_checkpoint();
  cp.stats = {{"position.mean", {0.1, 0.2, 0.3}}, {"position.std", {1.0, 2.0, 3.0}}};
  const std::string path = (dir_ / "c.h5").string();
  write_checkpoint(path, a, cp);

  // One byte of one weight changed where HDF5 stores it (its metadata stays intact).
  const std::string flipped = (dir_ / "flipped.h5").string();
  fs::copy_file(path, flipped);
  haddr_t offset = HADDR_UNDEF;
  {
    const hid_t f = H5Fopen(flipped.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t ds = H5Dopen2(f, "/weights/decoder.proj.layers.2.weight", H5P_DEFAULT);
    offset = H5Dget_offset(ds);
    H5Dclose(ds);
    H5Fclose(f);
  }
  ASSERT_NE(offset, HADDR_UNDEF);
  {
    std::fstream f(flipped, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(static_cast<std::streamoff>(offset) + 5);
    char byte = 0;
    f.read(&byte, 1);
    byte ^= 0x10;
    f.seekp(static_cast<std::streamoff>(offset) + 5);
    f.write(&byte, 1);
  }
  ad::ParamStore<float> b;
  make_params(b, 8);
  expect_refused(flipped, b, "checksum");
  read_checkpoint(path, b);  // the original still loads

  // Values no training writes, even with a matching checksum (written that way).
  Checkpoint nan_stats = cp;
  nan_stats.stats["position.std"][1] = std::nan("");
  write_checkpoint((dir_ / "nan_stats.h5").string(), a, nan_stats);
  expect_refused((dir_ / "nan_stats.h5").string(), b, "/stats/position.std");
  Checkpoint zero_std = cp;
  zero_std.stats["position.std"][0] = 0;
  write_checkpoint((dir_ / "zero_std.h5").string(), a, zero_std);
  expect_refused((dir_ / "zero_std.h5").string(), b, "std must be finite and > 0");
  ad::ParamStore<float> negative;
  make_params(negative, 8);
  fill_random(negative, 5);
  negative.moment2()[3] = -1e-3f;
  write_checkpoint((dir_ / "negative_v.h5").string(), negative, cp);
  expect_refused((dir_ / "negative_v.h5").string(), b, "negative or non-finite second moment");
  ad::ParamStore<float> nan_weight;
  make_params(nan_weight, 8);
  fill_random(nan_weight, 5);
  nan_weight.values()[0] = std::nanf("");
  write_checkpoint((dir_ / "nan_weight.h5").string(), nan_weight, cp);
  expect_refused((dir_ / "nan_weight.h5").string(), b, "non-finite values");
}

TEST_F(CheckpointTest, LoadModelRebuildsTheModelFromTheEmbeddedConfig) {
  Config config = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
  ad::ParamStore<float> params;
  const std::string path = (dir_ / "model.h5").string();
  write_initial_model(path, config, 7, params);
  const LoadedModel loaded = load_model(path);
  EXPECT_EQ(to_toml(loaded.config), to_toml(config));
  EXPECT_EQ(loaded.params.entries().size(), params.entries().size());
  EXPECT_TRUE(same_tensors(params, loaded.params));
}

TEST_F(CheckpointTest, AveragedModelHoldsTheMeanWeightsAndRefusesOtherModelsOrData) {
  Config config = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
  const auto write_model = [&](const Config& c, unsigned seed, double stat, const std::string& name) {
    ad::ParamStore<float> params;
    Checkpoint cp;
    cp.stats["velocity.mean"] = {stat, 0.0, 0.0};
    const std::string path = (dir_ / name).string();
    write_initial_model(path, c, seed, params, cp);
    return path;
  };
  const std::string a = write_model(config, 1, 0.5, "a.h5");
  const std::string b = write_model(config, 2, 0.5, "b.h5");
  Config other_training = config;
  other_training.train.learning_rate *= 2;  // training settings may differ, the energy's too
  other_training.physics.weight = 0.5;
  const std::string c = write_model(other_training, 3, 0.5, "c.h5");

  const LoadedModel la = load_model(a), lb = load_model(b), lc = load_model(c);
  const LoadedModel mean = average_models({a, b, c});
  EXPECT_FALSE(mean.checkpoint.has_optimizer);
  EXPECT_EQ(to_toml(mean.config), to_toml(la.config));
  int differing = 0;
  for (const auto& e : la.params.entries()) {
    for (int64_t k = 0; k < e.size(); ++k) {
      const std::size_t i = e.offset + static_cast<std::size_t>(k);
      const double expected = (static_cast<double>(la.params.values()[i]) + lb.params.values()[i] + lc.params.values()[i]) / 3;
      EXPECT_NEAR(mean.params.values()[i], expected, 1e-6 * (1 + std::abs(expected)));
      differing += la.params.values()[i] != lb.params.values()[i];
    }
  }
  EXPECT_GT(differing, 0);  // the seeds gave different weights, so the mean is not a copy

  // The error names the refused file and what differs.
  const auto expect_refused = [&](const std::string& other, const std::string& file, const std::string& what) {
    try {
      average_models({a, other});
      ADD_FAILURE() << other << " was averaged in";
    } catch (const CheckpointError& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  expect_refused(write_model(config, 4, 0.7, "other_data.h5"), "other_data.h5", "statistics");
  Config other_radius = config;
  other_radius.model.world_radius *= 2;  // same shapes, another model
  expect_refused(write_model(other_radius, 5, 0.5, "other_model.h5"), "other_model.h5", "[model]");
}

// train.init_from across [model] configs: shared tensors copied by name, a tensor only this
// model has starts at zero, and a tensor only the checkpoint has is refused by name.
TEST_F(CheckpointTest, WeightsByNameFillAnAddedInputWeightWithZeros) {
  const Config plain = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
  Config local = plain;
  local.model.vertex_local_features = true;
  ad::ParamStore<float> trained;
  Checkpoint cp;
  cp.state.global_step = 12;
  const std::string path = (dir_ / "plain.h5").string();
  write_initial_model(path, plain, 7, trained, cp);

  ad::ParamStore<float> widened;
  model::register_params(widened, local.model);
  model::init_params(widened, local.model, 8);
  const WeightsByName read = read_weights_by_name(path, widened);
  EXPECT_EQ(read.checkpoint.state.global_step, 12);
  EXPECT_EQ(read.added, std::vector<std::string>{"decoder.local.weight"});
  EXPECT_FALSE(read.config.model.vertex_local_features);
  for (const auto& e : widened.entries()) {
    const auto first = widened.values().begin() + static_cast<std::ptrdiff_t>(e.offset);
    if (e.name == "decoder.local.weight") {
      EXPECT_TRUE(std::all_of(first, first + e.size(), [](float v) { return v == 0.0f; }));
      continue;
    }
    const auto& t = trained.entries()[static_cast<std::size_t>(trained.index_of(e.name))];
    EXPECT_TRUE(std::equal(first, first + e.size(), trained.values().begin() + static_cast<std::ptrdiff_t>(t.offset)))
        << e.name;
  }
  EXPECT_TRUE(std::all_of(widened.moment1().begin(), widened.moment1().end(), [](float v) { return v == 0.0f; }));

  // The other way round the checkpoint holds a weight this model would drop.
  const std::string local_path = (dir_ / "local.h5").string();
  cp.config_toml = to_toml(local);
  write_checkpoint(local_path, widened, cp);
  ad::ParamStore<float> narrow;
  model::register_params(narrow, plain.model);
  try {
    read_weights_by_name(local_path, narrow);
    ADD_FAILURE() << "a checkpoint with a weight this model lacks was accepted";
  } catch (const CheckpointError& e) {
    EXPECT_NE(std::string(e.what()).find("decoder.local.weight"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not in this model"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace layersnet
