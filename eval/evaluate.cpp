// Evaluation over a split (see evaluate.h).
#include "eval/evaluate.h"

#include "dataset/h5.h"
#include "dataset/neighbours.h"
#include "dataset/pin_carry.h"
#include "eval/machine.h"
#include "eval/stress.h"

#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>

namespace layersnet::eval {

std::map<std::string, std::vector<std::string>> read_subsets(const std::string& root) {
  std::map<std::string, std::vector<std::string>> out;
  const std::string path = (std::filesystem::path(root) / "dataset.json").string();
  std::ifstream in(path);
  if (!in) return out;
  std::stringstream text;
  text << in.rdbuf();
  const nlohmann::json j = nlohmann::json::parse(text.str(), nullptr, false);
  if (j.is_discarded() || !j.contains("subsets") || !j["subsets"].is_object()) return out;
  for (const auto& [name, ids] : j["subsets"].items()) {
    if (!ids.is_array()) continue;
    for (const auto& id : ids)
      if (id.is_string()) out[id.get<std::string>()].push_back(name);
  }
  return out;
}

double blender_seconds_per_frame(const std::string& path) {
  namespace h5 = dataset::h5;
  const h5::Handle f = h5::open_file(path);
  if (!h5::has_attr(f.get(), "q_blender_s_per_frame")) return -1;
  return h5::read_float_attr(f.get(), "q_blender_s_per_frame", {path, "/"});
}

// Mean distance between two rollouts of the same frames (scene units, over frames and vertices);
// NaN when either diverged.
double mean_distance(const Rollout& a, const Rollout& b) {
  const std::size_t n = std::min(a.frames.size(), b.frames.size());
  double sum = 0;
  for (std::size_t k = 0; k < n; ++k) sum += (a.frames[k] - b.frames[k]).rowwise().norm().cast<double>().mean();
  return n ? sum / static_cast<double>(n) : 0.0;
}

double wind_share(const std::vector<Points>& model_scaled, const std::vector<Points>& model_data_wind,
                  const std::vector<Points>& twin, const std::vector<Points>& truth) {
  const std::size_t n = model_scaled.size();
  if (model_data_wind.size() != n || twin.size() != n || truth.size() != n)
    throw std::invalid_argument("wind_share: frame lists of different lengths");
  double along = 0, blender = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::MatrixXd m = (model_data_wind[k] - model_scaled[k]).cast<double>();
    const Eigen::MatrixXd g = (truth[k] - twin[k]).cast<double>();
    along += m.cwiseProduct(g).sum();
    blender += g.squaredNorm();
  }
  return blender > 0 ? along / blender : std::numeric_limits<double>::quiet_NaN();
}

namespace {

// Checks that a twin folder was made under the wind x wind_scale, where it says so.
void check_wind_twins(const std::string& folder, double wind_scale) {
  if (wind_scale == 1.0)
    throw std::runtime_error("--wind-twins " + folder + ": twins are compared under a changed wind; give --wind-scale "
                             "(the factor the twins were simulated with, 0 for calm twins)");
  if (!std::filesystem::is_directory(folder))
    throw std::runtime_error("--wind-twins " + folder + ": no such folder; make the twins with scripts/predictability.sh "
                             "DATA OUT 0.01 calm-wind (they land in OUT/calm_wind)");
  const std::string scene = (std::filesystem::path(folder) / "scene.json").string();
  if (!std::filesystem::exists(scene)) return;  // another generator's twins: the user vouches for them
  std::ifstream in(scene);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded()) throw std::runtime_error(scene + ": not valid JSON");
  if (!j.contains("wind_scale") || !j["wind_scale"].is_number())
    throw std::runtime_error(scene + ": no number 'wind_scale'; these are not twins under a changed wind (make them "
                             "with scripts/predictability.sh ... calm-wind)");
  const double twin_scale = j["wind_scale"].get<double>();
  const auto text = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  if (twin_scale != wind_scale)
    throw std::runtime_error(scene + ": the twins were simulated with wind_scale " + text(twin_scale) +
                             ", not --wind-scale " + text(wind_scale) + "; pass --wind-scale " + text(twin_scale));
}

}  // namespace

SequenceResult score_rollout(const dataset::Sequence& seq, const Rollout& r, const CollisionOptions& o,
                             int mark_frames) {
  const GarmentLayout L = garment_layout(seq.info);
  SequenceResult s;
  s.garment_types = L.types;
  s.scale = seq.info.scale;
  s.first_frame = r.first_frame;
  s.step_ms = r.step_ms;
  s.diverged_at = r.diverged_at;
  s.garment_error.assign(L.num_garments(), 0.0);
  const double n = static_cast<double>(r.frames.size());
  double inner = 0, outer = 0, h = 0, lo = 0, la = 0, ln = 0;
  const GarmentEdges edges = garment_edges(seq);
  std::vector<double> strains;  // every edge of every frame, for the sequence's p99
  const FacePairs pairs = adjacent_face_pairs(L);
  std::vector<double> dihedrals;  // every interior edge of every frame
  std::array<double, kBodyDistanceBands> band_sum{};
  bool finite = true;
  for (size_t k = 0; k < r.frames.size(); ++k) {
    const int t = r.first_frame + static_cast<int>(k);
    const Points truth = garments_at(seq, t);
    const FrameMetrics m = frame_metrics(L, r.frames[k], truth, seq.body_at(t), seq.info.body_faces, o);
    const dataset::NearestBody near = dataset::nearest_body(truth, seq.body_at(t));
    for (Eigen::Index v = 0; v < truth.rows(); ++v) {
      const double metres = near.distance[static_cast<std::size_t>(v)] / seq.info.scale;
      const int band = metres < kBodyDistanceBandEdgesM[0] ? 0 : metres < kBodyDistanceBandEdgesM[1] ? 1 : 2;
      band_sum[band] += (r.frames[k].row(v) - truth.row(v)).cast<double>().norm();
      ++s.band_vertex_frames[band];
    }
    if (r.frames[k].allFinite()) {
      const std::vector<double> e = edge_strains(edges, r.frames[k]);
      s.strain_p99_curve.push_back(quantile(e, 0.99));
      strains.insert(strains.end(), e.begin(), e.end());
      const std::vector<double> d = dihedral_angles_deg(pairs, r.frames[k]);
      s.dihedral_curve.push_back(mean_std(d).mean);
      dihedrals.insert(dihedrals.end(), d.begin(), d.end());
    } else {  // NaN would break the sort; the sequence counts as diverged
      s.strain_p99_curve.push_back(std::numeric_limits<double>::quiet_NaN());
      s.dihedral_curve.push_back(std::numeric_limits<double>::quiet_NaN());
      finite = false;
    }
    s.error_curve.push_back(m.error);
    s.error += m.error / n;
    for (int g = 0; g < L.num_garments(); ++g) s.garment_error[g] += m.garment_error[g] / n;
    inner += m.inner_error / n;
    outer += m.outer_error / n;
    h += m.h_rate / n;
    lo += m.l_rate_outer / n;
    la += m.l_rate_all / n;
    ln += m.l_rate_outer_near / n;
  }
  for (int b = 0; b < kBodyDistanceBands; ++b)
    s.band_error[b] = s.band_vertex_frames[b] > 0 ? band_sum[b] / static_cast<double>(s.band_vertex_frames[b]) : 0.0;
  s.inner_error = inner;
  s.h_rate = h;
  if (finite) {
    s.strain_mean = mean_std(strains).mean;
    s.strain_p99 = quantile(std::move(strains), 0.99);
    s.dihedral_mean = mean_std(dihedrals).mean;
    s.dihedral_p99 = quantile(std::move(dihedrals), 0.99);
  } else {
    s.strain_mean = s.strain_p99 = std::numeric_limits<double>::quiet_NaN();
    s.dihedral_mean = s.dihedral_p99 = std::numeric_limits<double>::quiet_NaN();
  }
  s.mark = std::clamp(mark_frames, 1, std::max(1, static_cast<int>(r.frames.size())));
  if (!s.error_curve.empty()) {
    s.error_to_mark = 0;
    for (int k = 0; k < s.mark; ++k) s.error_to_mark += s.error_curve[k] / s.mark;
    s.dihedral_at_mark = s.dihedral_curve[s.mark - 1];
  }
  if (L.layered()) {
    s.outer_error = outer;
    s.l_rate_outer = lo;
    s.l_rate_all = la;
    s.l_rate_outer_near = ln;
  }
  return s;
}

RolloutStart rollout_start(const std::string& sequence_path, const EvalOptions& o) {
  if (!o.start_after_ramp) return {o.start_frame, false};
  const int settled = settled_frame(sequence_path, -1);
  if (settled < 0) return {o.start_frame, false};  // not from `layersnet generate`
  return {std::max(2, settled - 1), true};           // t0 + 1 = first settled frame
}

std::vector<std::string> select_sequences(const std::vector<std::string>& split_ids,
                                          const std::vector<std::string>& selection, const std::string& split,
                                          const std::string& where) {
  if (selection.empty()) return split_ids;
  std::vector<bool> chosen(split_ids.size(), false);
  for (const std::string& entry : selection) {
    const size_t dots = entry.find("..");
    const std::string first = dots == std::string::npos ? entry : entry.substr(0, dots);
    const std::string last = dots == std::string::npos ? entry : entry.substr(dots + 2);
    bool any = false;
    for (size_t i = 0; i < split_ids.size(); ++i)
      if (first <= split_ids[i] && split_ids[i] <= last) chosen[i] = any = true;
    if (!any)
      throw std::runtime_error(where + ": split '" + split + "' has no sequence " +
                               (dots == std::string::npos ? "'" + entry + "'" : "in the range '" + entry + "'") +
                               "; --sequences takes ids of that split, or ranges FIRST..LAST of them");
  }
  std::vector<std::string> ids;
  for (size_t i = 0; i < split_ids.size(); ++i)
    if (chosen[i]) ids.push_back(split_ids[i]);
  return ids;
}

std::vector<MethodResult> evaluate(const dataset::DatasetManifest& manifest, std::vector<Predictor*> predictors,
                                   const EvalOptions& o, bool progress) {
  std::vector<std::string> ids = select_sequences(manifest.split(o.split), o.sequences, o.split, manifest.manifest_path());
  if (o.max_sequences > 0 && static_cast<int>(ids.size()) > o.max_sequences) ids.resize(o.max_sequences);
  if (ids.empty())
    throw std::runtime_error(manifest.manifest_path() + ": split '" + o.split +
                             "' lists no sequences; choose another with --split");
  const auto subsets = read_subsets(manifest.root);
  std::unique_ptr<Replay> twins;
  if (!o.wind_twins.empty()) {
    if (o.mirror)
      throw std::runtime_error("--wind-twins " + o.wind_twins + " with --mirror: the twins are of the files, not of their "
                               "mirror images; evaluate the twins without --mirror");
    check_wind_twins(o.wind_twins, o.wind_scale);
    twins = std::make_unique<Replay>("wind twin", o.wind_twins);
  }
  std::vector<MethodResult> results(predictors.size());
  for (size_t p = 0; p < predictors.size(); ++p) results[p].name = predictors[p]->name();
  for (const std::string& id : ids) {
    const dataset::Sequence seq = [&] {
      dataset::Sequence read = dataset::read_sequence(manifest.sequence_path(id));
      if (o.mirror) dataset::mirror(read);
      return read;
    }();
    const RolloutStart start = rollout_start(manifest.sequence_path(id), o);
    dataset::Sequence rigged;  // what every method but the ground truth sees under --rig-pins
    if (o.rig_pins) {
      rigged = seq;
      dataset::rig_pins(rigged, start.input_frame);
    }
    const dataset::Sequence& seen = o.rig_pins ? rigged : seq;
    dataset::Sequence scaled_wind;  // what the models see under --wind-scale
    const bool rescale = seq.info.has_wind && o.wind_scale != 1.0;
    if (rescale) {
      scaled_wind = seen;
      scaled_wind.info.wind_strength *= static_cast<float>(o.wind_scale);
    }
    CollisionOptions co;
    co.max_body_distance = o.max_body_distance_m * seq.info.scale;
    co.max_layer_distance = o.max_layer_distance_m * seq.info.scale;
    // Blender's cloth under the scaled wind and under the data's, on the rollouts' frames; and the
    // twin moved by the two's difference at the input frame, where both rollouts start from the
    // data, so that truth - twin_from_start is what the wind moves within the rollout's window.
    Rollout twin, truth, twin_from_start;
    double twin_moved = 0, twin_moved_in_window = 0;
    if (twins && rescale) {
      GroundTruth data;
      truth = rollout(data, seq, start.input_frame, o.frames);
      twin = rollout(*twins, seq, start.input_frame, o.frames);
      const Points start_offset = garments_at(seq, start.input_frame) -
                                  twins->step(seq, start.input_frame - 1, Points(), Points(), Points());
      twin_from_start = twin;
      for (Points& frame : twin_from_start.frames) frame += start_offset;
      twin_moved = mean_distance(truth, twin);
      twin_moved_in_window = mean_distance(truth, twin_from_start);
    }
    for (size_t p = 0; p < predictors.size(); ++p) {
      const bool scaled = rescale && predictors[p]->takes_scaled_wind();
      const bool truth_itself = dynamic_cast<const GroundTruth*>(predictors[p]) != nullptr;
      const dataset::Sequence& given = truth_itself ? seq : seen;
      const Rollout r = rollout(*predictors[p], scaled ? scaled_wind : given, start.input_frame, o.frames, o.recorded_pins);
      SequenceResult s = score_rollout(seq, r, co, o.mark_frames);
      if (scaled) {
        const Rollout data_wind = rollout(*predictors[p], given, start.input_frame, o.frames, o.recorded_pins);
        s.wind_moved = mean_distance(r, data_wind);
        if (!twin.frames.empty() && twin.frames.size() == r.frames.size()) {
          s.twin_moved = twin_moved;
          s.twin_moved_in_window = twin_moved_in_window;
          s.wind_error_rise = s.error - mean_distance(data_wind, truth);
          s.wind_share = wind_share(r.frames, data_wind.frames, twin_from_start.frames, truth.frames);
        }
      }
      s.id = id;
      s.after_ramp = start.after_ramp;
      if (auto it = subsets.find(id); it != subsets.end()) s.subsets = it->second;
      if (progress)
        std::printf("  %-10s %-22s %3zu frames from %3d  error %8.2f mm  H %5.2f %%  L %s  strain p99 %6.2f %%\n",
                    id.c_str(), predictors[p]->name().c_str(), r.frames.size(), r.first_frame, s.error * s.mm(),
                    100 * s.h_rate,
                    s.l_rate_outer < 0 ? "  -" : (std::to_string(100 * s.l_rate_outer).substr(0, 5) + " %").c_str(),
                    100 * s.strain_p99);
      results[p].sequences.push_back(std::move(s));
    }
    if (progress) std::fflush(stdout);
  }
  return results;
}

void Replay::begin(const dataset::Sequence& seq) {
  const std::string path = (std::filesystem::path(folder_) / std::filesystem::path(seq.info.path).filename()).string();
  if (path == loaded_) return;
  if (!std::filesystem::exists(path))
    throw std::runtime_error(path + ": no recorded sequence to replay for " + seq.info.path +
                             "; the replay folder needs a file of the same name for every evaluated sequence");
  dataset::Sequence recorded = dataset::read_sequence(path);
  const auto mismatch = [&](const std::string& what) {
    return std::runtime_error(path + ": cannot replay against " + seq.info.path + ": " + what);
  };
  if (recorded.info.num_garments() != seq.info.num_garments())
    throw mismatch(std::to_string(recorded.info.num_garments()) + " garments, not " +
                   std::to_string(seq.info.num_garments()));
  for (int g = 0; g < seq.info.num_garments(); ++g)
    if (recorded.info.garments[g].num_vertices != seq.info.garments[g].num_vertices)
      throw mismatch("garment " + std::to_string(g) + " has " + std::to_string(recorded.info.garments[g].num_vertices) +
                     " vertices, not " + std::to_string(seq.info.garments[g].num_vertices));
  if (recorded.info.num_frames < seq.info.num_frames)
    throw mismatch(std::to_string(recorded.info.num_frames) + " frames, fewer than " +
                   std::to_string(seq.info.num_frames));
  recorded_ = std::move(recorded);
  loaded_ = path;
}

Points Replay::step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) {
  begin(seq);
  return garments_at(recorded_, t + 1);
}

double median_ms_per_frame(Predictor& predictor, const dataset::Sequence& seq, int t0, int frames, int threads) {
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  Rollout r;
  try {
    r = rollout(predictor, seq, t0, frames);
  } catch (...) {
    omp_set_num_threads(before);
    throw;
  }
  omp_set_num_threads(before);
  return median(r.step_ms);
}

Summary summarise(const MethodResult& m) {
  Summary s;
  std::vector<double> err, inner, outer, h, lo, la, ln, strain_mean, strain_p99, steps, wind_moved;
  std::vector<double> twin_moved, twin_moved_in_window, wind_error_rise, wind_shares;
  std::vector<double> dihedral_mean, dihedral_p99, to_mark, at_mark, at_end;
  std::vector<std::vector<double>> dihedral_curve;
  std::map<std::string, std::vector<double>> by_type, by_subset;
  std::vector<std::vector<double>> curve, strain_curve;
  std::array<double, kBodyDistanceBands> band_sum_mm{};
  std::array<int64_t, kBodyDistanceBands> band_count{};
  for (const SequenceResult& r : m.sequences) {
    if (r.diverged_at >= 0 || !std::isfinite(r.error)) {
      ++s.diverged;
      continue;
    }
    const double mm = r.mm();
    for (int b = 0; b < kBodyDistanceBands; ++b) {
      band_sum_mm[b] += r.band_error[b] * mm * static_cast<double>(r.band_vertex_frames[b]);
      band_count[b] += r.band_vertex_frames[b];
    }
    err.push_back(r.error * mm);
    inner.push_back(r.inner_error * mm);
    h.push_back(100 * r.h_rate);
    strain_mean.push_back(100 * r.strain_mean);
    if (r.wind_moved >= 0) wind_moved.push_back(r.wind_moved * mm);
    if (std::isfinite(r.wind_share)) {
      twin_moved.push_back(r.twin_moved * mm);
      twin_moved_in_window.push_back(r.twin_moved_in_window * mm);
      wind_error_rise.push_back(r.wind_error_rise * mm);
      wind_shares.push_back(r.wind_share);
    }
    strain_p99.push_back(100 * r.strain_p99);
    dihedral_mean.push_back(r.dihedral_mean);
    dihedral_p99.push_back(r.dihedral_p99);
    to_mark.push_back(r.error_to_mark * mm);
    if (!r.dihedral_curve.empty()) {
      at_mark.push_back(r.dihedral_at_mark);
      at_end.push_back(r.dihedral_curve.back());
    }
    s.mark = s.mark == 0 ? r.mark : std::min(s.mark, r.mark);
    for (size_t k = 0; k < r.dihedral_curve.size(); ++k) {
      if (dihedral_curve.size() <= k) dihedral_curve.resize(k + 1);
      dihedral_curve[k].push_back(r.dihedral_curve[k]);
    }
    if (r.outer_error >= 0) {
      outer.push_back(r.outer_error * mm);
      lo.push_back(100 * r.l_rate_outer);
      la.push_back(100 * r.l_rate_all);
      ln.push_back(100 * r.l_rate_outer_near);
    }
    // A type worn twice in one sequence counts once (its garments' vertex-weighted mean is
    // not kept, so the plain mean of the two garments is used).
    std::map<std::string, std::vector<double>> seq_types;
    for (size_t g = 0; g < r.garment_types.size(); ++g) seq_types[r.garment_types[g]].push_back(r.garment_error[g] * mm);
    for (const auto& [type, values] : seq_types) by_type[type].push_back(mean_std(values).mean);
    for (const auto& sub : r.subsets) by_subset[sub].push_back(r.error * mm);
    for (size_t k = 0; k < r.error_curve.size(); ++k) {
      if (curve.size() <= k) curve.resize(k + 1);
      curve[k].push_back(r.error_curve[k] * mm);
    }
    for (size_t k = 0; k < r.strain_p99_curve.size(); ++k) {
      if (strain_curve.size() <= k) strain_curve.resize(k + 1);
      strain_curve[k].push_back(100 * r.strain_p99_curve[k]);
    }
    steps.insert(steps.end(), r.step_ms.begin(), r.step_ms.end());
  }
  s.error_mm = mean_std(err);
  s.inner_mm = mean_std(inner);
  s.outer_mm = mean_std(outer);
  s.h_percent = mean_std(h);
  s.l_outer_percent = mean_std(lo);
  s.l_all_percent = mean_std(la);
  s.l_near_percent = mean_std(ln);
  s.strain_mean_percent = mean_std(strain_mean);
  s.wind_moved_mm = mean_std(wind_moved);
  s.twin_moved_mm = mean_std(twin_moved);
  s.twin_moved_in_window_mm = mean_std(twin_moved_in_window);
  s.wind_error_rise_mm = mean_std(wind_error_rise);
  s.wind_share = mean_std(wind_shares);
  s.strain_p99_percent = mean_std(strain_p99);
  s.dihedral_mean_deg = mean_std(dihedral_mean);
  s.dihedral_p99_deg = mean_std(dihedral_p99);
  s.error_to_mark_mm = mean_std(to_mark);
  s.dihedral_at_mark_deg = mean_std(at_mark);
  s.dihedral_end_deg = mean_std(at_end);
  for (const auto& v : dihedral_curve) s.dihedral_curve_deg.push_back(mean_std(v).mean);
  for (const auto& [k, v] : by_type) s.by_type_mm[k] = mean_std(v);
  for (const auto& [k, v] : by_subset) s.by_subset_mm[k] = mean_std(v);
  for (const auto& v : curve) s.curve_mm.push_back(mean_std(v).mean);
  for (const auto& v : strain_curve) s.strain_p99_curve_percent.push_back(mean_std(v).mean);
  const double all_vertex_frames = static_cast<double>(band_count[0] + band_count[1] + band_count[2]);
  for (int b = 0; b < kBodyDistanceBands; ++b) {
    s.band_mm[b] = band_count[b] > 0 ? band_sum_mm[b] / static_cast<double>(band_count[b])
                                     : std::numeric_limits<double>::quiet_NaN();
    s.band_share[b] = all_vertex_frames > 0 ? static_cast<double>(band_count[b]) / all_vertex_frames : 0.0;
  }
  const int64_t near_count = band_count[0] + band_count[1];
  s.near_body_mm = near_count > 0 ? (band_sum_mm[0] + band_sum_mm[1]) / static_cast<double>(near_count)
                                  : std::numeric_limits<double>::quiet_NaN();
  s.free_cloth_mm = s.band_mm[kBodyDistanceBands - 1];
  s.free_share = s.band_share[kBodyDistanceBands - 1];
  if (!steps.empty()) {
    std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
    s.median_step_ms = steps[steps.size() / 2];
  }
  return s;
}

std::vector<Comparison> compare_with_baselines(const std::vector<MethodResult>& methods) {
  std::vector<Comparison> out;
  std::vector<Summary> sums;  // each method summarised once
  for (const MethodResult& m : methods) sums.push_back(summarise(m));
  for (size_t mi = 0; mi < methods.size(); ++mi) {
    const MethodResult& m = methods[mi];
    if (m.kind != "model") continue;
    const Summary& sm = sums[mi];
    const size_t first = out.size();
    for (size_t bi = 0; bi < methods.size(); ++bi) {
      const MethodResult& b = methods[bi];
      if (b.kind != "baseline" || b.post_processed != m.post_processed) continue;
      const Summary& sb = sums[bi];
      Comparison c;
      c.model = m.name;
      c.baseline = b.name;
      c.post_processed = m.post_processed;
      c.ratio_of_means = sb.error_mm.mean > 0 ? sm.error_mm.mean / sb.error_mm.mean : 0;
      c.free_ratio_of_means = sb.free_cloth_mm > 0 ? sm.free_cloth_mm / sb.free_cloth_mm : 0;
      std::map<std::string, const SequenceResult*> base;
      for (const auto& r : b.sequences) base[r.id] = &r;
      for (const auto& r : m.sequences) {
        const auto it = base.find(r.id);
        if (it == base.end()) continue;
        const SequenceResult& q = *it->second;
        if (r.diverged_at >= 0 || q.diverged_at >= 0 || !std::isfinite(r.error) || !std::isfinite(q.error) ||
            !(q.error > 0)) {
          ++c.skipped;
          continue;
        }
        c.ids.push_back(r.id);
        c.ratios.push_back(r.error / q.error);
      }
      if (!c.ratios.empty()) {
        c.mean_ratio = mean_std(c.ratios).mean;
        c.median_ratio = quantile(c.ratios, 0.5);
        const auto worst = std::max_element(c.ratios.begin(), c.ratios.end());
        c.worst_ratio = *worst;
        c.worst_id = c.ids[static_cast<size_t>(worst - c.ratios.begin())];
      }
      out.push_back(std::move(c));
    }
    // The best baseline has the lowest error, so the highest ratio of means.
    size_t best = out.size();
    for (size_t i = first; i < out.size(); ++i)
      if (out[i].ratio_of_means > 0 && (best == out.size() || out[i].ratio_of_means > out[best].ratio_of_means))
        best = i;
    if (best < out.size()) out[best].best_baseline = true;
  }
  return out;
}

}  // namespace layersnet::eval
