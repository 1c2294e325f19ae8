// The whole `layersnet eval` (see eval_run.h).
#include "eval/eval_run.h"

#include "autodiff/bf16_gemm.h"
#include "autodiff/gemm_f32.h"
#include "dataset/manifest.h"
#include "dataset/sha256.h"
#include "dataset/stats.h"
#include "eval/evaluate.h"
#include "eval/machine.h"
#include "eval/report.h"
#include "run/checkpoint.h"
#include "run/run_dir.h"

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>

namespace layersnet::eval {

namespace {

// "<folder>/<stem> (<attention>[+RET])": distinguishes ablation runs in one table.
std::string default_name(const std::string& path, const Config& c) {
  const std::filesystem::path p(path);
  std::string folder = p.parent_path().filename().string();
  std::string name = (folder.empty() ? "" : folder + "/") + p.stem().string();
  return name + " (" + c.model.attention + (c.model.rotation_equivalent ? "+RET" : ", vanilla") + ")";
}

}  // namespace

void run_evaluation(EvalRunOptions o) {
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

  EvalOptions eo;
  eo.split = o.split.empty() ? base.eval.split : o.split;
  eo.frames = o.frames > 0 ? o.frames : base.eval.frames;
  eo.mark_frames = o.mark_frames;
  eo.start_frame = o.start_frame >= 2 ? o.start_frame : std::max(2, base.data.first_frame);
  eo.start_after_ramp = o.start.empty() ? o.start_frame < 0 : o.start == "ramp";
  eo.max_sequences = o.max_sequences;
  eo.sequences = o.sequences;
  eo.wind_scale = o.wind_scale;
  eo.wind_twins = o.wind_twins;
  eo.mirror = o.mirror;
  eo.rig_pins = o.rig_pins;

  const bool any_bf16 = std::count(o.precisions.begin(), o.precisions.end(), ad::MatmulPrecision::kBFloat16) > 0;
  std::vector<std::unique_ptr<Predictor>> owned;
  std::vector<std::string> kinds, paths;
  std::vector<bool> model_post;  // the post-processing settings the models run with
  // The step baseline is the first physics-base model's own step, so that a model is measured
  // against its zero output, not against a step with other settings.
  std::string step_from;
  ModelConfig step_settings;
  for (size_t i = 0; i < o.checkpoints.size(); ++i) {
    const Config c = parse_config_text(read_checkpoint_config(o.checkpoints[i]), o.checkpoints[i]);
    Config rolled = c;  // its rollouts (and its step) as --set leaves them
    for (const auto& a : o.settings) apply_rollout_override(rolled, a);
    if (step_from.empty() && c.model.velocity_base == "physics") {
      step_from = o.checkpoints[i];
      step_settings = rolled.model;
    }
    if (rolled.model.velocity_base == "physics" && rolled.model.physics_step_pins == "recorded" && !rolled.eval.recorded_pins)
      std::fprintf(stderr, "eval: warning: %s's step takes the recorded pins but its rollouts do not "
                           "(eval.recorded_pins = false); set it so that every method gets them\n", o.checkpoints[i].c_str());
    const std::string name = i < o.names.size() ? o.names[i] : default_name(o.checkpoints[i], c);
    const std::vector<double> tethers = o.tethers.empty() ? std::vector<double>{c.eval.patch_tether} : o.tethers;
    std::vector<bool> constrained;
    for (const auto& setting : o.constraints) constrained.push_back(setting == "on");
    if (constrained.empty()) constrained.push_back(c.eval.constraints);
    model_post.insert(model_post.end(), constrained.begin(), constrained.end());
    for (const bool constrain : constrained)
      for (const double tether : tethers)
        for (const ad::MatmulPrecision precision : o.precisions) {
          std::string prefix;  // in front: tables cut long names
          if (o.constraints.size() > 1 && constrain) prefix += "[constrained] ";
          if (o.tethers.size() > 1) {
            char tag[48];
            std::snprintf(tag, sizeof tag, "[t%g] ", tether);
            prefix += tag;
          }
          auto model = load_model_predictor(o.checkpoints[i], prefix + name, fallback.get());
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
    owned.push_back(std::make_unique<Replay>(name, o.replays[r]));
    kinds.push_back("replay");
    paths.push_back(o.replays[r]);
  }
  // Baselines once per post-processing setting the models run with, under the first model's
  // rollout settings (and --set): a model with the constraints, friction and pins is compared
  // with baselines that get the same.
  Config post = base;
  for (const auto& a : o.settings) apply_rollout_override(post, a);
  eo.recorded_pins = post.eval.recorded_pins;  // every method alike, as the first model rolls out
  std::vector<bool> baseline_post = model_post;
  if (baseline_post.empty())  // no model: --constraints alone says how the baselines run
    for (const auto& setting : o.constraints) baseline_post.push_back(setting == "on");
  if (baseline_post.empty()) baseline_post.push_back(false);
  std::sort(baseline_post.begin(), baseline_post.end());
  baseline_post.erase(std::unique(baseline_post.begin(), baseline_post.end()), baseline_post.end());
  const size_t baseline_first = owned.size();
  for (const bool on : baseline_post) {
    std::vector<std::unique_ptr<Predictor>> plain;
    plain.push_back(std::make_unique<ConstantVelocity>());
    plain.push_back(std::make_unique<FollowBody>());
    plain.push_back(std::make_unique<SkinnedToBody>(false));
    plain.push_back(std::make_unique<SkinnedToBody>(true));
    plain.push_back(std::make_unique<PhysicsStep>(step_settings));
    for (auto& b : plain) {
      owned.push_back(on ? std::make_unique<PostProcessed>(std::move(b), post.eval) : std::move(b));
      kinds.push_back("baseline");
      paths.push_back("");
    }
  }
  const size_t baseline_count = owned.size() - baseline_first;
  owned.push_back(std::make_unique<GroundTruth>());
  kinds.push_back("ground truth");
  paths.push_back("");
  std::vector<Predictor*> predictors;
  for (auto& p : owned) predictors.push_back(p.get());
  if (eo.rig_pins)
    std::printf("eval: every method's pinned vertices are rigged from the body (--rig-pins)%s; the ground truth's are the data's\n",
                eo.recorded_pins ? " at every frame (eval.recorded_pins)" : ", for the step and the constraints to take or not");
  else if (eo.recorded_pins)
    std::printf("eval: every method's pinned vertices are the data's at every frame (eval.recorded_pins)\n");
  std::printf("eval: baseline 'one physics step' is %s\n",
              step_from.empty() ? "the step with its default settings" : ("the step of " + step_from).c_str());

  std::printf("eval: %s split '%s', %zu model(s), %zu replay(s) + %zu baselines, up to %d frames from %s, %d thread(s), "
              "products %s%s%s, float32 GEMM kernel %s\n",
              root.c_str(), eo.split.c_str(), model_count, o.replays.size(), baseline_count, eo.frames,
              start_description(eo).c_str(),
              omp_get_max_threads(), o.precision_label.c_str(), any_bf16 ? ", bf16 kernel " : "", any_bf16 ? ad::bf16_kernel_name() : "",
              ad::f32_gemm_kernel_name(ad::f32_gemm_kernel()));
  std::vector<MethodResult> results = evaluate(manifest, predictors, eo, true);
  for (size_t p = 0; p < results.size(); ++p) {
    results[p].kind = kinds[p];
    results[p].checkpoint = paths[p];
    if (kinds[p] == "model") results[p].checkpoint_sha256 = io::sha256_file(paths[p]);
    if (const auto* net = dynamic_cast<const ModelPredictor*>(predictors[p])) results[p].post_processed = net->config().eval.constraints;
    if (dynamic_cast<const PostProcessed*>(predictors[p])) results[p].post_processed = true;
  }

  ReportContext ctx;
  ctx.dataset = root;
  ctx.manifest_sha256 = io::sha256_file(manifest.manifest_path());
  ctx.post_processing = post.eval;
  ctx.options = eo;
  ctx.physics_step_from = step_from;
  // Speed on the first sequence of the split, 1 and 2 threads.
  const std::string speed_id = results[0].sequences[0].id;
  const dataset::Sequence speed_seq = dataset::read_sequence(manifest.sequence_path(speed_id));
  const int speed_t0 = results[0].sequences[0].first_frame - 1;  // the evaluation's own start
  ctx.speed_sequence = speed_id;
  ctx.speed_frames = std::min(o.speed_frames, speed_seq.info.num_frames - 1 - speed_t0);
  for (size_t p = 0; p + 1 < predictors.size(); ++p) {
    if (kinds[p] == "replay") continue;  // a recording has no speed of its own
    results[p].ms_per_frame_1thread = median_ms_per_frame(*predictors[p], speed_seq, speed_t0, ctx.speed_frames, 1);
    results[p].ms_per_frame_2threads = median_ms_per_frame(*predictors[p], speed_seq, speed_t0, ctx.speed_frames, 2);
  }
  double blender_sum = 0;
  int blender_n = 0;
  for (const auto& s : results[0].sequences) {
    const double b = blender_seconds_per_frame(manifest.sequence_path(s.id));
    if (b > 0) {
      blender_sum += b;
      ++blender_n;
    }
  }
  ctx.blender_s_per_frame = blender_n ? blender_sum / blender_n : -1;
  ctx.load_average = load_average_1min();  // context for the speed figures on a shared machine

  const auto written = write_report(o.out, results, ctx);
  std::printf("\n%s", summary_table(results, ctx).c_str());
  std::printf("wrote");
  for (const auto& w : written) std::printf(" %s", w.c_str());
  std::printf("\n");
}


}  // namespace layersnet::eval
