// The `layersnet stress` run and report (see stress_report.h).
#include "eval/stress_report.h"

#include "dataset/file_io.h"
#include "dataset/manifest.h"
#include "dataset/sha256.h"
#include "dataset/stats.h"
#include "eval/report.h"
#include "eval/stress.h"
#include "eval/tether.h"
#include "run/checkpoint.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

namespace layersnet::eval {

nlohmann::json stress_result_json(const StressResult& r) {
  return {{"label", r.label},
          {"frames", r.frames},
          {"speed", r.scene.speed},
          {"wind_strength", r.scene.wind_strength},
          {"finite", r.finite},
          {"first_bad_frame", r.first_bad_frame},
          {"max_distance_over_bound", r.max_bound_ratio},
          {"max_distance_over_graph_diameter", r.max_diameter_ratio},
          {"max_strain_p99", r.max_strain_p99},
          {"max_strain", r.max_strain},
          {"strain_limit", r.strain_limit},
          {"first_torn_frame", r.first_torn_frame},
          {"within_bound", r.within_bound()},
          {"within_strain", r.within_strain()},
          {"bounds_units", r.bounds},
          {"max_vertex_speed_units_per_frame", r.max_vertex_speed},
          {"max_body_speed_units_per_frame", r.max_body_speed},
          {"ms_per_frame", r.ms_per_frame},
          {"passed", r.passed()},
          {"per_frame", {{"distance_over_bound", r.bound_ratio_per_frame},
                         {"max_vertex_speed_units_per_frame", r.vertex_speed_per_frame},
                         {"nearest_vertex_to_body_units", r.nearest_per_frame},
                         {"max_edge_stretch", r.edge_stretch_per_frame},
                         {"strain_p99", r.strain_p99_per_frame},
                         {"strain_max", r.strain_max_per_frame}}}};
}

// Why a run failed, for the table and the progress line.
std::string stress_verdict(const StressResult& r) {
  if (r.passed()) return "ok";
  if (!r.finite) return "FAIL: non-finite";
  std::string why;
  if (!r.within_bound()) why = "distance";
  if (!r.within_strain()) why += why.empty() ? "strain" : ", strain";
  return why.empty() ? "FAIL" : "FAIL: " + why;
}

bool run_stress(const StressOptions& o) {
  // The data set (for statistics a checkpoint lacks) comes from the checkpoint's config.
  const std::string root =
      o.dataset.empty() ? parse_config_text(read_checkpoint_config(o.checkpoint), o.checkpoint).data.dataset : o.dataset;
  const dataset::DatasetManifest manifest = dataset::read_manifest(root);
  std::unique_ptr<dataset::NormalisationStats> fallback;
  if (std::filesystem::exists(manifest.stats_path()))
    fallback = std::make_unique<dataset::NormalisationStats>(dataset::read_stats(manifest.stats_path()));
  const std::unique_ptr<ModelPredictor> model = load_model_predictor(o.checkpoint, "model", fallback.get());
  model->apply_eval_settings(o.settings);
  if (o.tether >= 0) model->set_patch_tether(o.tether);
  const Config& config = model->config();
  std::string id = o.sequence;
  if (id.empty()) {
    for (const auto* split : {&manifest.test, &manifest.val, &manifest.train})
      if (!split->empty()) {
        id = split->front();
        break;
      }
    if (id.empty()) throw std::runtime_error(root + ": the data set lists no sequences; give --sequence ID");
  }
  const dataset::Sequence source = dataset::read_sequence(manifest.sequence_path(id));
  const int first = o.first_frame >= 0 ? o.first_frame : settled_frame(manifest.sequence_path(id));
  std::printf("stress: %s on %s sequence %s (%d frames, %lld garment vertices), rollouts of %d frames looping source "
              "frames %d..%d, %d thread(s)\n",
              o.checkpoint.c_str(), root.c_str(), id.c_str(), source.info.num_frames,
              static_cast<long long>(source.info.total_garment_vertices()), o.frames, first, source.info.num_frames - 1,
              omp_get_max_threads());

  const auto structure = dataset::build_structure(source.info, static_cast<float>(config.model.patch_size));
  const double data_tether = data_tether_ratio(source, *structure, first);
  if (config.eval.patch_tether > 0)
    std::printf("patch tether on: every vertex within %.2f rest patch radii of its patch mates' centre (eval/tether.h); "
                "the data's own max over frames %d..%d: %.3f\n",
                config.eval.patch_tether, first, source.info.num_frames - 1, data_tether);
  else
    std::printf("patch tether off (eval.patch_tether = 0); the data's own max offset / rest patch radius: %.3f\n", data_tether);
  if (config.eval.constraints) {
    int pinned = 0;
    for (const dataset::GarmentMesh& g : source.info.garments) pinned += g.num_pinned();
    char strain[64] = "no edge limit";
    if (config.eval.strain_limit > 0) std::snprintf(strain, sizeof strain, "edge strain <= %g", config.eval.strain_limit);
    std::printf("cloth constraints on: %s, collision shell %g units, %d passes per frame, body friction %g "
                "within %g units, %d pinned vertices %s (run/cloth_constraints.h)\n",
                strain, config.eval.collision_shell, config.eval.constraint_iterations,
                config.eval.body_friction, config.eval.friction_distance, pinned,
                !config.eval.pins ? "left free (eval.pins = false)"
                : config.eval.recorded_pins ? "taken from the data (eval.recorded_pins)" : "carried with the body");
  } else
    std::printf("cloth constraints off (eval.constraints = false)\n");
  // The strain limit comes from the whole data set's ground truth, not the one source: any
  // sequence's real cloth may stretch that much.
  const StrainExtremes data_strain = data_set_strain(manifest);
  const double strain_limit = kStrainAllowance * data_strain.p99;
  std::printf("strain limit: per-frame p99 of |edge length / rest length - 1| <= %.3f (%.1f x the data's own worst "
              "p99 %.3f over its %zu sequences after the ramp; the data's own max %.3f; eval/stress.h)\n",
              strain_limit, kStrainAllowance, data_strain.p99, manifest.all_ids().size(), data_strain.max);
  std::vector<StressResult> results;
  const auto run_one = [&](const StressScene& s, const std::string& label) {
    const auto start = std::chrono::steady_clock::now();
    results.push_back(stress_rollout(*model, source, s, label, strain_limit));
    std::printf("  %s: %d frames in %.0f s (%s)\n", label.c_str(), results.back().frames,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
                stress_verdict(results.back()).c_str());
    std::fflush(stdout);
  };
  for (double w : o.no_winds ? std::vector<double>{} : o.winds) {
    StressScene s;
    s.frames = o.frames;
    s.wind_strength = w;
    s.first = first;
    char label[64];
    std::snprintf(label, sizeof label, "wind %g", w);
    run_one(s, label);
  }
  if (o.speed > 0) {
    StressScene s;
    s.frames = o.frames;
    s.speed = o.speed_factor ? o.speed : speed_factor_for_top_speed(source, first, o.speed, o.frames);
    s.first = first;
    char label[64];
    if (o.speed_factor)
      std::snprintf(label, sizeof label, "speed %gx", o.speed);
    else
      std::snprintf(label, sizeof label, "top speed %gx (s=%.2f)", o.speed, s.speed);
    run_one(s, label);
    std::printf("  body top speed %.1f mm/frame = %.2fx the data's %.1f (time factor s = %.2f)\n",
                results.back().max_body_speed * 1000.0 / source.info.scale,
                results.back().max_body_speed / body_top_speed(source, first, 1.0, o.frames),
                body_top_speed(source, first, 1.0, o.frames) * 1000.0 / source.info.scale, s.speed);
  }
  const double mm = 1000.0 / source.info.scale;
  // gap: the garment's nearest vertex to the body (grows when cloth comes off); stretch: edge
  // length / rest length (grows when cloth tears apart) — which of the two broke a failed run.
  std::printf("\n| run | frames | finite | first bad | max dist / bound | max dist / D | max gap mm | max stretch "
              "| max strain p99 (limit %.3f) | max speed mm/f (body) | ms/frame | |\n",
              strain_limit);
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  bool ok = true;
  const auto largest = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); };
  for (const auto& r : results) {
    std::printf("| %s | %d | %s | %d | %.3f | %.3f | %.0f | %.2f | %.3f | %.1f (%.1f) | %.1f | %s |\n", r.label.c_str(),
                r.frames, r.finite ? "yes" : "NO", r.first_bad_frame, r.max_bound_ratio, r.max_diameter_ratio,
                largest(r.nearest_per_frame) * mm, largest(r.edge_stretch_per_frame), r.max_strain_p99,
                r.max_vertex_speed * mm, r.max_body_speed * mm, r.ms_per_frame, stress_verdict(r).c_str());
    ok = ok && r.passed();
  }
  std::printf("bound per garment (units):");
  for (double b : results.empty() ? std::vector<double>{} : results[0].bounds) std::printf(" %.3f", b);
  const double data_ratio = data_bound_ratio(source, first);
  std::printf("  (c_g + %.1f x rest graph diameter; eval/stress.h); the data's own max dist / bound over frames %d..%d: %.3f\n",
              kStretchAllowance, first, source.info.num_frames - 1, data_ratio);

  nlohmann::json j = {{"checkpoint", o.checkpoint}, {"checkpoint_sha256", io::sha256_file(o.checkpoint)},
            {"dataset", root}, {"dataset_manifest_sha256", io::sha256_file(manifest.manifest_path())}, {"sequence", id},
            {"runs", nlohmann::json::array()},     {"data_bound_ratio", data_ratio},
            {"patch_tether", config.eval.patch_tether}, {"data_tether_ratio", data_tether},
            {"constraints", config.eval.constraints},
            {"strain_limit", strain_limit}, {"strain_allowance", kStrainAllowance},
            {"data_strain_p99", data_strain.p99}, {"data_strain_max", data_strain.max}};
  for (const auto& r : results) j["runs"].push_back(stress_result_json(r));
  if (o.precision_frames > 0) {
    const PrecisionResult p = compare_precision(config, model->params(), model->stats(), source, o.precision_frames, first);
    std::printf("\nfloat32 vs float64 over %d frames: max divergence %.3g mm (per-vertex max), worst frame mean %.3g mm, "
                "frame 1 mean %.3g mm, last frame mean %.3g mm; bound (model error on %s) %.3g mm; %s; ms/frame %.1f vs %.1f\n",
                p.frames, p.worst_max() * p.mm_per_unit, p.worst_mean() * p.mm_per_unit,
                p.mean_divergence.empty() ? 0.0 : p.mean_divergence.front() * p.mm_per_unit,
                p.mean_divergence.empty() ? 0.0 : p.mean_divergence.back() * p.mm_per_unit, id.c_str(),
                p.model_error * p.mm_per_unit, p.passed() ? "ok" : "FAIL", p.ms_float, p.ms_double);
    ok = ok && p.passed();
    j["precision"] = {{"frames", p.frames},
                      {"max_divergence_units", p.max_divergence},
                      {"mean_divergence_units", p.mean_divergence},
                      {"worst_mean_mm", p.worst_mean() * p.mm_per_unit},
                      {"worst_max_mm", p.worst_max() * p.mm_per_unit},
                      {"bound_model_error_mm", p.model_error * p.mm_per_unit},
                      {"ms_per_frame_float", p.ms_float},
                      {"ms_per_frame_double", p.ms_double},
                      {"finite", p.finite},
                      {"passed", p.passed()}};
  }
  j["first_frame"] = first;
  j["passed"] = ok;
  if (!o.json_path.empty()) {
    io::write_file_atomic(o.json_path, report_text(std::move(j)) + "\n");
    std::printf("wrote %s\n", o.json_path.c_str());
  }
  std::printf("stress: %s (distance bound, strain p99 <= %.3f)\n",
              ok ? "every run within its bounds" : "FAILED: a run broke a bound (see the table)", strain_limit);
  return ok;
}


}  // namespace layersnet::eval
