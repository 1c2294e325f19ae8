// `layersnet export --checkpoint C [--sequence ID] [--frames N] [--format obj|ply] [--out DIR]`:
// one rollout written as predicted and ground-truth meshes per frame (body, each garment) to
// open in Blender or MeshLab, plus strip.png (prediction over ground truth, a few frames).
// Without --checkpoint, --baseline chooses the predictor (constant-velocity | follow-body |
// nearest-body | skinned | physics-step), post-processed like a model with --set eval.constraints=true.
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "cli/model_option.h"
#include "dataset/manifest.h"
#include "dataset/stats.h"
#include "eval/evaluate.h"
#include "eval/export.h"
#include "eval/rollout.h"
#include "run/checkpoint.h"

#include <cstdio>
#include <filesystem>
#include <memory>

namespace {
using namespace layersnet;

struct ExportCliOptions {
  cli::ModelOption model;
  std::string baseline = "follow-body";
  std::string dataset;
  std::string split;
  std::string sequence;
  int frames = -1;
  int start_frame = -1;
  std::string out = "export_out";
  std::vector<std::string> settings;  // "eval.KEY=VALUE" rollout settings of the checkpoint
  eval::ExportOptions exp;
};

int run_export(const ExportCliOptions& o) {
  const std::string checkpoint = o.model.path();  // empty: a baseline
  Config base;
  if (!checkpoint.empty()) base = parse_config_text(read_checkpoint_config(checkpoint), checkpoint);
  const std::string root = o.dataset.empty() ? base.data.dataset : o.dataset;
  const dataset::DatasetManifest manifest = dataset::read_manifest(root);
  const std::string split = o.split.empty() ? base.eval.split : o.split;
  std::string id = o.sequence;
  if (id.empty()) {
    const auto& ids = manifest.split(split);
    if (ids.empty()) throw std::runtime_error(manifest.manifest_path() + ": split '" + split + "' is empty; give --sequence");
    id = ids.front();
  }
  std::unique_ptr<eval::Predictor> predictor;
  if (!checkpoint.empty()) {
    std::unique_ptr<dataset::NormalisationStats> fallback;
    if (std::filesystem::exists(manifest.stats_path()))
      fallback = std::make_unique<dataset::NormalisationStats>(dataset::read_stats(manifest.stats_path()));
    auto model = eval::load_model_predictor(checkpoint, checkpoint, fallback.get());
    model->apply_eval_settings(o.settings);
    predictor = std::move(model);
  } else if (o.baseline == "constant-velocity") {
    predictor = std::make_unique<eval::ConstantVelocity>();
  } else if (o.baseline == "follow-body") {
    predictor = std::make_unique<eval::FollowBody>();
  } else if (o.baseline == "skinned" || o.baseline == "nearest-body") {
    predictor = std::make_unique<eval::SkinnedToBody>(o.baseline == "skinned");
  } else if (o.baseline == "physics-step") {
    predictor = std::make_unique<eval::PhysicsStep>();
  } else {
    throw std::runtime_error("--baseline '" + o.baseline +
                             "' is unknown: use constant-velocity, follow-body, nearest-body, skinned or physics-step");
  }
  Config rolled = base;  // the rollout settings as --set leaves them, as `layersnet eval` rolls out
  for (const auto& a : o.settings) apply_rollout_override(rolled, a);
  // A baseline gets the same post-processing as a model when asked: --set eval.constraints=true.
  if (checkpoint.empty() && rolled.eval.constraints)
    predictor = std::make_unique<eval::PostProcessed>(std::move(predictor), rolled.eval);
  const dataset::Sequence seq = dataset::read_sequence(manifest.sequence_path(id));
  const int frames = o.frames > 0 ? o.frames : base.eval.frames;
  // The same start as `layersnet eval`: after the file's ramp unless a frame is given.
  eval::EvalOptions start;
  start.start_after_ramp = o.start_frame < 2;
  start.start_frame = o.start_frame >= 2 ? o.start_frame : std::max(2, base.data.first_frame);
  const int t0 = eval::rollout_start(manifest.sequence_path(id), start).input_frame;
  const eval::Rollout r = eval::rollout(*predictor, seq, t0, frames, rolled.eval.recorded_pins);
  const int files = eval::export_rollout(o.out, seq, r, o.exp);
  std::printf("export: %s (%s), frames %d..%d predicted by %s: %d %s files", id.c_str(), split.c_str(), r.first_frame,
              r.first_frame + static_cast<int>(r.frames.size()) - 1, predictor->name().c_str(), files,
              o.exp.format.c_str());
  if (o.exp.strip_frames > 0) std::printf(" + strip.png");
  std::printf(" in %s\n", o.out.c_str());
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(export, "Write a rollout's predicted and ground-truth meshes (OBJ/PLY) and a PNG strip",
                  [](CLI::App& sub) {
                    auto o = std::make_shared<ExportCliOptions>();
                    o->model.add_to(sub, "checkpoint to roll out");
                    sub.add_option("--baseline", o->baseline, "without --checkpoint: constant-velocity | follow-body | nearest-body | skinned | physics-step (with --set eval.constraints=true: post-processed like a model)");
                    sub.add_option("--dataset", o->dataset, "data set folder (default: the checkpoint's data.dataset)");
                    sub.add_option("--split", o->split, "split to take the sequence from (default: eval.split)");
                    sub.add_option("--sequence", o->sequence, "sequence id (default: the split's first)");
                    sub.add_option("--frames", o->frames, "predicted frames (default: eval.frames)");
                    sub.add_option("--start-frame", o->start_frame, "input frame t0 (default: as eval, the frame before the first one after the file's ramp; data.first_frame without ramp attributes)");
                    sub.add_option("--format", o->exp.format, "obj | ply");
                    sub.add_option("--strip-frames", o->exp.strip_frames, "panels in strip.png (0 = no strip)");
                    sub.add_option("--out", o->out, "output folder");
                    sub.add_option("--set", o->settings,
                                   "rollout setting of the checkpoint, e.g. --set eval.constraints=false (eval.* keys, model.physics_step_cg_iterations, model.physics_step_pins)");
                    return [o] {
                      if (!o->model.given() && o->dataset.empty()) {
                        std::fprintf(stderr, "layersnet export: give --checkpoint, --run or --dataset\n");
                        return cli::kExitUsage;
                      }
                      return run_export(*o);  // errors: reported by cli/main.cpp
                    };
                  });
