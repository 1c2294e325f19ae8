#include "train/trainer.h"

#include "autodiff/optim.h"
#include "autodiff/tape.h"
#include "dataset/file_io.h"
#include "dataset/manifest.h"
#include "dataset/stats.h"
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "train/distributed.h"
#include "train/eta.h"
#include "train/gsl_random.h"
#include "run/run_dir.h"
#include "train/sample_step.h"
#include "train/train_data.h"

#include <Eigen/Core>
#include <gsl/gsl_randist.h>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

namespace layersnet {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double learning_rate_at(const TrainConfig& train, int epoch) {
  // lr_decay_epochs are 1-based epochs after which the rate drops (official step policy).
  double lr = train.learning_rate;
  for (int d : train.lr_decay_epochs)
    if (d <= epoch) lr *= train.lr_gamma;
  return lr;
}

int rollout_steps_at(const TrainConfig& train, int epoch) {
  if (train.rollout_steps.empty()) return 0;
  return train.rollout_steps[static_cast<std::size_t>(std::min<int>(epoch, static_cast<int>(train.rollout_steps.size()) - 1))];
}

Config run_config(const std::string& run_dir, const std::vector<std::string>& overrides) {
  const std::string path = (fs::path(run_dir) / "config.toml").string();
  if (!fs::exists(path))
    throw ConfigError(path + ": not found; " + run_dir +
                      " does not hold a run to resume (start one with `layersnet train --config F --run " + run_dir + "`)");
  Config config = load_config({path});
  std::ifstream in(path);
  apply_saved_config_defaults(config, std::string(std::istreambuf_iterator<char>(in), {}));
  for (const auto& o : overrides) apply_override(config, o);
  return config;
}

namespace {

// What a diverged run leaves and how to go on (both stop messages end with it).
std::string divergence_advice(const std::string& run_dir) {
  const auto kept = list_checkpoints(run_dir);
  return "The last valid checkpoint is " + (kept.empty() ? std::string("none (no checkpoint was written yet)") : kept.back()) +
         ". Lower train.learning_rate or set train.grad_clip, then resume or restart.";
}

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

// Non-finite values become null, as JSON has no NaN.
nlohmann::ordered_json json_number(double x) { return std::isfinite(x) ? nlohmann::ordered_json(x) : nlohmann::ordered_json(nullptr); }

nlohmann::ordered_json json_parts(const LossParts& p, double orthogonality_excess) {
  return {{"total", json_number(p.total)},
          {"vertex", json_number(p.vertex)},
          {"patch", json_number(p.patch)},
          {"normal", json_number(p.normal)},
          {"collision_body", json_number(p.collision_body)},
          {"collision_layer", json_number(p.collision_layer)},
          {"orthogonality", json_number(p.orthogonality)},
          {"orthogonality_excess", json_number(orthogonality_excess)},
          {"edge_strain", json_number(p.edge_strain)},
          {"physics", json_number(p.physics)}};
}

std::string duration_text(double s) {
  if (!std::isfinite(s) || s < 0) return "?";
  char buf[32];
  const long long t = static_cast<long long>(s + 0.5);
  if (t >= 3600) std::snprintf(buf, sizeof buf, "%lldh%02lldm", t / 3600, (t / 60) % 60);
  else std::snprintf(buf, sizeof buf, "%lldm%02llds", t / 60, t % 60);
  return buf;
}

bool all_finite(std::span<const float> values) {
  for (float v : values)
    if (!std::isfinite(v)) return false;
  return true;
}

// The outcomes of all n samples of a batch on every rank, in sample order (local: this rank's).
std::vector<SampleOutcome> gather_outcomes(const Ranks& ranks, const std::vector<SampleOutcome>& local, int n) {
  constexpr int kWidth = 14;
  std::vector<double> packed;
  for (const auto& o : local) {
    const LossParts& l = o.loss;
    packed.insert(packed.end(), {l.total, l.vertex, l.patch, l.normal, l.collision_body, l.collision_layer,
                                 l.orthogonality, l.edge_strain, o.loss_finite ? 1.0 : 0.0, o.grad_finite ? 1.0 : 0.0,
                                 o.build_seconds, o.model_seconds, l.physics, l.physics_weighted});
  }
  const std::vector<double> all = ranks.gather_items(packed, n, kWidth);
  std::vector<SampleOutcome> out(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double* v = all.data() + static_cast<std::ptrdiff_t>(i) * kWidth;
    SampleOutcome& o = out[static_cast<std::size_t>(i)];
    o.loss = {v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[12], v[13]};
    o.loss_finite = v[8] != 0;
    o.grad_finite = v[9] != 0;
    o.build_seconds = v[10];
    o.model_seconds = v[11];
  }
  return out;
}

// Everything of one run that lives across epochs.
class Run {
 public:
  Run(const Config& config, const TrainOptions& options);
  TrainSummary execute();

 private:
  void open_data();
  void restore(const std::string& path);
  void start_from(const std::string& path);  // train.init_from
  void run_epoch(int epoch);
  bool run_batch(int epoch, int ngs, const std::vector<int64_t>& order);  // false: max_steps reached
  bool step_cap_reached() const {
    return config_.train.max_steps > 0 && batches_before_ + summary_.batches >= config_.train.max_steps;
  }
  double validate();
  double validate_rollouts();  // train.val_rollout_frames > 0
  void save(const std::string& path);
  void save_step_checkpoint();
  void log_progress(int epoch);
  // One writer: only rank 0 prints, logs metrics and writes files.
  void metric(const nlohmann::ordered_json& record) {
    if (ranks_.rank() == 0) io::append_line(metrics_path_, record.dump());
  }
  bool writer() const { return ranks_.rank() == 0; }

  Config config_;
  TrainOptions options_;
  const Ranks& ranks_;
  std::ostream null_out_{nullptr};  // the other ranks' progress lines go nowhere
  std::ostream& out_;
  std::string metrics_path_;
  int threads_ = 1;
  dataset::NormalisationStats stats_;
  std::unique_ptr<TrainData> train_, val_;
  ad::ParamStore<float> params_;
  std::unique_ptr<ad::Adam<float>> adam_;
  std::vector<std::unique_ptr<ad::ParamStore<float>>> slots_;  // one gradient buffer per local batch slot
  std::vector<std::unique_ptr<ad::Tape<float>>> tapes_;        // one per thread
  GslRandom shuffle_rng_, rollout_rng_;
  std::vector<uint8_t> shuffle_at_epoch_start_;
  TrainingState state_;
  int64_t batches_per_epoch_ = 0;
  int64_t batches_before_ = 0;  // batches of the run before this process started (resume)
  TrainSummary summary_;
  // Progress window (since the last log line).
  LossParts window_loss_;
  int64_t window_batches_ = 0, window_samples_ = 0;
  double window_grad_norm_ = 0;
  double window_data_s_ = 0, window_build_s_ = 0, window_model_s_ = 0, window_optim_s_ = 0, window_wall_s_ = 0,
         window_reduce_s_ = 0;
  int64_t window_sent_bytes_ = 0;
  double total_wall_s_ = 0;
  TrainingEta eta_;  // the run's time left, from the cost of each batch's samples and self-fed steps
  int64_t total_samples_ = 0;
  Clock::time_point window_start_ = Clock::now();
};

Run::Run(const Config& config, const TrainOptions& options)
    : config_(config),
      options_(options),
      ranks_(Ranks::world()),
      out_(ranks_.rank() != 0 ? null_out_ : options.log ? *options.log : std::cout),
      metrics_path_((fs::path(options.run_dir) / "metrics.jsonl").string()),
      shuffle_rng_(static_cast<uint64_t>(config.train.seed) * 2 + 1),
      rollout_rng_(static_cast<uint64_t>(config.train.seed) * 2 + 2) {}

void Run::open_data() {
  const dataset::DatasetManifest manifest = dataset::read_manifest(config_.data.dataset);
  train_ = std::make_unique<TrainData>(manifest, "train", stats_, config_);
  if (train_->num_samples() == 0)
    throw std::runtime_error(config_.data.dataset + ": the train split has no samples for data.first_frame = " +
                             std::to_string(config_.data.first_frame) + " and data.max_frames = " +
                             std::to_string(config_.data.max_frames) + " (sequences too short?)");
  if (config_.train.validate && !manifest.val.empty()) val_ = std::make_unique<TrainData>(manifest, "val", stats_, config_);
}

void Run::restore(const std::string& path) {
  Checkpoint cp = read_checkpoint(path, params_);
  if (!cp.has_optimizer)
    throw CheckpointError(path + ": a packed model (weights only, no optimizer state) cannot resume a run; resume from "
                          "the run's checkpoints/step_*.h5");
  if (!all_finite(params_.values()))
    throw CheckpointError(path + ": holds non-finite weights; delete it to resume from the previous checkpoint");
  Config saved = parse_config_text(cp.config_toml, path + ":/config");
  saved.train = config_.train;
  saved.eval = config_.eval;
  if (to_toml(saved) != to_toml(config_))
    out_ << "warning: " << path << " was written with a different [model], [loss] or [data] config than "
         << options_.run_dir << "/config.toml; continuing with config.toml\n";
  state_ = cp.state;
  adam_->set_step_count(cp.state.global_step);
  for (const auto& [name, rng] : {std::pair<std::string, GslRandom*>{"shuffle", &shuffle_rng_}, {"rollout", &rollout_rng_}}) {
    const auto it = cp.state.rng.find(name);
    if (it == cp.state.rng.end()) throw CheckpointError(path + ": /state/rng/" + name + " is missing");
    rng->set_state(it->second, path + ":/state/rng/" + name);
  }
  const dataset::NormalisationStats saved_stats = stats_from_arrays(cp.stats, path);
  if (stats_to_arrays(saved_stats) != stats_to_arrays(stats_))
    out_ << "warning: " << (config_.data.stats.empty() ? config_.data.dataset + "/stats.h5" : config_.data.stats)
         << " differs from the statistics in " << path
         << "; continuing with the checkpoint's (the run's own) statistics\n";
  stats_ = saved_stats;
  summary_.best_val_error = state_.best_val_error;
  summary_.updates = state_.global_step;
}

void Run::start_from(const std::string& path) {
  const Checkpoint cp = read_checkpoint(path, params_);
  // A fine-tuning run is a new run: the optimizer and its schedule start over.
  for (auto moments : {params_.moment1(), params_.moment2()}) std::fill(moments.begin(), moments.end(), 0.0f);
  Config saved = parse_config_text(cp.config_toml, path + ":/config");
  saved.train = config_.train;
  saved.eval = config_.eval;
  saved.data = config_.data;
  saved.loss = config_.loss;
  if (to_toml(saved) != to_toml(config_))
    out_ << "warning: " << path << " was trained with another [model] config than this run's; the weights fit its "
         << "layout, but its radii or options differ\n";
  // The weights expect inputs normalised as they were trained.
  stats_ = stats_from_arrays(cp.stats, path);
  out_ << "starting from the weights of " << path << " (" << cp.state.global_step << " updates)\n";
  metric({{"event", "init_from"}, {"checkpoint", path}, {"updates", cp.state.global_step}});
}

void Run::save(const std::string& path) {
  if (!all_finite(params_.values()) || !all_finite(params_.moment1()) || !all_finite(params_.moment2()))
    throw TrainingStopped(path + ": not written: the parameters or Adam moments hold non-finite values (the updates "
                          "diverged); stopped. " + divergence_advice(options_.run_dir));
  Checkpoint cp;
  cp.config_toml = to_toml(config_);
  cp.state = state_;
  cp.state.global_step = adam_->step_count();
  // Mid-epoch the shuffle generator is saved as of the epoch's start (the order is
  // regenerated on resume); at an epoch boundary as it is now.
  cp.state.rng["shuffle"] = state_.position == 0 ? shuffle_rng_.state() : shuffle_at_epoch_start_;
  cp.state.rng["rollout"] = rollout_rng_.state();
  cp.stats = stats_to_arrays(stats_);
  if (writer()) write_checkpoint(path, params_, cp);
  summary_.last_checkpoint = path;
}

void Run::save_step_checkpoint() {
  if (writer()) fs::create_directories(fs::path(options_.run_dir) / "checkpoints");
  const int64_t batches = state_.epoch * batches_per_epoch_ +
                          (state_.position + config_.train.batch_size - 1) / config_.train.batch_size;
  save(checkpoint_path(options_.run_dir, batches));
  if (writer()) prune_checkpoints(options_.run_dir, config_.train.keep_checkpoints);
}

TrainSummary Run::execute() {
  const TrainConfig& tc = config_.train;
  if (tc.threads > 0) omp_set_num_threads(tc.threads);
  // The ops own the threads; Eigen's own GEMM threads, which it starts when a step runs outside
  // the per-sample parallel loop (batch 1), contended with them and halved the speed.
  Eigen::setNbThreads(1);
  threads_ = std::max(1, omp_get_max_threads());
  std::optional<RunLock> lock;
  if (writer()) {
    fs::create_directories(options_.run_dir);
    lock.emplace(options_.run_dir);  // before anything is read or written there
    if (!options_.resume && holds_run(options_.run_dir))
      throw std::runtime_error(options_.run_dir + " already holds a run; continue it with `layersnet train --resume " +
                               options_.run_dir + "` or choose another --run directory");
  }
  // Refuses to start without stats.h5, or with one not made from the training split, and says
  // that `layersnet prepare DATASET` makes it. A resumed run keeps its checkpoint's statistics
  // (restore() warns when the data set's differ), so only a fresh run needs them to match.
  // data.stats names a file on purpose, so it is used with a note instead of refused.
  std::string stats_note;
  stats_ = dataset::load_training_stats(dataset::read_manifest(config_.data.dataset), config_.data.stats,
                                        /*require_training_split=*/!options_.resume, &stats_note);
  if (!stats_note.empty() && !options_.resume) out_ << "note: " << stats_note << "\n";
  if (writer()) io::write_file_atomic((fs::path(options_.run_dir) / "config.toml").string(), to_toml(config_));
  for (const auto& w : config_warnings(config_)) out_ << "warning: " << w << "\n";

  model::register_params(params_, config_.model);
  model::init_params(params_, config_.model, static_cast<uint64_t>(tc.seed));
  adam_ = std::make_unique<ad::Adam<float>>(
      params_, ad::AdamOptions{tc.learning_rate, tc.adam_beta1, tc.adam_beta2, tc.adam_eps, 0.0});
  std::string resumed_from;
  if (!options_.resume && !tc.init_from.empty()) start_from(tc.init_from);
  if (options_.resume && !writer()) {
    // Rank 0 picks the checkpoint (setting damaged ones aside); the others read the same one.
    resumed_from = ranks_.broadcast("");
    if (!resumed_from.empty()) restore(resumed_from);
    else if (!tc.init_from.empty()) start_from(tc.init_from);
  } else if (options_.resume) {
    const auto checkpoints = list_checkpoints(options_.run_dir);
    if (checkpoints.empty()) {
      out_ << options_.run_dir << ": no checkpoint yet; the run starts from its beginning\n";
      if (!tc.init_from.empty()) start_from(tc.init_from);
      metric({{"event", "resume"}, {"checkpoint", nullptr}});
    } else {
      // A damaged newest checkpoint (torn by a full disk, a changed byte) costs only the work
      // since the one before: it is set aside as <name>.damaged, the evidence kept.
      std::string reasons;
      for (auto it = checkpoints.rbegin(); it != checkpoints.rend() && resumed_from.empty(); ++it) {
        try {
          restore(*it);
          resumed_from = *it;
        } catch (const std::runtime_error& e) {
          reasons += std::string("\n  ") + e.what();
          std::error_code ec;
          fs::rename(*it, *it + ".damaged", ec);
          out_ << "warning: cannot resume from " << *it << ": " << e.what() << "\n  set aside as " << *it
               << ".damaged; trying the checkpoint before it\n";
          metric({{"event", "damaged_checkpoint"}, {"checkpoint", *it}});
        }
      }
      if (resumed_from.empty())
        throw CheckpointError(options_.run_dir + ": no intact checkpoint to resume from:" + reasons +
                              "\nstart a new run with another --run directory");
    }
    ranks_.broadcast(resumed_from);
  }
  open_data();  // after restore: samples are built with the run's own statistics
  batches_per_epoch_ = (train_->num_samples() + tc.batch_size - 1) / tc.batch_size;
  if (!resumed_from.empty()) {
    if (state_.position > train_->num_samples())
      throw CheckpointError(resumed_from + ": position " + std::to_string(state_.position) + " is beyond the " +
                            std::to_string(train_->num_samples()) + " samples of the train split (data set changed?)");
    out_ << "resuming " << resumed_from << ": epoch " << state_.epoch + 1 << ", sample " << state_.position << " of "
         << train_->num_samples() << ", " << state_.global_step << " updates\n";
    metric({{"event", "resume"}, {"checkpoint", resumed_from}, {"epoch", state_.epoch + 1}, {"position", state_.position}});
  }
  for (int s = 0; s < ranks_.local_count(tc.batch_size); ++s) {
    slots_.push_back(std::make_unique<ad::ParamStore<float>>());
    model::register_params(*slots_.back(), config_.model);
  }
  for (int t = 0; t < threads_; ++t) tapes_.push_back(std::make_unique<ad::Tape<float>>());
  out_ << "training " << train_->num_samples() << " samples/epoch (" << train_->ids().size() << " sequences), "
       << batches_per_epoch_ << " batches of " << tc.batch_size << ", " << tc.epochs << " epochs, " << threads_
       << " threads" << (ranks_.distributed() ? " per rank, " + std::to_string(ranks_.size()) + " ranks" : std::string())
       << ", " << params_.total_size() << " parameter slots -> " << options_.run_dir << "\n";

  // max_steps counts every batch of the run, those before a resume too.
  batches_before_ = state_.epoch * batches_per_epoch_ + (state_.position + tc.batch_size - 1) / tc.batch_size;
  window_start_ = Clock::now();
  while (state_.epoch < tc.epochs) {
    if (step_cap_reached()) break;
    run_epoch(static_cast<int>(state_.epoch));
  }
  // A max_steps stop inside an epoch keeps its work: a checkpoint of where it stopped, from
  // which --resume continues (an epoch end has written its own).
  if (state_.epoch < tc.epochs && state_.position > 0) {
    const int64_t batches = state_.epoch * batches_per_epoch_ + (state_.position + tc.batch_size - 1) / tc.batch_size;
    if (!fs::exists(checkpoint_path(options_.run_dir, batches))) save_step_checkpoint();
  }
  summary_.updates = adam_->step_count();
  summary_.samples_per_second = total_wall_s_ > 0 ? static_cast<double>(total_samples_) / total_wall_s_ : 0;
  metric({{"event", "stop"},
          {"updates", summary_.updates},
          {"epoch", state_.epoch},
          {"samples_per_s", json_number(summary_.samples_per_second)}});
  return summary_;
}

void Run::run_epoch(int epoch) {
  const TrainConfig& tc = config_.train;
  adam_->set_lr(learning_rate_at(tc, epoch));
  const int ngs = rollout_steps_at(tc, epoch);
  // The order of the epoch: regenerated from the saved generator state on resume.
  shuffle_at_epoch_start_ = shuffle_rng_.state();
  std::vector<int64_t> order(static_cast<std::size_t>(train_->num_samples()));
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int64_t>(i);
  shuffle_rng_.shuffle(order);
  while (state_.position < train_->num_samples()) {
    if (!run_batch(epoch, ngs, order)) return;
    const int64_t done = state_.epoch * batches_per_epoch_ +
                         (state_.position + tc.batch_size - 1) / tc.batch_size;
    if (state_.position < train_->num_samples() && tc.checkpoint_every > 0 && done % tc.checkpoint_every == 0)
      save_step_checkpoint();
  }
  const double val = validate();
  state_.epoch = epoch + 1;
  state_.position = 0;
  bool best = false;
  if (val >= 0) {
    summary_.last_val_error = val;
    best = state_.best_val_error < 0 || val < state_.best_val_error;
    if (best) state_.best_val_error = val;
    summary_.best_val_error = state_.best_val_error;
    const bool by_rollout = config_.train.val_rollout_frames > 0;
    out_ << "epoch " << epoch + 1 << " validation: " << (by_rollout ? "rollout" : "one-step") << " error " << val
         << " (best " << state_.best_val_error << ")\n";
    metric({{"event", "val"},
            {"epoch", epoch + 1},
            {"step", adam_->step_count()},
            {by_rollout ? "rollout_error" : "one_step_error", json_number(val)},
            {"best", best}});
  }
  // best.h5 first: a kill between the two writes resumes from the previous checkpoint and
  // writes both again.
  if (best) save(best_checkpoint_path(options_.run_dir));
  if (config_.train.epoch_checkpoints || state_.epoch == config_.train.epochs) save_step_checkpoint();
}

bool Run::run_batch(int epoch, int ngs, const std::vector<int64_t>& order) {
  const TrainConfig& tc = config_.train;
  if (step_cap_reached()) return false;
  const auto t0 = Clock::now();
  const int64_t begin = state_.position;
  const int nb = static_cast<int>(std::min<int64_t>(tc.batch_size, train_->num_samples() - begin));
  const int nl = ranks_.local_count(nb);  // this rank's samples: i = rank, rank + R, ...
  // Draws on this thread in sample order, for the whole batch on every rank (the generators
  // stay in step); file reads only of this rank's samples (HDF5 is not thread-safe).
  std::vector<SampleRef> refs(static_cast<std::size_t>(nb));
  std::vector<int> self_fed(static_cast<std::size_t>(nb));
  std::vector<Window> windows;
  windows.reserve(static_cast<std::size_t>(nl));
  for (int i = 0; i < nb; ++i) {
    const SampleRef r = train_->samples()[static_cast<std::size_t>(order[static_cast<std::size_t>(begin + i)])];
    refs[static_cast<std::size_t>(i)] = r;
    const int drawn = rollout_rng_.uniform_int_inclusive(ngs);
    const int n = std::min(drawn, r.t - train_->first_t(r.sequence));  // no rollout before the first sample frame
    self_fed[static_cast<std::size_t>(i)] = n;
    std::vector<float> noise;
    if (tc.input_noise > 0) {  // drawn here, in sample order: the same numbers for any thread or rank count
      noise.resize(static_cast<std::size_t>(train_->garment_vertices(r.sequence)) * 3);
      for (float& e : noise) e = static_cast<float>(gsl_ran_gaussian(rollout_rng_.get(), tc.input_noise));
    }
    if (!ranks_.owns(i)) continue;
    windows.push_back(train_->read_window(r.sequence, r.t - n, r.t));
    windows.back().input_noise = std::move(noise);
  }
  for (int j = 0; j < nl; ++j) {
    auto dst = slots_[static_cast<std::size_t>(j)]->values();
    std::copy(params_.values().begin(), params_.values().end(), dst.begin());
  }
  const auto t1 = Clock::now();
  const PhysicsStep physics = physics_step_at(config_.physics, adam_->step_count());
  std::vector<SampleOutcome> local(static_cast<std::size_t>(nl));
  std::vector<std::string> errors(static_cast<std::size_t>(nl));
  // One sample per iteration; kernels inside run single-threaded (no nested parallelism),
  // a lone sample keeps the threads for its kernels.
#pragma omp parallel for schedule(dynamic, 1) if (nl > 1)
  for (int j = 0; j < nl; ++j) {
    try {
      const auto k = static_cast<std::size_t>(j);
      const int i = ranks_.rank() + j * ranks_.size();
      local[k] = train_sample(*train_, windows[k], refs[static_cast<std::size_t>(i)].t,
                              self_fed[static_cast<std::size_t>(i)], config_,
                              *tapes_[static_cast<std::size_t>(omp_get_thread_num())], *slots_[k], physics);
    } catch (const std::exception& e) {
      errors[static_cast<std::size_t>(j)] = e.what();
    }
  }
  for (const auto& e : errors)
    if (!e.empty()) throw std::runtime_error(e);
  const auto t2 = Clock::now();
  // Mean gradient, summed in sample order (across ranks too: bit-identical to one process),
  // and every sample's outcome.
  std::vector<std::span<const float>> grads;
  for (int j = 0; j < nl; ++j) grads.push_back(slots_[static_cast<std::size_t>(j)]->grads());
  auto g = params_.grads();
  const int64_t sent = ranks_.mean_in_sample_order(g, grads, nb);
  const std::vector<SampleOutcome> outcomes = gather_outcomes(ranks_, local, nb);
  const auto t3r = Clock::now();
  window_reduce_s_ += seconds(t2, t3r);
  summary_.reduce_seconds += seconds(t2, t3r);
  window_sent_bytes_ += sent;
  summary_.sent_bytes += sent;
  if (options_.after_gradients) options_.after_gradients(summary_.batches, params_);
  LossParts mean;
  bool finite = true;
  for (const auto& o : outcomes) {
    mean += o.loss.scaled(1.0 / nb);
    finite = finite && o.loss_finite && o.grad_finite;
  }
  const double norm = ad::grad_norm(params_);
  finite = finite && std::isfinite(norm);
  ++summary_.batches;
  state_.position = begin + nb;
  if (!finite) {
    ++summary_.skipped;
    ++state_.nonfinite_in_row;
    std::ostringstream samples;
    nlohmann::ordered_json records = nlohmann::ordered_json::array();
    for (int i = 0; i < nb; ++i) {
      const auto k = static_cast<std::size_t>(i);
      const auto& id = train_->ids()[static_cast<std::size_t>(refs[k].sequence)];
      samples << (i ? ", " : "") << id << " t=" << refs[k].t << " self-fed " << self_fed[k] << " loss "
              << outcomes[k].loss.total << (outcomes[k].grad_finite ? "" : " (non-finite gradient)");
      records.push_back({{"sequence", id},
                         {"t", refs[k].t},
                         {"self_fed", self_fed[k]},
                         {"loss", json_number(outcomes[k].loss.total)},
                         {"grad_finite", outcomes[k].grad_finite}});
    }
    out_ << "epoch " << epoch + 1 << " batch " << summary_.batches << ": non-finite loss or gradient, update skipped ("
         << state_.nonfinite_in_row << " in a row); samples: " << samples.str() << "\n";
    metric({{"event", "nonfinite"},
            {"epoch", epoch + 1},
            {"in_row", state_.nonfinite_in_row},
            {"grad_norm", json_number(norm)},
            {"samples", records}});
    if (state_.nonfinite_in_row >= tc.max_nonfinite_in_row) {
      throw TrainingStopped(std::to_string(state_.nonfinite_in_row) +
                            " updates in a row had a non-finite loss or gradient (train.max_nonfinite_in_row = " +
                            std::to_string(tc.max_nonfinite_in_row) + "); stopped. " +
                            divergence_advice(options_.run_dir));
    }
  } else {
    state_.nonfinite_in_row = 0;
    if (tc.grad_clip > 0 && norm > tc.grad_clip) {
      const float s = static_cast<float>(tc.grad_clip / norm);
      for (float& x : g) x *= s;
    }
    adam_->step();
    if (summary_.first_loss < 0) summary_.first_loss = mean.total;
    summary_.last_loss = mean.total;
    window_loss_ += mean;
    window_grad_norm_ += norm;
    ++window_batches_;
  }
  const auto t3 = Clock::now();
  window_samples_ += nb;
  window_data_s_ += seconds(t0, t1);
  window_optim_s_ += seconds(t3r, t3);
  window_wall_s_ += seconds(t0, t3);
  for (const auto& o : outcomes) window_build_s_ += o.build_seconds, window_model_s_ += o.model_seconds;
  total_wall_s_ += seconds(t0, t3);
  total_samples_ += nb;
  int64_t steps = 0;
  for (const int n : self_fed) steps += n;
  eta_.add_batch(seconds(t0, t3), nb, steps);
  summary_.wall_seconds += seconds(t0, t3);
  summary_.read_seconds += seconds(t0, t1);
  summary_.optimizer_seconds += seconds(t3r, t3);
  for (const auto& o : outcomes) summary_.build_seconds += o.build_seconds, summary_.model_seconds += o.model_seconds;
  if (summary_.batches % tc.log_every == 0 || state_.position >= train_->num_samples()) log_progress(epoch);
  return true;
}

void Run::log_progress(int epoch) {
  const TrainConfig& tc = config_.train;
  const double rate = window_wall_s_ > 0 ? static_cast<double>(window_samples_) / window_wall_s_ : 0;
  // Later epochs run longer self-fed rollouts: their cost comes from the fitted cost per step.
  std::vector<int> later_steps;
  for (int e = epoch + 1; e < tc.epochs; ++e) later_steps.push_back(rollout_steps_at(tc, e));
  const double eta = eta_.remaining_seconds(train_->num_samples() - state_.position, rollout_steps_at(tc, epoch),
                                            train_->num_samples(), later_steps);
  const LossParts loss = window_batches_ > 0 ? window_loss_.scaled(1.0 / static_cast<double>(window_batches_)) : LossParts{};
  const LossParts weighted = loss.weighted(config_.loss);
  // The penalty's floor is a constant Σ(d − c) (312 at the default sizes) that would hide every
  // other term: show how far above it the maps are.
  const double orth_floor = config_.loss.orthogonality != 0 ? model::orthogonality_floor(config_.model) : 0.0;
  const double orth_excess = window_batches_ > 0 ? loss.orthogonality - orth_floor : 0.0;
  // Thread-seconds outside the model (reading, sample building, optimizer) over all.
  const double outside = window_data_s_ + window_build_s_ + window_optim_s_ + window_reduce_s_;
  const double share = outside + window_model_s_ > 0 ? outside / (outside + window_model_s_) : 0;
  char line[512];
  std::snprintf(line, sizeof line,
                "epoch %d/%d  step %lld  sample %lld/%lld  %.2f samples/s  ETA %s  lr %.3g  loss above floor %.5g "
                "(vertex %.4g patch %.4g normal %.4g body %.4g layer %.4g orth excess %.4g strain %.4g)  outside model %.0f%%",
                epoch + 1, tc.epochs, static_cast<long long>(adam_->step_count()), static_cast<long long>(state_.position),
                static_cast<long long>(train_->num_samples()), rate, duration_text(eta).c_str(),
                learning_rate_at(tc, epoch), loss.total - config_.loss.orthogonality * orth_floor, loss.vertex, loss.patch, loss.normal, loss.collision_body,
                loss.collision_layer, orth_excess, loss.edge_strain, 100 * share);
  out_ << line;
  if (config_.physics.weight > 0) out_ << "  physics " << loss.physics << " (weighted " << loss.physics_weighted << ")";
  out_ << std::endl;
  metric({{"event", "train"},
          {"epoch", epoch + 1},
          {"step", adam_->step_count()},
          {"batch", summary_.batches},
          {"position", state_.position},
          {"lr", json_number(learning_rate_at(tc, epoch))},
          {"rollout_max", rollout_steps_at(tc, epoch)},
          {"loss", json_parts(loss, orth_excess)},
          {"loss_weighted", json_parts(weighted, config_.loss.orthogonality * orth_excess)},
          {"grad_norm", json_number(window_batches_ > 0 ? window_grad_norm_ / static_cast<double>(window_batches_) : 0)},
          {"samples_per_s", json_number(rate)},
          {"eta_s", json_number(eta)},
          {"threads", threads_},
          {"seconds",
           {{"wall", json_number(window_wall_s_)},
            {"read", json_number(window_data_s_)},
            {"build", json_number(window_build_s_)},
            {"model", json_number(window_model_s_)},
            {"optimizer", json_number(window_optim_s_)},
            {"reduce", json_number(window_reduce_s_)}}},
          {"share_outside_model", json_number(share)},
          {"ranks", ranks_.size()},
          {"sent_bytes", window_sent_bytes_}});
  window_loss_ = {};
  window_batches_ = window_samples_ = 0;
  window_grad_norm_ = window_data_s_ = window_build_s_ = window_model_s_ = window_optim_s_ = window_wall_s_ = 0;
  window_reduce_s_ = 0;
  window_sent_bytes_ = 0;
}

// sum + score(0, tape) + ... + score(m − 1, tape). This rank scores its items k (k mod R =
// rank, each read first by read(k) on this thread) on the OpenMP threads, each on its own tape
// (tapes[thread]); the scores of all ranks are gathered and added in index order, so the sum
// does not depend on the thread or rank count. The first error (by index) is rethrown.
template <class Read, class Score>
double sum_in_parallel(double sum, int m, const Ranks& ranks, const std::vector<std::unique_ptr<ad::Tape<float>>>& tapes,
                       Read&& read, Score&& score) {
  const int ml = ranks.local_count(m);
  for (int j = 0; j < ml; ++j) read(static_cast<std::size_t>(ranks.rank() + j * ranks.size()));
  std::vector<double> values(static_cast<std::size_t>(ml));
  std::vector<std::string> errors(static_cast<std::size_t>(ml));
#pragma omp parallel for schedule(dynamic, 1) if (ml > 1)
  for (int j = 0; j < ml; ++j) {
    try {
      values[static_cast<std::size_t>(j)] = score(static_cast<std::size_t>(ranks.rank() + j * ranks.size()),
                                                  *tapes[static_cast<std::size_t>(omp_get_thread_num())]);
    } catch (const std::exception& e) {
      errors[static_cast<std::size_t>(j)] = e.what();
    }
  }
  for (const auto& e : errors)
    if (!e.empty()) throw std::runtime_error(e);
  for (double v : ranks.gather_items(values, m, 1)) sum += v;
  return sum;
}

double Run::validate() {
  if (!val_ || val_->num_samples() == 0) return -1;
  if (config_.train.val_rollout_frames > 0) return validate_rollouts();
  const auto start = Clock::now();
  // Evenly spaced subset when val_samples limits it (deterministic, no generator).
  const int64_t total = val_->num_samples();
  const int64_t n = config_.train.val_samples > 0 ? std::min<int64_t>(config_.train.val_samples, total) : total;
  std::vector<int64_t> picks(static_cast<std::size_t>(n));
  for (int64_t i = 0; i < n; ++i) picks[static_cast<std::size_t>(i)] = i * total / n;
  double sum = 0;
  const int64_t chunk = 4 * threads_;
  for (int64_t b = 0; b < n; b += chunk) {
    const int m = static_cast<int>(std::min(chunk, n - b));
    std::vector<Window> windows(static_cast<std::size_t>(m));
    std::vector<int> ts(static_cast<std::size_t>(m));
    auto read = [&](std::size_t k) {
      const SampleRef r = val_->samples()[static_cast<std::size_t>(picks[static_cast<std::size_t>(b) + k])];
      windows[k] = val_->read_window(r.sequence, r.t, r.t);
      ts[k] = r.t;
    };
    sum = sum_in_parallel(sum, m, ranks_, tapes_, read, [&](std::size_t k, ad::Tape<float>& tape) {
      return one_step_error(*val_, windows[k], ts[k], config_, tape, params_);
    });
  }
  out_ << "validation on " << n << " samples took " << duration_text(seconds(start, Clock::now())) << "\n";
  return sum / static_cast<double>(n);
}

double Run::validate_rollouts() {
  const auto start = Clock::now();
  const int count = static_cast<int>(val_->ids().size());
  std::vector<int> last_t(static_cast<std::size_t>(count), -1);
  for (const SampleRef& r : val_->samples())
    last_t[static_cast<std::size_t>(r.sequence)] = std::max(last_t[static_cast<std::size_t>(r.sequence)], r.t);
  std::vector<int> sequences, t0, steps;
  for (int i = 0; i < count; ++i) {
    if (last_t[static_cast<std::size_t>(i)] < 0) continue;
    const int first = val_->rollout_start(i);
    sequences.push_back(i);
    t0.push_back(first);
    steps.push_back(std::min(config_.train.val_rollout_frames, last_t[static_cast<std::size_t>(i)] - first + 1));
  }
  const int m = static_cast<int>(sequences.size());
  std::vector<Window> windows(static_cast<std::size_t>(m));
  auto read = [&](std::size_t k) { windows[k] = val_->read_window(sequences[k], t0[k], t0[k] + steps[k] - 1); };
  const double sum = sum_in_parallel(0.0, m, ranks_, tapes_, read, [&](std::size_t k, ad::Tape<float>& tape) {
    return rollout_error(*val_, windows[k], t0[k], steps[k], config_, tape, params_);
  });
  out_ << "validation: rollouts of up to " << config_.train.val_rollout_frames << " frames on " << m
       << " sequences took " << duration_text(seconds(start, Clock::now())) << "\n";
  return m > 0 ? sum / m : -1;
}

}  // namespace

TrainSummary train(const Config& config, const TrainOptions& options) {
  if (options.run_dir.empty()) throw std::runtime_error("train: no run directory given (--run DIR)");
  const Ranks& ranks = Ranks::world();
  Run run(config, options);
  if (!ranks.distributed()) return run.execute();
  try {
    return run.execute();
  } catch (const TrainingStopped&) {
    throw;  // decided on gathered values: every rank stops at the same update, rank 0 reports
  } catch (const std::exception& e) {
    // A failure of one rank (a bad file, a write error) would leave the others waiting in the
    // next collective: end the whole job.
    ranks.abort_job(e.what(), 1);
  }
}

}  // namespace layersnet
