// `layersnet stress --checkpoint C [--dataset D] [--sequence ID] [--frames 600] [--winds 0,400,2000]
// [--speed 5] [--precision-frames 100] [--json F]`: long rollouts of one checkpoint at constant
// wind strengths and with the body sped up, and float32 against float64 over the same checkpoint
// (eval/stress_report.h). Exits 4 when any run breaks its distance bound or strain limit.
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "cli/model_option.h"
#include "autodiff/arena.h"
#include "eval/stress_report.h"

#include <Eigen/Core>

#include <omp.h>

#include <memory>

namespace {

struct StressCli {
  layersnet::eval::StressOptions options;
  layersnet::cli::ModelOption model;
  int threads = 0;
};

int run_stress(StressCli& c) {
  layersnet::ad::keep_freed_memory_in_process();
  c.options.checkpoint = c.model.required_path();
  if (c.threads > 0) omp_set_num_threads(c.threads);
  Eigen::setNbThreads(1);  // the ops own the threads (as bench model); nested GEMM threads only contend
  return layersnet::eval::run_stress(c.options) ? layersnet::cli::kExitOk : layersnet::cli::kExitCheckFailed;
}

}  // namespace

LAYERSNET_COMMAND(stress, "Long rollouts at extreme wind and body speed, and float32 vs float64, with bounds",
                  [](CLI::App& sub) {
                    auto args = std::make_shared<StressCli>();
                    layersnet::eval::StressOptions* o = &args->options;
                    args->model.add_to(sub, "checkpoint to test");
                    sub.add_option("--dataset", o->dataset, "data set folder (default: the checkpoint's data.dataset)");
                    sub.add_option("--sequence", o->sequence, "sequence id (default: the first test sequence)");
                    sub.add_option("--first-frame", o->first_frame,
                                   "first source frame of the loop (default: after the generator's rest and ramp, "
                                   "the file's rest_frames + ramp_frames; 0 without them)");
                    sub.add_option("--frames", o->frames, "frames of each stress sequence (rollout: frames - 3)")
                        ->check(CLI::Range(4, 1000000));
                    sub.add_option("--winds", o->winds, "constant wind strengths, one run each")
                        ->delimiter(',')
                        ->check(layersnet::cli::kFiniteNonNegative);
                    sub.add_flag("--no-winds", o->no_winds, "skip the wind runs (only the speed run)");
                    sub.add_option("--speed", o->speed,
                                   "extra run with the body's top speed this multiple of the data's (0 = none)")
                        ->check(layersnet::cli::kFiniteNonNegative);
                    sub.add_flag("--speed-factor", o->speed_factor,
                                 "--speed is the time factor s (every body velocity x s) instead");
                    sub.add_option("--precision-frames", o->precision_frames, "frames of the float32/float64 comparison (0 = skip)");
                    sub.add_option("--threads", args->threads, "OpenMP threads (0 = all)");
                    sub.add_option("--tether", o->tether,
                                   "patch tether factor for these rollouts (0 = off; default: the checkpoint's eval.patch_tether)")
                        ->check(layersnet::cli::kFiniteNonNegative);
                    sub.add_option("--set", o->settings,
                                   "rollout setting, e.g. --set eval.constraints=false (eval.* keys, model.physics_step_cg_iterations and model.physics_step_pins; default: the checkpoint's)");
                    sub.add_option("--json", o->json_path, "write the results as JSON to this file");
                    return [args] { return run_stress(*args); };
                  });
