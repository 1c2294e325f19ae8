// Evaluation reports (see report.h).
#include "eval/report.h"

#include "dataset/file_io.h"
#include "eval/machine.h"

#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string_view>

namespace layersnet::eval {
namespace {

using nlohmann::json;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}
std::string pm(const MeanStd& m, const char* f = "%.1f") {
  if (m.count == 0) return "–";
  return fmt(f, m.mean) + " ± " + fmt(f, m.std);
}
json ms_json(const MeanStd& m) { return {{"mean", m.mean}, {"std", m.std}, {"sequences", m.count}}; }

// Blender seconds per frame / model seconds per frame: how many times faster the rollout is.
double speedup(double blender_s, double ms) { return blender_s > 0 && ms > 0 ? blender_s * 1000.0 / ms : -1; }


// gnuplot exits 0 even when its PNG could not be written in full (a full disk): a plot counts
// only when the file ends with PNG's IEND chunk.
bool complete_png(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary | std::ios::ate);
  if (!in) return false;
  const std::streamoff size = in.tellg();
  if (size < 20) return false;
  char tail[8];
  in.seekg(size - 8);
  in.read(tail, 8);
  return in && std::string_view(tail, 4) == "IEND";
}

// A per-rollout-frame curve of the summaries (curve_mm, strain_p99_curve_percent).
using SummaryCurve = std::vector<double> Summary::*;

std::string curve_data(const std::vector<MethodResult>& methods, SummaryCurve curve) {
  // Columns: frame, then one per method; blank for methods whose rollout is shorter.
  std::vector<std::vector<double>> sums;
  size_t n = 0;
  for (const auto& m : methods) {
    sums.push_back(summarise(m).*curve);
    n = std::max(n, sums.back().size());
  }
  std::ostringstream o;
  o << "frame";  // header row (gnuplot columnhead), not a comment
  for (const auto& m : methods) o << "\t\"" << m.name << "\"";
  o << "\n";
  for (size_t k = 0; k < n; ++k) {
    o << k + 1;
    for (const auto& s : sums) o << "\t" << (k < s.size() ? fmt("%.6g", s[k]) : "NaN");
    o << "\n";
  }
  return o.str();
}

// Plots into `out` (curve.png, strain.png, crumple.png, speed.png). The data and the script go to a
// scratch folder that is removed afterwards, so a report folder holds reports only; gnuplot's log
// is kept in `out` when it failed.
bool plot(const std::filesystem::path& out, const std::vector<MethodResult>& methods) {
  if (!gnuplot_available()) return false;
  static int serial = 0;
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("layersnet-plot-" + std::to_string(::getpid()) + "-" + std::to_string(serial++));
  std::filesystem::create_directories(dir);
  struct Remove {
    std::filesystem::path p;
    ~Remove() {
      std::error_code ec;
      std::filesystem::remove_all(p, ec);
    }
  } scratch{dir};
  io::write_file_atomic(dir / "curve.dat", curve_data(methods, &Summary::curve_mm));
  io::write_file_atomic(dir / "strain.dat", curve_data(methods, &Summary::strain_p99_curve_percent));
  io::write_file_atomic(dir / "crumple.dat", curve_data(methods, &Summary::dihedral_curve_deg));
  std::ostringstream gp;
  gp << "set terminal png size 900,520\nset output '" << (out / "curve.png").string() << "'\n"
     << "set title 'Euclidean error over the rollout'\nset xlabel 'predicted frame'\nset ylabel 'error (mm)'\n"
     << "set key left top\nset grid\nset datafile missing 'NaN'\nplot ";
  bool first = true;
  for (size_t m = 0; m < methods.size(); ++m) {
    if (methods[m].kind == "ground truth") continue;
    gp << (first ? "" : ", ") << "'" << (dir / "curve.dat").string() << "' using 1:" << m + 2
       << " with linespoints title columnhead(" << m + 2 << ")";
    first = false;
  }
  gp << "\n";
  // Strain: every method, the ground truth too (its strain is the simulator's own).
  gp << "set output '" << (out / "strain.png").string() << "'\nset title 'Edge strain over the rollout (mean over "
     << "sequences)'\nset ylabel 'p99 of |edge length / rest length - 1| (%)'\nplot ";
  for (size_t m = 0; m < methods.size(); ++m)
    gp << (m ? ", " : "") << "'" << (dir / "strain.dat").string() << "' using 1:" << m + 2
       << " with linespoints title columnhead(" << m + 2 << ") noenhanced";  // names hold '_'
  gp << "\n";
  gp << "set output '" << (out / "crumple.png").string() << "'\nset title 'Crumple over the rollout (mean over "
     << "sequences)'\nset ylabel 'mean dihedral angle (degrees)'\nplot ";
  for (size_t m = 0; m < methods.size(); ++m)
    gp << (m ? ", " : "") << "'" << (dir / "crumple.dat").string() << "' using 1:" << m + 2
       << " with lines title columnhead(" << m + 2 << ") noenhanced";
  gp << "\n";
  // Error vs speed: one point per method that has a measured speed.
  std::ostringstream sp;
  for (const auto& m : methods) {
    if (m.kind == "ground truth" || m.ms_per_frame_1thread <= 0) continue;
    sp << fmt("%.6g", m.ms_per_frame_1thread) << "\t" << fmt("%.6g", summarise(m).error_mm.mean) << "\t\"" << m.name
       << "\"\n";
  }
  io::write_file_atomic(dir / "speed.dat", sp.str());
  gp << "set output '" << (out / "speed.png").string() << "'\nset title 'Error against speed (1 thread)'\n"
     << "set xlabel 'ms per frame (median, log scale)'\nset ylabel 'error (mm)'\nset logscale x\nunset key\n"
     << "plot '" << (dir / "speed.dat").string() << "' using 1:2 with points pt 7 ps 1.5, '' using 1:2:3 with labels "
     << "offset 1,1 left\n";
  io::write_file_atomic(dir / "plots.gp", gp.str());
  const bool ok = run_gnuplot(dir / "plots.gp", dir / "gnuplot.log");
  std::error_code ec;
  if (!ok) std::filesystem::copy_file(dir / "gnuplot.log", out / "gnuplot.log",
                                      std::filesystem::copy_options::overwrite_existing, ec);
  return ok;
}

// Band b of kBodyDistanceBandEdgesM in metres: [lower, upper], upper -1 for the open last band.
std::array<double, 2> band_bounds(int b) {
  return {b == 0 ? 0.0 : kBodyDistanceBandEdgesM[b - 1], b < kBodyDistanceBands - 1 ? kBodyDistanceBandEdgesM[b] : -1.0};
}

std::string band_label(int b) {
  const auto [lo, hi] = band_bounds(b);
  return hi < 0 ? fmt(">= %g m", lo) : fmt("%g", lo) + fmt("–%g m", hi);
}

std::vector<std::string> all_types(const std::vector<MethodResult>& methods) {
  std::set<std::string> t;
  for (const auto& m : methods)
    for (const auto& s : m.sequences) t.insert(s.garment_types.begin(), s.garment_types.end());
  return {t.begin(), t.end()};
}

}  // namespace

std::string start_description(const EvalOptions& o) {
  const std::string fixed = "input frame " + std::to_string(o.start_frame);
  // A changed wind is part of what the rollouts were, so every place that says where they start says it too.
  const std::string wind = o.wind_scale == 1.0 ? "" : "; the models saw the data's wind strengths x " + fmt("%g", o.wind_scale);
  const std::string mirror = o.mirror ? "; on the sequences' mirror images (x -> -x)" : "";
  const std::string rigged = o.rig_pins ? "; the methods saw the pins rigged from the body, not the data's" : "";
  return (o.start_after_ramp ? "input frame rest_frames + ramp_frames - 1 of each file, the first predicted frame "
                               "following the generator's ramp (" + fixed + " for files without them)"
                             : fixed) + wind + mirror + rigged;
}

std::string summary_table(const std::vector<MethodResult>& methods, const ReportContext& c) {
  std::ostringstream o;
  char line[512];
  const char* row = "%-44s %16s %9s %9s %7s %7s %7s %8s %9s %8s %8s %8s\n";
  std::snprintf(line, sizeof line, row, "method", "error mm", "near mm", "free mm", "H %", "L %", "L-near%",
                "strain%", "strain99%", "crumple", "ms/f 1t", "ms/f 2t");
  o << line << std::string(150, '-') << "\n";
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    const auto mean = [](const MeanStd& v, const char* f) { return v.count ? fmt(f, v.mean) : std::string("–"); };
    std::snprintf(line, sizeof line, row, m.name.substr(0, 44).c_str(), pm(s.error_mm).c_str(),
                  fmt("%.1f", s.near_body_mm).c_str(), fmt("%.1f", s.free_cloth_mm).c_str(),
                  mean(s.h_percent, "%.2f").c_str(), mean(s.l_outer_percent, "%.2f").c_str(),
                  mean(s.l_near_percent, "%.2f").c_str(), mean(s.strain_mean_percent, "%.1f").c_str(),
                  mean(s.strain_p99_percent, "%.0f").c_str(), mean(s.dihedral_mean_deg, "%.1f°").c_str(),
                  m.ms_per_frame_1thread > 0 ? fmt("%.3g", m.ms_per_frame_1thread).c_str() : "–",
                  m.ms_per_frame_2threads > 0 ? fmt("%.3g", m.ms_per_frame_2threads).c_str() : "–");
    o << line;
    if (s.diverged) o << "    (" << s.diverged << " diverged sequence(s) left out: non-finite prediction)\n";
    if (s.wind_moved_mm.count)
      o << "    the wind x " << fmt("%g", c.options.wind_scale) << " moves its cloth by " << pm(s.wind_moved_mm)
        << " mm from its rollout under the data's wind (" << s.wind_moved_mm.count << " sequences)\n";
    if (s.wind_share.count)
      o << "    against Blender's twins (" << s.wind_share.count << " sequences): Blender's cloth moves by "
        << pm(s.twin_moved_mm) << " mm (" << pm(s.twin_moved_in_window_mm) << " within the window), this error rises by " << pm(s.wind_error_rise_mm) << " mm ("
        << fmt("%.2f", s.wind_error_rise_mm.mean / s.twin_moved_mm.mean) << " of it), share of Blender's movement "
        << pm(s.wind_share, "%.2f") << "\n";
  }
  o << "(" << (methods.empty() ? 0 : methods[0].sequences.size()) << " " << c.options.split << " sequences, up to "
    << c.options.frames << " predicted frames from " << start_description(c.options)
    << "; near / free: ground truth within / beyond " << kBodyDistanceBandEdgesM.back()
    << " m of the body; L = share of outer-layer vertices, L-near = only those within " << c.options.max_layer_distance_m
    << " m of the inner layer; strain = |edge length / rest length - 1| in %, mean and 99th percentile over "
       "edges x frames; crumple = mean dihedral angle between adjacent triangles; [constrained]: the cloth "
       "constraints, contact friction and pins after every frame";
  if (c.blender_s_per_frame > 0) o << "; Blender " << fmt("%.3f", c.blender_s_per_frame) << " s/frame";
  o << ")\n";
  const auto comparisons = compare_with_baselines(methods);
  if (!comparisons.empty()) {
    o << "\nEach model against its best baseline under the same post-processing (error ratio; per sequence: mean, "
         "median, worst):\n";
    for (const Comparison& k : comparisons) {
      if (!k.best_baseline) continue;
      std::snprintf(line, sizeof line, "  %-44s vs %-44s %.2fx  (per sequence %.2f / %.2f / %.2f %s; free cloth %.2fx)\n",
                    k.model.substr(0, 44).c_str(), k.baseline.substr(0, 44).c_str(), k.ratio_of_means, k.mean_ratio,
                    k.median_ratio, k.worst_ratio, k.worst_id.c_str(), k.free_ratio_of_means);
      o << line;
    }
  }
  return o.str();
}

std::string report_json(const std::vector<MethodResult>& methods, const ReportContext& c) {
  json j;
  j["dataset"] = c.dataset;
  j["dataset_manifest_sha256"] = c.manifest_sha256;
  j["mark_frames"] = c.options.mark_frames;
  j["post_processing"] = {{"strain_limit", c.post_processing.strain_limit},
                          {"fold_limit", c.post_processing.fold_limit},
                          {"collision_shell", c.post_processing.collision_shell},
                          {"constraint_iterations", c.post_processing.constraint_iterations},
                          {"body_friction", c.post_processing.body_friction},
                          {"layer_friction", c.post_processing.layer_friction},
                          {"friction_distance", c.post_processing.friction_distance},
                          {"pins", c.post_processing.pins}};
  j["split"] = c.options.split;
  j["sequences_selected"] = c.options.sequences;  // --sequences; empty = the whole split
  j["frames"] = c.options.frames;
  j["start"] = c.options.start_after_ramp ? "ramp" : "fixed";  // per sequence: first_frame, input_frame
  j["start_frame"] = c.options.start_frame;
  j["wind_scale"] = c.options.wind_scale;  // 1 = the data's wind
  j["wind_twins"] = c.options.wind_twins;  // "" = none
  j["mirror"] = c.options.mirror;  // true: the sequences' mirror images were evaluated
  j["recorded_pins"] = c.options.recorded_pins;  // true: every method's pinned vertices were the data's
  j["rig_pins"] = c.options.rig_pins;  // true: ... rigged from the body instead (dataset::rig_pins)
  j["h_collision_max_distance_m"] = c.options.max_body_distance_m;
  j["l_collision_near_max_distance_m"] = c.options.max_layer_distance_m;
  j["blender_s_per_frame"] = c.blender_s_per_frame;
  j["speed"] = {{"sequence", c.speed_sequence}, {"frames", c.speed_frames}, {"load_average_1min", c.load_average}};
  j["physics_step_baseline"] = c.physics_step_from.empty() ? "defaults" : c.physics_step_from;
  j["units"] = "error_*_mm: millimetres (scene units / scale * 1000); error_units: scene units; rates in [0, 1], "
               "*_percent in percent; l_rate_outer = colliding / outer vertices, l_rate_all = colliding / all garment "
               "vertices (official aggregate); strain_*: |edge length / rest length - 1| over every garment edge and rollout "
               "frame, a ratio per sequence (mean, p99 = 99th percentile by linear interpolation; strain_p99_curve: "
               "per frame), *_percent in percent over sequences; start ramp: first_frame = the file's rest_frames + "
               "ramp_frames, fixed: input_frame = start_frame; error_by_body_distance / band_*: bands of the ground truth's "
               "distance to its nearest body vertex (band_m in metres, upper -1 = open), error pooled over the band's "
               "vertex-frames, share of all vertex-frames; near_body_mm / free_cloth_mm: the same pooled within / beyond "
               "the last band edge; dihedral_*_deg: angle between the normals of the two triangles of every interior "
               "edge, degrees (0 = flat), mean and p99 over edges x frames, curve per frame; *_at_mark / to_mark: at / "
               "over the first mark_frames frames; comparisons: model error / baseline error for baselines with the "
               "same post_processed flag, ratio of the means and per sequence; wind_moved_mm (only with wind_scale != 1, "
               "models): mean distance between the rollout with the scaled wind and the same model's under the data's "
               "wind; with wind_twins (Blender's re-simulations under the scaled wind): twin_moved_mm = mean distance "
               "between the data and its twin, twin_moved_in_window_mm = the same with the twin moved by its offset from the "
               "data at the input frame (what the wind moves within the rollout's window), wind_error_rise_mm = error with the scaled wind minus error with the "
               "data's, wind_share = the model's wind movement projected on Blender's within the window, sum m.g / "
               "sum g.g over frames and vertices (1 = all of it, 0 = none, < 0 = against it)";
  j["methods"] = json::array();
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    json jm = {{"name", m.name}, {"kind", m.kind}, {"checkpoint", m.checkpoint},
               {"checkpoint_sha256", m.checkpoint_sha256}, {"post_processed", m.post_processed},
               {"ms_per_frame_1thread", m.ms_per_frame_1thread}, {"ms_per_frame_2threads", m.ms_per_frame_2threads},
               {"speedup_vs_blender_1thread", speedup(c.blender_s_per_frame, m.ms_per_frame_1thread)},
               {"speedup_vs_blender_2threads", speedup(c.blender_s_per_frame, m.ms_per_frame_2threads)},
               {"median_step_ms_during_eval", s.median_step_ms}, {"diverged_sequences", s.diverged}};
    json js = {{"error_mm", ms_json(s.error_mm)}, {"inner_mm", ms_json(s.inner_mm)}, {"outer_mm", ms_json(s.outer_mm)},
               {"h_collision_percent", ms_json(s.h_percent)},
               {"l_collision_outer_percent", ms_json(s.l_outer_percent)},
               {"l_collision_all_percent", ms_json(s.l_all_percent)},
               {"l_collision_near_percent", ms_json(s.l_near_percent)}, {"curve_mm", s.curve_mm},
               {"strain_mean_percent", ms_json(s.strain_mean_percent)},
               {"strain_p99_percent", ms_json(s.strain_p99_percent)},
               {"strain_p99_curve_percent", s.strain_p99_curve_percent},
               {"near_body_mm", s.near_body_mm}, {"free_cloth_mm", s.free_cloth_mm}, {"free_share", s.free_share},
               {"dihedral_mean_deg", ms_json(s.dihedral_mean_deg)}, {"dihedral_p99_deg", ms_json(s.dihedral_p99_deg)},
               {"dihedral_curve_deg", s.dihedral_curve_deg}, {"mark", s.mark},
               {"error_to_mark_mm", ms_json(s.error_to_mark_mm)},
               {"dihedral_at_mark_deg", ms_json(s.dihedral_at_mark_deg)},
               {"dihedral_end_deg", ms_json(s.dihedral_end_deg)}};
    if (s.wind_moved_mm.count > 0) js["wind_moved_mm"] = ms_json(s.wind_moved_mm);
    if (s.wind_share.count > 0) {
      js["twin_moved_mm"] = ms_json(s.twin_moved_mm);
      js["twin_moved_in_window_mm"] = ms_json(s.twin_moved_in_window_mm);
      js["wind_error_rise_mm"] = ms_json(s.wind_error_rise_mm);
      js["wind_share"] = ms_json(s.wind_share);
    }
    js["error_by_body_distance"] = json::array();
    for (int b = 0; b < kBodyDistanceBands; ++b)
      js["error_by_body_distance"].push_back({{"band_m", band_bounds(b)}, {"error_mm", s.band_mm[b]},
                                              {"share", s.band_share[b]}});
    for (const auto& [k, v] : s.by_type_mm) js["by_type_mm"][k] = ms_json(v);
    for (const auto& [k, v] : s.by_subset_mm) js["by_subset_mm"][k] = ms_json(v);
    jm["summary"] = js;
    jm["sequences"] = json::array();
    for (const auto& r : m.sequences) {
      std::vector<double> curve, garments;
      for (double e : r.error_curve) curve.push_back(e * r.mm());
      for (double e : r.garment_error) garments.push_back(e * r.mm());
      std::vector<double> band_mm;
      for (double e : r.band_error) band_mm.push_back(e * r.mm());
      jm["sequences"].push_back({{"id", r.id}, {"subsets", r.subsets}, {"garment_types", r.garment_types},
                                 {"scale", r.scale}, {"first_frame", r.first_frame},
                                 {"input_frame", r.first_frame - 1}, {"start", r.after_ramp ? "ramp" : "fixed"},
                                 {"error_units", r.error},
                                 {"error_mm", r.error * r.mm()}, {"error_curve_mm", curve},
                                 {"garment_error_mm", garments}, {"inner_mm", r.inner_error * r.mm()},
                                 {"band_error_mm", band_mm}, {"band_vertex_frames", r.band_vertex_frames},
                                 {"outer_mm", r.outer_error < 0 ? -1.0 : r.outer_error * r.mm()},
                                 {"h_rate", r.h_rate}, {"l_rate_outer", r.l_rate_outer}, {"l_rate_all", r.l_rate_all},
                                 {"l_rate_outer_near", r.l_rate_outer_near}, {"strain_mean", r.strain_mean},
                                 {"strain_p99", r.strain_p99}, {"strain_p99_curve", r.strain_p99_curve},
                                 {"dihedral_mean_deg", r.dihedral_mean}, {"dihedral_p99_deg", r.dihedral_p99},
                                 {"dihedral_curve_deg", r.dihedral_curve}, {"mark", r.mark},
                                 {"error_to_mark_mm", r.error_to_mark * r.mm()},
                                 {"step_ms", r.step_ms}, {"diverged_at", r.diverged_at}});
      if (r.wind_moved >= 0) jm["sequences"].back()["wind_moved_mm"] = r.wind_moved * r.mm();
      if (std::isfinite(r.wind_share)) {
        jm["sequences"].back()["twin_moved_mm"] = r.twin_moved * r.mm();
        jm["sequences"].back()["twin_moved_in_window_mm"] = r.twin_moved_in_window * r.mm();
        jm["sequences"].back()["wind_error_rise_mm"] = r.wind_error_rise * r.mm();
        jm["sequences"].back()["wind_share"] = r.wind_share;
      }
    }
    j["methods"].push_back(jm);
  }
  j["comparisons"] = json::array();
  for (const Comparison& k : compare_with_baselines(methods)) {
    json per = json::object();
    for (size_t i = 0; i < k.ids.size(); ++i) per[k.ids[i]] = k.ratios[i];
    j["comparisons"].push_back({{"model", k.model}, {"baseline", k.baseline}, {"post_processed", k.post_processed},
                                {"best_baseline", k.best_baseline}, {"ratio_of_means", k.ratio_of_means},
                                {"free_cloth_ratio_of_means", k.free_ratio_of_means},
                                {"per_sequence", per}, {"mean_ratio", k.mean_ratio}, {"median_ratio", k.median_ratio},
                                {"worst_ratio", k.worst_ratio}, {"worst_sequence", k.worst_id},
                                {"skipped_sequences", k.skipped}});
  }
  return report_text(std::move(j));
}

namespace {
void round_numbers(json& j) {
  if (j.is_number_float()) {
    const double x = j.get<double>();
    if (std::isfinite(x)) j = std::stod(fmt("%.7g", x));
  } else if (j.is_structured()) {
    for (auto& element : j) round_numbers(element);
  }
}
}  // namespace

std::string report_text(json report) {
  round_numbers(report);
  return report.dump();
}

std::string report_markdown(const std::vector<MethodResult>& methods, const ReportContext& c) {
  std::ostringstream o;
  const size_t n_seq = methods.empty() ? 0 : methods[0].sequences.size();
  std::string selection;
  for (const std::string& entry : c.options.sequences) selection += (selection.empty() ? "" : ",") + entry;
  o << "# Evaluation: " << c.dataset << ", split `" << c.options.split << "`"
    << (selection.empty() ? "" : ", sequences `" + selection + "`") << "\n\n"
    << n_seq << " sequences; rollouts from the ground truth at " << start_description(c.options)
    << " (each sequence's first predicted frame: `first_frame` in eval.json) for up to "
    << c.options.frames << " predicted frames (body and wind from the data every frame). Errors in mm "
    << "(scene units / `scale` · 1000): mean over a frame's vertices, then over the sequence's frames, then "
    << "mean ± std over sequences. Collision rates in % aggregated the same way; H-collision over all garment "
    << "vertices (distance limit " << c.options.max_body_distance_m << " m), L-collision over outer-layer vertices "
    << "(the official aggregate divides by all garment vertices: column *L ÷ all*; *near*: only outer vertices within "
    << c.options.max_layer_distance_m << " m of their nearest inner vertex). Definitions: eval/README.md.\n\n";
  o << "## Every method\n\n"
       "`[constrained]`: the cloth constraints, contact friction and pins after every predicted frame (settings in "
       "eval.json `post_processing`), for the baselines exactly as for the model. Near / free: error over the "
       "vertex-frames whose ground truth lies within / beyond "
    << kBodyDistanceBandEdgesM.back()
    << " m of the body. "
    << (c.options.rig_pins ? "Pinned vertices: every method but the ground truth sees them rigged from the body "
                             "(moved from the input frame with the body inside their loop, `--rig-pins`), as `simulate` "
                             "rigs a scene; the error is against the data. "
        : c.options.recorded_pins ? "Pinned vertices: every method, the ground truth included, takes them from the data "
                                    "at every frame (driven like the body; `eval.recorded_pins`). "
                                  : "")
    << "Crumple: mean dihedral angle between adjacent triangles (0° = flat). *One physics step*: "
    << (c.physics_step_from.empty() ? std::string("the step with its default settings")
                                    : "the step of `" + c.physics_step_from + "` (its zero output)")
    << ".\n\n"
       "| method | error mm | near body mm | free cloth mm | H-coll % | L-coll % | strain % (mean / p99) | crumple ° |\n"
       "|---|---|---|---|---|---|---|---|\n";
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    o << "| " << m.name << " | " << pm(s.error_mm) << " | " << fmt("%.1f", s.near_body_mm) << " | "
      << fmt("%.1f", s.free_cloth_mm) << " | " << pm(s.h_percent, "%.2f") << " | " << pm(s.l_outer_percent, "%.2f")
      << " | " << fmt("%.1f", s.strain_mean_percent.mean) << " / " << fmt("%.0f", s.strain_p99_percent.mean) << " | "
      << fmt("%.1f", s.dihedral_mean_deg.mean) << " |\n";
  }
  bool moved = false;
  const bool twins = !c.options.wind_twins.empty();
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    if (!s.wind_moved_mm.count) continue;
    if (!moved) {
      o << "\n## What the wind change moves\n\nMean distance between each model's rollout with the wind x "
        << fmt("%g", c.options.wind_scale) << " and its rollout under the data's wind, over frames and vertices, "
           "mean ± std over sequences with wind (per sequence: `wind_moved_mm` in eval.json). It says how far the "
           "model's cloth follows the wind, not whether it follows it the right way.";
      if (twins)
        o << " Against Blender's twins (" << c.options.wind_twins << ", the same sequences re-simulated with the wind x "
          << fmt("%g", c.options.wind_scale) << "): how far the wind moves Blender's cloth (the data against its twin; "
             "within the window: with the twin moved by its offset at the input frame, from which both rollouts "
             "start), the model's error rise (error with the wind x " << fmt("%g", c.options.wind_scale)
          << " minus error under the data's wind), that rise over Blender's movement (ratio of the means), and the "
             "share of Blender's movement within the window that the model reproduces (its movement projected on "
             "Blender's, per sequence; 1 = all of it, 0 = none).";
      o << (twins ? "\n\n| model | moved mm | Blender's cloth moved mm | within the window mm | error rise mm | rise / "
                    "Blender's | share of Blender's movement |\n|---|---|---|---|---|---|---|\n"
                  : "\n\n| model | moved mm |\n|---|---|\n");
    }
    moved = true;
    o << "| " << m.name << " | " << pm(s.wind_moved_mm);
    if (twins && s.wind_share.count)
      o << " | " << pm(s.twin_moved_mm) << " | " << pm(s.twin_moved_in_window_mm) << " | " << pm(s.wind_error_rise_mm) << " | "
        << fmt("%.2f", s.wind_error_rise_mm.mean / s.twin_moved_mm.mean) << " | " << pm(s.wind_share, "%.2f");
    else if (twins)
      o << " | – | – | – | – | –";
    o << " |\n";
  }
  const auto comparisons = compare_with_baselines(methods);
  if (!comparisons.empty()) {
    o << "\n## Each model against the baselines under the same post-processing\n\n"
         "Ratio = model error / baseline error: of the means over sequences, and per sequence (their mean, median and "
         "the worst sequence). **Bold**: the best baseline (lowest error) under that post-processing.\n\n"
         "| model | baseline | ratio of means | free cloth | per sequence: mean | median | worst (sequence) |\n"
         "|---|---|---|---|---|---|---|\n";
    for (const Comparison& k : comparisons) {
      const std::string b = k.best_baseline ? "**" + k.baseline + "**" : k.baseline;
      o << "| " << k.model << " | " << b << " | " << fmt("%.2f", k.ratio_of_means) << " | "
        << fmt("%.2f", k.free_ratio_of_means) << " | " << fmt("%.2f", k.mean_ratio) << " | "
        << fmt("%.2f", k.median_ratio) << " | " << fmt("%.2f", k.worst_ratio) << " (" << k.worst_id << ")";
      if (k.skipped) o << ", " << k.skipped << " diverged left out";
      o << " |\n";
    }
    o << "\nPer sequence, each model against its best baseline:\n\n| model | baseline |";
    std::vector<std::string> ids;
    for (const Comparison& k : comparisons)
      if (k.best_baseline && k.ids.size() > ids.size()) ids = k.ids;
    for (const auto& id : ids) o << " " << id << " |";
    o << "\n|---|---|";
    for (size_t i = 0; i < ids.size(); ++i) o << "---|";
    o << "\n";
    for (const Comparison& k : comparisons) {
      if (!k.best_baseline) continue;
      o << "| " << k.model << " | " << k.baseline << " |";
      for (const auto& id : ids) {
        const auto it = std::find(k.ids.begin(), k.ids.end(), id);
        o << " " << (it == k.ids.end() ? std::string("–") : fmt("%.2f", k.ratios[static_cast<size_t>(it - k.ids.begin())]))
          << " |";
      }
      o << "\n";
    }
  }
  o << "\n## Crumple and long rollouts\n\n"
       "Dihedral angle between the two triangles of every interior garment edge, degrees (0 = flat): mean and 99th "
       "percentile over edges × frames, and the frame mean at frame "
    << c.options.mark_frames
    << " (the mark; the rollout's last frame when shorter) and at each rollout's last frame. The error is the mean over "
       "the first "
    << c.options.mark_frames
    << " frames and over the whole rollout. Cloth that crumples keeps its edge lengths, so strain misses it.\n\n"
       "![crumple over frames](crumple.png)\n\n"
       "| method | crumple mean ° | crumple p99 ° | at the mark ° | at the end ° | error to the mark mm | error, whole rollout mm |\n"
       "|---|---|---|---|---|---|---|\n";
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    o << "| " << m.name << " | " << pm(s.dihedral_mean_deg) << " | " << pm(s.dihedral_p99_deg) << " | "
      << pm(s.dihedral_at_mark_deg) << " | " << pm(s.dihedral_end_deg) << " | " << pm(s.error_to_mark_mm) << " | "
      << pm(s.error_mm) << " |\n";
  }
  o << "\n";
  o << "## Summary (paper Table 3 layout)\n\n"
    << "| method | overall mm | inner mm | outer mm | L-coll % (÷ outer) | L-coll % (÷ all) | L-coll % (near) | "
       "H-coll % | ms/frame 1 thr | ms/frame 2 thr | × Blender speed | diverged |\n"
       "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    const double up = speedup(c.blender_s_per_frame, m.ms_per_frame_1thread);
    o << "| " << m.name << " | " << pm(s.error_mm) << " | " << pm(s.inner_mm) << " | " << pm(s.outer_mm) << " | "
      << pm(s.l_outer_percent, "%.2f") << " | " << pm(s.l_all_percent, "%.2f") << " | " << pm(s.l_near_percent, "%.2f")
      << " | " << pm(s.h_percent, "%.2f")
      << " | " << (m.ms_per_frame_1thread > 0 ? fmt("%.3g", m.ms_per_frame_1thread) : "–") << " | "
      << (m.ms_per_frame_2threads > 0 ? fmt("%.3g", m.ms_per_frame_2threads) : "–") << " | "
      << (up > 0 ? fmt("%.3g", up) : "–") << " | " << s.diverged << " |\n";
  }
  o << "\nSpeed: median wall time per predicted frame (sample building + forward) over a " << c.speed_frames
    << "-frame rollout of `" << c.speed_sequence << "`; Blender's own time: "
    << (c.blender_s_per_frame > 0 ? fmt("%.3f", c.blender_s_per_frame) + " s/frame (mean over the evaluated sequences, "
                                                                            "recorded at generation)"
                                  : std::string("not recorded in these files"))
    << ". Machine load (1-minute average) after the run: " << fmt("%.1f", c.load_average)
    << " — on a loaded machine 2 threads can be slower than 1. The ground-truth row is the floor of the "
       "collision rates.\n\n";
  o << "## Edge strain, % (every method, the ground truth too)\n\n"
       "Strain = |edge length / rest length − 1| over every garment edge (each once; rest length from the file's rest "
       "shape) and every rollout frame: per sequence the mean and the 99th percentile, then mean ± std over "
       "sequences. The ground truth's strain is the simulator's own.\n\n![strain p99 over frames](strain.png)\n\n"
       "| method | strain % (mean) | strain % (p99) |\n|---|---|---|\n";
  for (const auto& m : methods) {
    const Summary s = summarise(m);
    o << "| " << m.name << " | " << pm(s.strain_mean_percent, "%.2f") << " | " << pm(s.strain_p99_percent, "%.2f")
      << " |\n";
  }
  o << "\n## Error by the ground truth's distance from the body, mm (share of vertex-frames)\n\n"
       "Each vertex-frame falls in a band by the ground truth's distance to its nearest body vertex; the error is "
       "pooled over every vertex-frame of the band in every sequence. Cloth on the body follows the body (and the "
       "contact friction); free cloth is driven by its own dynamics and the wind.\n\n| method |";
  for (int b = 0; b < kBodyDistanceBands; ++b) o << " " << band_label(b) << " |";
  o << "\n|---|";
  for (int b = 0; b < kBodyDistanceBands; ++b) o << "---|";
  o << "\n";
  for (const auto& m : methods) {
    if (m.kind == "ground truth") continue;
    const Summary s = summarise(m);
    o << "| " << m.name << " |";
    for (int b = 0; b < kBodyDistanceBands; ++b)
      o << " " << fmt("%.1f", s.band_mm[b]) << " (" << fmt("%.0f", 100 * s.band_share[b]) << " %) |";
    o << "\n";
  }
  o << "\n";
  const auto types = all_types(methods);
  o << "## Per garment type (paper Table 2 layout), mm (sequences)\n\n| method |";
  for (const auto& t : types) o << " " << t << " |";
  o << " overall |\n|---|";
  for (size_t i = 0; i <= types.size(); ++i) o << "---|";
  o << "\n";
  for (const auto& m : methods) {
    if (m.kind == "ground truth") continue;
    const Summary s = summarise(m);
    o << "| " << m.name << " |";
    for (const auto& t : types)
      o << " "
        << (s.by_type_mm.count(t) ? pm(s.by_type_mm.at(t)) + " (" + std::to_string(s.by_type_mm.at(t).count) + ")" : "–")
        << " |";
    o << " " << pm(s.error_mm) << " |\n";
  }
  o << "\n## Per split (paper Table 1 layout), mm (sequences)\n\nT / L: tight / loose inner layer; +W: windy (max strength > "
       "250); sequences with moderate wind belong to none (dataset.json `subsets`).\n\n| method | T | T+W | L | L+W |\n"
       "|---|---|---|---|---|\n";
  for (const auto& m : methods) {
    if (m.kind == "ground truth") continue;
    const Summary s = summarise(m);
    o << "| " << m.name << " |";
    for (const char* sub : {"T", "T+W", "L", "L+W"})
      o << " " << (s.by_subset_mm.count(sub) ? pm(s.by_subset_mm.at(sub)) + " (" + std::to_string(s.by_subset_mm.at(sub).count) + ")" : "–") << " |";
    o << "\n";
  }
  o << "\n## Error over the rollout (mm, mean over sequences)\n\n![error over frames](curve.png)\n"
       "![error vs speed](speed.png)\n\n| frame |";
  std::vector<Summary> sums;
  size_t n = 0;
  for (const auto& m : methods) {
    if (m.kind == "ground truth") continue;
    o << " " << m.name << " |";
    sums.push_back(summarise(m));
    n = std::max(n, sums.back().curve_mm.size());
  }
  o << "\n|---|";
  for (size_t i = 0; i < sums.size(); ++i) o << "---|";
  o << "\n";
  for (size_t k = 0; k < n; ++k) {
    o << "| " << k + 1 << " |";
    for (const auto& s : sums) o << " " << (k < s.curve_mm.size() ? fmt("%.1f", s.curve_mm[k]) : "–") << " |";
    o << "\n";
  }
  return o.str();
}

std::vector<std::string> write_report(const std::string& dir_name, const std::vector<MethodResult>& methods,
                                      const ReportContext& c) {
  const std::filesystem::path dir(dir_name);
  std::filesystem::create_directories(dir);
  std::vector<std::string> written;
  io::write_file_atomic(dir / "eval.json", report_json(methods, c));
  written.push_back((dir / "eval.json").string());
  const bool ran = plot(dir, methods);
  std::vector<std::string> plots, broken;
  for (const char* name : {"curve.png", "speed.png", "strain.png", "crumple.png"}) {
    const std::filesystem::path png = dir / name;
    if (ran && complete_png(png)) {
      plots.push_back(png.string());
    } else if (std::filesystem::exists(png)) {
      broken.push_back(name);
      std::error_code ec;
      std::filesystem::remove(png, ec);  // a truncated picture would pass for a result
    }
  }
  std::string md = report_markdown(methods, c);
  if (!ran)
    md += "\n(No plots: gnuplot is missing or failed — install `gnuplot-nox` (scripts/debian-packages.txt); "
          "see gnuplot.log.)\n";
  for (const auto& name : broken)
    md += "\n(" + name + " was not written in full — the disk may be full; see gnuplot.log.)\n";
  io::write_file_atomic(dir / "eval.md", md);
  written.push_back((dir / "eval.md").string());
  written.insert(written.end(), plots.begin(), plots.end());
  if (ran && plots.size() < 4)
    std::fprintf(stderr, "warning: %s: %zu of 4 plots were written in full (is the disk full?)\n", dir_name.c_str(),
                 plots.size());
  return written;
}

}  // namespace layersnet::eval
