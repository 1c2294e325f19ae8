// `layersnet eval --checkpoint C [--checkpoint C2 ...] [--split test] [--frames N] [--out DIR]`:
// rollouts of every checkpoint, of recorded sequences (--replay) and of the two baselines (constant velocity, follow the body)
// over a split, Euclidean error, collision rates and edge strain (with the ground truth's own
// values as the floor), speed at 1 and 2 threads against Blender's recorded time; writes
// eval.json, eval.md, curve.png, speed.png, strain.png to --out and prints the summary table.
// See eval/README.md.
#include "autodiff/bf16_gemm.h"
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "dataset/manifest.h"
#include "dataset/stats.h"
#include "eval/evaluate.h"
#include "eval/report.h"
#include "train/checkpoint.h"
#include "train/run_dir.h"

#include <Eigen/Core>

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

namespace {
using namespace layersnet;

struct EvalCliOptions {
  std::vector<std::string> runs;
  std::vector<std::string> checkpoints;
  std::vector<std::string> names;
  std::vector<std::string> replays;  // folders of recorded sequences (eval::Replay)
  std::string dataset;
  std::string split;
  int frames = -1;
  int start_frame = -1;
  std::string start;  // ramp | fixed; empty: ramp, or fixed when --start-frame is given
  int max_sequences = 0;
  int speed_frames = 10;
  int threads = 0;
  std::string out = "eval_out";
  std::string precision = "float32";  // of the models' linear products: float32 | bf16 | float32,bf16
  std::vector<double> tethers;        // patch tether factors (eval/tether.h); empty: each checkpoint's own
  std::vector<std::string> constraints;  // "on" / "off" (train/cloth_constraints.h); empty: each checkpoint's own
  std::vector<std::string> settings;     // "eval.KEY=VALUE" for every model
};

// "<folder>/<stem> (<attention>[+RET])": distinguishes ablation runs in one table.
std::string default_name(const std::string& path, const Config& c) {
  const std::filesystem::path p(path);
  std::string folder = p.parent_path().filename().string();
  std::string name = (folder.empty() ? "" : folder + "/") + p.stem().string();
  return name + " (" + c.model.attention + (c.model.rotation_equivalent ? "+RET" : ", vanilla") + ")";
}

int run_eval(EvalCliOptions o) {
  // Every model once per listed precision (a list shows the bf16 speed/accuracy trade in one table).
  std::vector<ad::MatmulPrecision> precisions;
  for (std::size_t a = 0, b; a <= o.precision.size(); a = b + 1) {
    b = std::min(o.precision.find(',', a), o.precision.size());
    try {
      precisions.push_back(ad::parse_matmul_precision(o.precision.substr(a, b - a)));
    } catch (const std::exception& e) {
      throw cli::UsageError(std::string("--precision: ") + e.what());
    }
  }
  std::vector<std::string> from_runs;  // runs first, in order, then --checkpoint files
  for (const auto& run : o.runs) from_runs.push_back(run_checkpoint(run));
  o.checkpoints.insert(o.checkpoints.begin(), from_runs.begin(), from_runs.end());
  // Settings: the first checkpoint's config supplies the defaults.
  Config base;
  if (!o.checkpoints.empty()) base = parse_config_text(read_checkpoint_config(o.checkpoints[0]), o.checkpoints[0]);
  const std::string root = o.dataset.empty() ? base.data.dataset : o.dataset;
  const dataset::DatasetManifest manifest = dataset::read_manifest(root);
  std::unique_ptr<dataset::NormalisationStats> fallback;
  if (std::filesystem::exists(manifest.stats_path()))
    fallback = std::make_unique<dataset::NormalisationStats>(dataset::read_stats(manifest.stats_path()));

  eval::EvalOptions eo;
  eo.split = o.split.empty() ? base.eval.split : o.split;
  eo.frames = o.frames > 0 ? o.frames : base.eval.frames;
  eo.start_frame = o.start_frame >= 2 ? o.start_frame : std::max(2, base.data.first_frame);
  eo.start_after_ramp = o.start.empty() ? o.start_frame < 0 : o.start == "ramp";
  eo.max_sequences = o.max_sequences;

  const bool any_bf16 = std::count(precisions.begin(), precisions.end(), ad::MatmulPrecision::kBFloat16) > 0;
  std::vector<std::unique_ptr<eval::Predictor>> owned;
  std::vector<std::string> kinds, paths;
  for (size_t i = 0; i < o.checkpoints.size(); ++i) {
    const Config c = parse_config_text(read_checkpoint_config(o.checkpoints[i]), o.checkpoints[i]);
    const std::string name = i < o.names.size() ? o.names[i] : default_name(o.checkpoints[i], c);
    const std::vector<double> tethers = o.tethers.empty() ? std::vector<double>{c.eval.patch_tether} : o.tethers;
    std::vector<bool> constrained;
    for (const auto& setting : o.constraints) constrained.push_back(setting == "on");
    if (constrained.empty()) constrained.push_back(c.eval.constraints);
    for (const bool constrain : constrained)
      for (const double tether : tethers)
        for (const ad::MatmulPrecision precision : precisions) {
          std::string prefix;  // in front: tables cut long names
          if (o.constraints.size() > 1 && constrain) prefix += "[constrained] ";
          if (o.tethers.size() > 1) {
            char tag[48];
            std::snprintf(tag, sizeof tag, "[t%g] ", tether);
            prefix += tag;
          }
          auto model = eval::load_model_predictor(o.checkpoints[i], prefix + name, fallback.get());
          model->set_matmul_precision(precision);  // bf16: the name gets "[bf16] " in front
          model->apply_eval_settings(o.settings);
          model->set_patch_tether(tether);
          model->set_constraints(constrain);
          owned.push_back(std::move(model));
          kinds.push_back("model");
          paths.push_back(o.checkpoints[i]);
        }
  }
  const size_t model_count = owned.size();
  for (size_t r = 0; r < o.replays.size(); ++r) {
    const size_t n = o.checkpoints.size() + r;
    const std::string name = n < o.names.size() ? o.names[n] : "replay " + o.replays[r];
    owned.push_back(std::make_unique<eval::Replay>(name, o.replays[r]));
    kinds.push_back("replay");
    paths.push_back(o.replays[r]);
  }
  owned.push_back(std::make_unique<eval::ConstantVelocity>());
  owned.push_back(std::make_unique<eval::FollowBody>());
  owned.push_back(std::make_unique<eval::GroundTruth>());
  for (const char* k : {"baseline", "baseline", "ground truth"}) {
    kinds.push_back(k);
    paths.push_back("");
  }
  std::vector<eval::Predictor*> predictors;
  for (auto& p : owned) predictors.push_back(p.get());

  if (o.threads > 0) omp_set_num_threads(o.threads);  // the evaluation rollouts (speed sets its own)
  Eigen::setNbThreads(1);  // the ops own the threads (as bench model); nested GEMM threads only contend
  std::printf("eval: %s split '%s', %zu model(s), %zu replay(s) + 2 baselines, up to %d frames from %s, %d thread(s), "
              "products %s%s%s\n",
              root.c_str(), eo.split.c_str(), model_count, o.replays.size(), eo.frames, eval::start_description(eo).c_str(),
              omp_get_max_threads(), o.precision.c_str(), any_bf16 ? ", bf16 kernel " : "", any_bf16 ? ad::bf16_kernel_name() : "");
  std::vector<eval::MethodResult> results = eval::evaluate(manifest, predictors, eo, true);
  for (size_t p = 0; p < results.size(); ++p) {
    results[p].kind = kinds[p];
    results[p].checkpoint = paths[p];
  }

  eval::ReportContext ctx;
  ctx.dataset = root;
  ctx.options = eo;
  // Speed on the first sequence of the split, 1 and 2 threads.
  const std::string speed_id = results[0].sequences[0].id;
  const dataset::Sequence speed_seq = dataset::read_sequence(manifest.sequence_path(speed_id));
  const int speed_t0 = results[0].sequences[0].first_frame - 1;  // the evaluation's own start
  ctx.speed_sequence = speed_id;
  ctx.speed_frames = std::min(o.speed_frames, speed_seq.info.num_frames - 1 - speed_t0);
  for (size_t p = 0; p + 1 < predictors.size(); ++p) {
    if (kinds[p] == "replay") continue;  // a recording has no speed of its own
    results[p].ms_per_frame_1thread = eval::median_ms_per_frame(*predictors[p], speed_seq, speed_t0, ctx.speed_frames, 1);
    results[p].ms_per_frame_2threads = eval::median_ms_per_frame(*predictors[p], speed_seq, speed_t0, ctx.speed_frames, 2);
  }
  double blender_sum = 0;
  int blender_n = 0;
  for (const auto& s : results[0].sequences) {
    const double b = eval::blender_seconds_per_frame(manifest.sequence_path(s.id));
    if (b > 0) {
      blender_sum += b;
      ++blender_n;
    }
  }
  ctx.blender_s_per_frame = blender_n ? blender_sum / blender_n : -1;
  std::ifstream loadavg("/proc/loadavg");  // context for the speed figures on a shared machine
  loadavg >> ctx.load_average;

  const auto written = eval::write_report(o.out, results, ctx);
  std::printf("\n%s", eval::summary_table(results, ctx).c_str());
  std::printf("wrote");
  for (const auto& w : written) std::printf(" %s", w.c_str());
  std::printf("\n");
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(eval, "Roll out checkpoints and baselines over a split; error, collisions, speed, reports",
                  [](CLI::App& sub) {
                    auto o = std::make_shared<EvalCliOptions>();
                    sub.add_option("--checkpoint", o->checkpoints, "checkpoint (repeat for several variants)");
                    sub.add_option("--run", o->runs, "run directory of `layersnet train` (its best.h5, else newest checkpoint); repeatable");
                    sub.add_option("--name", o->names,
                                   "table name of each model, then of each replay, in order (runs first; default: "
                                   "folder/file, 'replay FOLDER')");
                    sub.add_option("--replay", o->replays,
                                   "folder of another simulator's recorded sequences, scored like a model: for each "
                                   "evaluated sequence the file of the same name, same garments (e.g. a "
                                   "re-simulation, scripts/predictability.sh); repeatable")
                        ->check(CLI::ExistingDirectory);
                    sub.add_option("--dataset", o->dataset, "data set folder (default: the first checkpoint's data.dataset)");
                    sub.add_option("--split", o->split, "train | val | test (default: the config's eval.split)");
                    sub.add_option("--frames", o->frames, "predicted frames per sequence (default: eval.frames)");
                    sub.add_option("--start", o->start,
                                   "where rollouts start: ramp = per sequence, the first predicted frame is the "
                                   "file's rest_frames + ramp_frames (files without them: as fixed); fixed = input "
                                   "frame t0 = --start-frame (default: ramp, or fixed when --start-frame is given)")
                        ->check(CLI::IsMember({"ramp", "fixed"}));
                    sub.add_option("--start-frame", o->start_frame,
                                   "input frame t0 of a fixed start, and of --start ramp for files without the ramp "
                                   "attributes (default: data.first_frame)");
                    sub.add_option("--max-sequences", o->max_sequences, "evaluate only the first N sequences (0 = all)");
                    sub.add_option("--speed-frames", o->speed_frames, "frames of the 1- and 2-thread speed rollouts")
                        ->check(CLI::Range(1, 1000000));
                    sub.add_option("--tether", o->tethers,
                                   "patch tether factors, e.g. 0,3: every model once per factor (default: each checkpoint's eval.patch_tether)")
                        ->delimiter(',')
                        ->check(layersnet::cli::kFiniteNonNegative);
                    sub.add_option("--constraints", o->constraints,
                                   "cloth constraints after every predicted frame (edge strain limit, collision shell; "
                                   "train/cloth_constraints.h): on, off, or off,on for every model both ways (default: each "
                                   "checkpoint's eval.constraints)")
                        ->delimiter(',')
                        ->check(CLI::IsMember({"on", "off"}));
                    sub.add_option("--set", o->settings,
                                   "rollout setting for every model, e.g. --set eval.strain_limit=0.2 (eval.* keys; "
                                   "`layersnet config --keys` lists them)");
                    sub.add_option("--threads", o->threads, "OpenMP threads of the evaluation rollouts (0 = all; speed is measured at 1 and 2)");
                    sub.add_option("--out", o->out, "output folder for eval.json, eval.md and plots");
                    sub.add_option("--precision", o->precision,
                                   "linear products of the models: float32, bf16 (inference-only bfloat16; names "
                                   "get '[bf16] '), or float32,bf16 (every model both ways)")
                        ->type_name("float32|bf16|float32,bf16");  // checked by ad::parse_matmul_precision
                    return [o] {
                      if (o->checkpoints.empty() && o->runs.empty() && o->dataset.empty()) {
                        std::fprintf(stderr, "layersnet eval: give --run or --checkpoint (or --dataset for baselines and replays only)\n");
                        return cli::kExitUsage;
                      }
                      return run_eval(*o);  // errors: reported by cli/main.cpp
                    };
                  });
