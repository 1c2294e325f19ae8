// `layersnet eval --checkpoint C [--checkpoint C2 ...] [--split test] [--frames N] [--out DIR]`:
// rollouts of every checkpoint, of recorded sequences (--replay) and of the two baselines (constant velocity, follow the body)
// over a split, Euclidean error, collision rates and edge strain (with the ground truth's own
// values as the floor), speed at 1 and 2 threads against Blender's recorded time; writes
// eval.json, eval.md, curve.png, speed.png, strain.png to --out and prints the summary table.
// The run: eval/eval_run.h; see eval/README.md.
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "autodiff/arena.h"
#include "eval/eval_run.h"

#include <Eigen/Core>

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <memory>

namespace {
using namespace layersnet;

struct EvalCli {
  eval::EvalRunOptions options;
  std::string precision = "float32";  // of the models' linear products: float32 | bf16 | float32,bf16
  int threads = 0;
};

int run_eval(EvalCli c) {
  ad::keep_freed_memory_in_process();
  // Every model once per listed precision (a list shows the bf16 speed/accuracy trade in one table).
  c.options.precisions.clear();
  for (std::size_t a = 0, b; a <= c.precision.size(); a = b + 1) {
    b = std::min(c.precision.find(',', a), c.precision.size());
    try {
      c.options.precisions.push_back(ad::parse_matmul_precision(c.precision.substr(a, b - a)));
    } catch (const std::exception& e) {
      throw cli::UsageError(std::string("--precision: ") + e.what());
    }
  }
  c.options.precision_label = c.precision;
  if (c.threads > 0) omp_set_num_threads(c.threads);  // the evaluation rollouts (speed sets its own)
  Eigen::setNbThreads(1);  // the ops own the threads (as bench model); nested GEMM threads only contend
  eval::run_evaluation(c.options);
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(eval, "Roll out checkpoints and baselines over a split; error, collisions, speed, reports",
                  [](CLI::App& sub) {
                    auto args = std::make_shared<EvalCli>();
                    eval::EvalRunOptions* o = &args->options;
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
                    sub.add_option("--frames", o->frames,
                                   "predicted frames per sequence, clamped to what each sequence holds; a large "
                                   "number (e.g. 1000) rolls out every frame after the start (default: eval.frames)");
                    sub.add_option("--mark", o->mark_frames,
                                   "long rollouts are also summarised over their first N frames (error) and at frame "
                                   "N (crumple)")
                        ->check(CLI::PositiveNumber);
                    sub.add_option("--start", o->start,
                                   "where rollouts start: ramp = per sequence, the first predicted frame is the "
                                   "file's rest_frames + ramp_frames (files without them: as fixed); fixed = input "
                                   "frame t0 = --start-frame (default: ramp, or fixed when --start-frame is given)")
                        ->check(CLI::IsMember({"ramp", "fixed"}));
                    sub.add_option("--start-frame", o->start_frame,
                                   "input frame t0 of a fixed start, and of --start ramp for files without the ramp "
                                   "attributes (default: data.first_frame)");
                    sub.add_option("--max-sequences", o->max_sequences, "evaluate only the first N sequences (0 = all)");
                    sub.add_option("--sequences", o->sequences,
                                   "evaluate only these sequences of the split: ids, or ranges FIRST..LAST of ids in "
                                   "string order, comma-separated (e.g. 00048..00083); before --max-sequences")
                        ->delimiter(',');
                    sub.add_option("--wind-scale", o->wind_scale,
                                   "factor on the data's wind strengths as the models see them; the ground truth "
                                   "is unchanged (0: how much a model's error owes to its response to the wind)")
                        ->check(layersnet::cli::kFiniteNonNegative);
                    sub.add_flag("--rig-pins", o->rig_pins,
                                 "the methods see the pinned vertices rigged from the body (moved from the rollout's "
                                 "input frame with the body inside their loop), as simulate rigs a scene, instead of "
                                 "the data's; the ground truth and the error stay the data's");
                    sub.add_flag("--mirror", o->mirror,
                                 "evaluate the mirror images of the sequences (x -> -x) instead: the simulator and the "
                                 "model-free baselines are symmetric under it, so a model that learned the cloth rather "
                                 "than its data's handedness is as close on both");
                    sub.add_option("--wind-twins", o->wind_twins,
                                   "folder of Blender's re-simulations of the evaluated sequences with the wind x "
                                   "--wind-scale (scripts/predictability.sh calm-wind twins): each model's error rise "
                                   "and movement are then set against Blender's")
                        ->type_name("DIR");
                    sub.add_option("--speed-frames", o->speed_frames, "frames of the 1- and 2-thread speed rollouts")
                        ->check(CLI::Range(1, 1000000));
                    sub.add_option("--tether", o->tethers,
                                   "patch tether factors, e.g. 0,3: every model once per factor (default: each checkpoint's eval.patch_tether)")
                        ->delimiter(',')
                        ->check(layersnet::cli::kFiniteNonNegative);
                    sub.add_option("--constraints", o->constraints,
                                   "cloth constraints after every predicted frame (edge strain limit, collision shell; "
                                   "run/cloth_constraints.h): on, off, or off,on for every model both ways (default: each "
                                   "checkpoint's eval.constraints)")
                        ->delimiter(',')
                        ->check(CLI::IsMember({"on", "off"}));
                    sub.add_option("--set", o->settings,
                                   "rollout setting for every model, e.g. --set eval.strain_limit=0.2 (eval.* keys, model.physics_step_cg_iterations and model.physics_step_pins; "
                                   "`layersnet config --keys` lists them)");
                    sub.add_option("--threads", args->threads, "OpenMP threads of the evaluation rollouts (0 = all; speed is measured at 1 and 2)");
                    sub.add_option("--out", o->out, "output folder for eval.json, eval.md and plots");
                    sub.add_option("--precision", args->precision,
                                   "linear products of the models: float32, bf16 (inference-only bfloat16; names "
                                   "get '[bf16] '), or float32,bf16 (every model both ways)")
                        ->type_name("float32|bf16|float32,bf16");  // checked by ad::parse_matmul_precision
                    return [args] {
                      const eval::EvalRunOptions& o = args->options;
                      if (o.checkpoints.empty() && o.runs.empty() && o.dataset.empty()) {
                        std::fprintf(stderr, "layersnet eval: give --run or --checkpoint (or --dataset for baselines and replays only)\n");
                        return cli::kExitUsage;
                      }
                      return run_eval(*args);  // errors: reported by cli/main.cpp
                    };
                  });
