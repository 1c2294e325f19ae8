#pragma once
// Helpers of the end-to-end tests: run the `layersnet` binary, read a file, make the tiny data
// set and checkpoint most of them start from.
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "eval/rollout.h"
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "run/config.h"
#include "run/run_dir.h"

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace layersnet::eval::cli_test {

// Runs `layersnet ARGS` (stderr merged into the returned text); *code = its exit status (-1 if killed).
inline std::string run_cli(const std::string& args, int* code) {
  const std::string cmd = std::string(LAYERSNET_BINARY) + " " + args + " 2>&1";
  std::FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  while (std::fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  *code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A freshly initialised configs/tiny.toml model (seed 7; its output layer starts at zero) carrying
// `stats`, with `overrides` (--set assignments) applied; its config names `dataset` when one is given.
inline void write_tiny_checkpoint(const std::filesystem::path& path, const dataset::NormalisationStats& stats,
                                  const std::string& dataset = "", const std::vector<std::string>& overrides = {}) {
  Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"}, overrides);
  if (!dataset.empty()) c.data.dataset = dataset;
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 7);
  Checkpoint cp;
  cp.config_toml = to_toml(c);
  cp.stats = stats_to_arrays(stats);
  write_checkpoint(path.string(), ps, cp);
}

// At root/data: a synthetic data set (n_train / n_val / n_test sequences of two tube garments,
// 9 frames, on a coarse body) with its stats.h5. At root/tiny.h5: a freshly initialised
// configs/tiny.toml model (seed 7) whose config names that data set and which carries its
// statistics. Returns the statistics.
inline dataset::NormalisationStats write_tiny_data_and_checkpoint(const std::filesystem::path& root, int n_train,
                                                                  int n_val, int n_test, bool wind) {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 9;
  o.rings = 4;
  o.segments = 8;
  o.body_rings = 4;
  o.body_segments = 8;
  o.wind = wind;
  const auto m = dataset::write_synthetic_dataset((root / "data").string(), n_train, n_val, n_test, o);
  const auto stats = dataset::compute_stats(m);
  dataset::write_stats(m.stats_path(), stats);
  write_tiny_checkpoint(root / "tiny.h5", stats, (root / "data").string());
  return stats;
}

}  // namespace layersnet::eval::cli_test
