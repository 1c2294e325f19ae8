// `layersnet bench scene`: cost follows the scene's content. One motion (the
// synthetic outfit of `bench scaling` at --vertices, 3x3-quad patches, body 106 x 65), timed
// in configurations that each take one part away (synthetic options: every other part of the
// sequence stays bit-identical, dataset/synthetic.h):
//   full         two garments + wind + body near
//   one_garment  the inner garment only (its vertices, patches and their edges)
//   no_wind      no wind token (ModelInput has_wind = false: no encoder, no edges)
//   body_far     body moved 20 units up, beyond R_b: no body neighbours, no body tokens
//   bare         all three removals at once (checks that the savings add up)
// For each: inference ms/frame (input build + forward without tape) and training step ms
// (forward + losses + backward + Adam), medians over interleaved passes, the measured saving
// vs full, and the EXPECTED saving from the full run's own stage times (model::StageTimes)
// scaled by the share of rows each stage loses (rows counted by the forward itself):
//   graph, attention edges  world + inter + mesh rows      inter RET messages   inter rows
//   body encoder            U body tokens                  other encoders       2P + A + ext + tokens
//   attention projections   4P + 2 tokens                  FFN/LN/memory        (L-1) tokens + P
//   decoder                 candidate rows + N + P         unstaged remainder   P
//   input build             N + P (the body/wind searches still run; sample + model input,
//                           patch structure cached as in a rollout)
//   train step              (train - Adam) x expected forward share (backward assumed ∝ forward)
#include "bench/bench_scene.h"
#include "autodiff/optim.h"
#include "bench/bench_util.h"
#include "dataset/file_io.h"
#include "eval/metrics.h"
#include "losses/losses.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <stdexcept>

namespace {


using namespace layersnet;


using bench::median;
using bench::median_times;
using bench::now_ms;
using eval::quantile;

struct Config {
  std::string name;
  bench::Scene scene;
  model::ModelInput<float> input;
  losses::LossInput<float> target;
  std::vector<double> infer, input_ms, forward, train, adam;
  std::vector<model::StageTimes> stages;
  model::StageTimes med;  // medians of the stage times, counts of the input
};


// Expected forward saving (ms) of a variant with work counts `v`, from the full run's stage
// times and counts `f` (see the file comment for the rows of each stage).
struct Expected {
  double graph = 0, encoder = 0, attention = 0, ffn = 0, decoder = 0, rest = 0;
  double forward() const { return graph + encoder + attention + ffn + decoder + rest; }
};
Expected expected_saving(const model::StageTimes& f, const model::StageTimes& v, int layers) {
  auto lost = [](double full, double var) { return full > 0 ? 1.0 - var / full : 0.0; };
  auto rows = [](const model::StageTimes& t) { return static_cast<double>(t.world_rows + t.inter_rows + t.mesh_rows); };
  auto enc = [](const model::StageTimes& t) {
    const double A = static_cast<double>(t.token_rows - t.patch_rows - t.body_tokens - t.ext_tokens);
    return 2.0 * t.patch_rows + A + t.ext_tokens + t.token_rows;
  };
  auto proj = [](const model::StageTimes& t) { return 4.0 * t.patch_rows + 2.0 * t.token_rows; };
  auto ffn = [layers](const model::StageTimes& t) { return (layers - 1.0) * t.token_rows + t.patch_rows; };
  auto dec = [](const model::StageTimes& t) { return static_cast<double>(t.candidate_rows + t.vertex_rows + t.patch_rows); };
  Expected e;
  e.graph = f.graph_ms * lost(rows(f), rows(v));
  e.encoder = f.encoder_body_ms * lost(static_cast<double>(f.body_tokens), static_cast<double>(v.body_tokens)) +
              (f.encoder_ms - f.encoder_body_ms) * lost(enc(f), enc(v));
  e.attention = (f.attention_ms - f.attention_edges_ms) * lost(proj(f), proj(v)) +
                (f.attention_edges_ms - f.attention_inter_ms) * lost(rows(f), rows(v)) +
                f.attention_inter_ms * lost(static_cast<double>(f.inter_rows), static_cast<double>(v.inter_rows));
  e.ffn = f.ffn_ms * lost(ffn(f), ffn(v));
  e.decoder = f.decoder_ms * lost(dec(f), dec(v));
  const double staged = f.graph_ms + f.encoder_ms + f.attention_ms + f.ffn_ms + f.decoder_ms;
  e.rest = std::max(0.0, f.total_ms - staged) * lost(static_cast<double>(f.patch_rows), static_cast<double>(v.patch_rows));
  return e;
}

}  // namespace

namespace layersnet::eval {

int run_bench_scene(const SceneBenchOptions& o) {
  ad::keep_freed_memory_in_process();
  omp_set_num_threads(o.threads);
  Eigen::setNbThreads(1);
  const ModelConfig mc;  // official sizes
  const LossConfig lc;
  // The outfit at --vertices with 3 x 3-quad patches, and its variants: the same sequence
  // without the outer garment, the wind, the body's nearness (20 units up), or all three.
  dataset::SyntheticOptions full = bench::outfit(o.vertices);
  for (auto& g : full.sheets) g.uv_step = {static_cast<float>(mc.patch_size / 3), static_cast<float>(mc.patch_size / 3)};
  dataset::SyntheticOptions one = full, calm = full, far = full, bare = full;
  one.sheets.resize(1);
  calm.wind = false;
  far.body_offset = {0.f, 0.f, 20.f};
  bare.sheets.resize(1), bare.wind = false, bare.body_offset = far.body_offset;
  std::vector<Config> cs(5);
  const std::pair<const char*, const dataset::SyntheticOptions*> variants[5] = {
      {"full", &full}, {"one_garment", &one}, {"no_wind", &calm}, {"body_far", &far}, {"bare", &bare}};
  const dataset::NormalisationStats stats = dataset::compute_stats(dataset::make_synthetic_sequence(full));
  for (int k = 0; k < 5; ++k) {
    Config& c = cs[k];
    c.name = variants[k].first;
    c.scene = bench::make_scene(*variants[k].second, mc);
    c.scene.stats = stats;  // the full scene's statistics for every variant
    const dataset::TrainingSample sample = bench::sample_of(c.scene, mc);
    c.input = model::model_input_from_sample(sample, c.scene.stats, mc);
    c.target = losses::loss_input_from_sample(sample, c.scene.seq.info);
  }
  ad::ParamStore<float> ps;
  model::register_params(ps, mc);
  model::init_params(ps, mc, 1);
  ad::Adam<float> adam(ps, {.lr = 1e-6});  // tiny steps: the parameters stay near the initial ones
  ad::Tape<float> tape;

  const char* wait = std::getenv("OMP_WAIT_POLICY");
  std::printf("bench scene: ~%lld garment vertices, %d thread(s), %d interleaved passes x %d iterations (+%d warm-up), "
              "model d=%d, %d layers, K=%d, decoder RET channels k=%d, OMP_WAIT_POLICY=%s\nload (uptime) at start: %s\n",
              (long long)o.vertices, o.threads, o.passes, o.iters, o.warmup, mc.width, mc.layers, mc.body_neighbors,
              mc.decoder_ret_channels, wait ? wait : "(default)", eval::load_averages().c_str());
  for (int pass = 0; pass < o.passes; ++pass) {
    for (auto& c : cs) {
      for (int it = 0; it < (pass == 0 ? o.warmup : 0) + o.iters; ++it) {
        const bool keep = !(pass == 0 && it < o.warmup);
        const bench::InferenceTiming inf = bench::time_inference(c.scene, mc, ps, tape);
        const double t_in = inf.input_ms, t_fwd = inf.forward_ms;
        const model::StageTimes& st = inf.stages;
        const double t0 = now_ms();
        tape.reset();
        ps.zero_grads();
        const auto pred = model::forward(tape, ps, mc, c.input);
        tape.backward(losses::compute_losses(tape, ps, mc, lc, c.target, pred).total);
        const double t_adam = now_ms();
        adam.step();
        const double t_end = now_ms();
        if (!keep) continue;
        c.input_ms.push_back(t_in), c.forward.push_back(t_fwd), c.infer.push_back(t_in + t_fwd);
        c.train.push_back(t_end - t0), c.adam.push_back(t_end - t_adam), c.stages.push_back(st);
      }
    }
    std::printf("  pass %d done (load %s)\n", pass + 1, eval::load_averages().c_str());
    std::fflush(stdout);
  }
  for (auto& c : cs) c.med = median_times(c.stages);

  const Config& f = cs[0];
  const auto& F = f.med;
  const double f_inf = median(f.infer), f_tr = median(f.train), f_in = median(f.input_ms), f_adam = median(f.adam);
  std::printf("\nfull run's forward split (ms, medians): graph %.1f, encoder %.1f (body tokens %.1f), attention %.1f "
              "(edges %.1f, of which inter RET %.1f), FFN/LN %.1f, decoder %.1f, total %.1f; input build %.1f; "
              "train %.1f (Adam %.1f)\n",
              F.graph_ms, F.encoder_ms, F.encoder_body_ms, F.attention_ms, F.attention_edges_ms, F.attention_inter_ms,
              F.ffn_ms, F.decoder_ms, F.total_ms, f_in, f_tr, f_adam);
  // Noise floor: savings smaller than the full run's own interquartile spread are not resolved.
  const double iqr_inf = quantile(f.infer, 0.75) - quantile(f.infer, 0.25), iqr_tr = quantile(f.train, 0.75) - quantile(f.train, 0.25);
  std::printf("full run's spread (interquartile, %zu iterations): infer %.1f ms (%.1f%%), train %.1f ms (%.1f%%): "
              "smaller savings are within the noise of this machine\n",
              f.infer.size(), iqr_inf, f_inf > 0 ? 100 * iqr_inf / f_inf : 0.0, iqr_tr, f_tr > 0 ? 100 * iqr_tr / f_tr : 0.0);
  std::printf("\n%-12s %6s %5s %5s %4s %7s %7s %7s | %8s %15s %15s | %8s %15s %15s\n", "config", "N", "P", "U", "T",
              "E_world", "E_inter", "E_mesh", "infer_ms", "saved (meas.)", "saved (exp.)", "train_ms", "saved (meas.)",
              "saved (exp.)");
  nlohmann::json out = {{"vertices", o.vertices}, {"threads", o.threads}, {"passes", o.passes}, {"iters", o.iters},
                        {"omp_wait_policy", wait ? wait : ""}, {"full_infer_iqr_ms", iqr_inf},
                        {"full_train_iqr_ms", iqr_tr}, {"configs", nlohmann::json::array()}};
  for (const auto& c : cs) {
    const auto& m = c.med;
    const double inf = median(c.infer), tr = median(c.train);
    const Expected e = expected_saving(F, m, mc.layers);
    const double n_share = 1.0 - static_cast<double>(m.vertex_rows + m.patch_rows) / static_cast<double>(F.vertex_rows + F.patch_rows);
    const double e_inf = e.forward() + f_in * n_share;
    const double e_tr = F.total_ms > 0 ? (f_tr - f_adam) * e.forward() / F.total_ms : 0;
    auto cell = [](double saved, double base) {
      char b[32];
      std::snprintf(b, sizeof b, "%7.1f %5.1f%%", saved, base > 0 ? 100 * saved / base : 0.0);
      return std::string(b);
    };
    std::printf("%-12s %6lld %5lld %5lld %4lld %7lld %7lld %7lld | %8.1f %15s %15s | %8.1f %15s %15s\n", c.name.c_str(),
                (long long)m.vertex_rows, (long long)m.patch_rows, (long long)m.body_tokens,
                (long long)(m.body_tokens + m.ext_tokens), (long long)m.world_rows, (long long)m.inter_rows,
                (long long)m.mesh_rows, inf, cell(f_inf - inf, f_inf).c_str(), cell(e_inf, f_inf).c_str(), tr,
                cell(f_tr - tr, f_tr).c_str(), cell(e_tr, f_tr).c_str());
    out["configs"].push_back(
        {{"name", c.name}, {"N", m.vertex_rows}, {"P", m.patch_rows}, {"U", m.body_tokens}, {"ext_tokens", m.ext_tokens},
         {"E_world", m.world_rows}, {"E_inter", m.inter_rows}, {"E_inter_body", m.body_rows}, {"E_mesh", m.mesh_rows},
         {"E_candidates", m.candidate_rows}, {"infer_ms", inf}, {"input_ms", median(c.input_ms)},
         {"forward_ms", median(c.forward)}, {"train_ms", tr}, {"adam_ms", median(c.adam)},
         {"saved_infer_ms", f_inf - inf}, {"expected_saved_infer_ms", e_inf}, {"saved_train_ms", f_tr - tr},
         {"expected_saved_train_ms", e_tr},
         {"forward_stages_ms", {{"graph", m.graph_ms}, {"encoder", m.encoder_ms}, {"encoder_body", m.encoder_body_ms},
                                {"attention", m.attention_ms}, {"attention_edges", m.attention_edges_ms},
                                {"attention_inter", m.attention_inter_ms}, {"ffn", m.ffn_ms}, {"decoder", m.decoder_ms},
                                {"total", m.total_ms}}},
         {"expected_saved_forward_ms", {{"graph", e.graph}, {"encoder", e.encoder}, {"attention", e.attention},
                                        {"ffn", e.ffn}, {"decoder", e.decoder}, {"rest", e.rest}, {"total", e.forward()}}}});
  }
  std::printf("\nforward stages per config (ms, medians): measured saving vs full | expected saving per stage\n");
  std::printf("%-12s %7s %7s %7s %7s %7s %7s | %6s %6s %6s %6s %6s %6s\n", "config", "graph", "enc", "attn", "ffn",
              "dec", "fwd", "e_grph", "e_enc", "e_attn", "e_ffn", "e_dec", "e_fwd");
  for (const auto& c : cs) {
    const auto& m = c.med;
    const Expected e = expected_saving(F, m, mc.layers);
    std::printf("%-12s %7.1f %7.1f %7.1f %7.1f %7.1f %7.1f | %6.1f %6.1f %6.1f %6.1f %6.1f %6.1f\n", c.name.c_str(),
                F.graph_ms - m.graph_ms, F.encoder_ms - m.encoder_ms, F.attention_ms - m.attention_ms, F.ffn_ms - m.ffn_ms,
                F.decoder_ms - m.decoder_ms, F.total_ms - m.total_ms, e.graph, e.encoder, e.attention, e.ffn, e.decoder,
                e.forward());
  }
  std::printf("T = body + wind + gravity tokens; E_inter = patch -> token edges; expected = full run's stage time x "
              "share of the stage's rows that the configuration lacks (rows counted by the forward)\nload (uptime) at "
              "end: %s\n",
              eval::load_averages().c_str());
  out["load_end"] = eval::load_averages();
  if (!o.json.empty()) {
    layersnet::io::write_file_atomic(o.json, out.dump(1) + "\n");
  }
  return 0;
}

}  // namespace layersnet::eval

