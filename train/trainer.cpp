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
#include <span>
#include <chrono>
#include <cmath>
#include <concepts>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <iostream>
#include <memory>
#include <numeric>
#include <optional>
#include <sstream>

namespace layersnet {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double learning_rate_at(const TrainConfig& train, int epoch, int64_t updates_done) {
  // lr_decay_epochs are 1-based epochs after which the rate drops (official step policy).
  double lr = train.learning_rate;
  for (int d : train.lr_decay_epochs)
    if (d <= epoch) lr *= train.lr_gamma;
  // Adam's first steps move every weight by about lr whatever its gradient: ramp them.
  if (train.lr_warmup_updates > 0 && updates_done < train.lr_warmup_updates)
    lr *= static_cast<double>(updates_done + 1) / static_cast<double>(train.lr_warmup_updates);
  return lr;
}

int rollout_steps_at(const TrainConfig& train, int epoch) {
  if (train.rollout_steps.empty()) return 0;
  return train.rollout_steps[std::min(static_cast<std::size_t>(epoch), train.rollout_steps.size() - 1)];
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
  std::vector<SampleOutcome> out(all.size() / kWidth);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double* v = all.data() + i * kWidth;
    SampleOutcome& o = out[i];
    o.loss = {v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[12], v[13]};
    o.loss_finite = v[8] != 0;
    o.grad_finite = v[9] != 0;
    o.build_seconds = v[10];
    o.model_seconds = v[11];
  }
  return out;
}

// v[i] for the int and int64_t indices the trainer counts samples and sequences with.
template <class Vector>
auto& element(Vector& v, std::integral auto i) {
  return v[static_cast<std::size_t>(i)];
}

// The j-th of this rank's items (samples of a batch, validation items): item rank + j·R.
std::size_t item_of_local(const Ranks& ranks, std::size_t j) {
  return static_cast<std::size_t>(ranks.rank()) + j * static_cast<std::size_t>(ranks.size());
}

// run(j, tape) for j = 0..m-1 on the OpenMP threads, one item per iteration, each thread on its
// own tape (tapes[thread]); the kernels inside run single-threaded (no nested parallelism), a lone
// item keeps the threads for its kernels. `start_order`, when given, is the order in which the
// items are handed out (a permutation of 0..m-1): the costliest first keeps threads from idling
// behind one long item at the end. The first error (by index) is rethrown.
template <class Work>
void for_each_on_threads(std::size_t m, const std::vector<std::unique_ptr<ad::Tape<float>>>& tapes, Work&& run,
                         const std::vector<std::size_t>& start_order = {}) {
  std::vector<std::string> errors(m);
#pragma omp parallel for schedule(dynamic, 1) if (m > 1)
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t j = start_order.empty() ? k : start_order[k];
    try {
      run(j, *tapes[static_cast<std::size_t>(omp_get_thread_num())]);
    } catch (const std::exception& e) {
      errors[j] = e.what();
    }
  }
  for (const auto& e : errors)
    if (!e.empty()) throw std::runtime_error(e);
}

// Seconds since the previous lap (or the start), and from the start to the last lap.
class Stopwatch {
 public:
  double lap() {
    const auto now = Clock::now();
    const double s = seconds(last_, now);
    last_ = now;
    return s;
  }
  double total() const { return seconds(start_, last_); }

 private:
  Clock::time_point start_ = Clock::now(), last_ = start_;
};

// What training batches cost. read (drawing, reading and the weight copies), reduce (summing the
// gradient, with R > 1 ranks the exchange) and optimizer (the finiteness check and the step) are
// wall time on the main thread, as is wall; build and model are summed over the threads.
struct Timing {
  int64_t samples = 0;
  double wall = 0, read = 0, build = 0, model = 0, optimizer = 0, reduce = 0;
  int64_t sent_bytes = 0;  // to other ranks (0 with one rank)

  Timing& operator+=(const Timing& o) {
    samples += o.samples;
    wall += o.wall, read += o.read, build += o.build, model += o.model, optimizer += o.optimizer, reduce += o.reduce;
    sent_bytes += o.sent_bytes;
    return *this;
  }
  double samples_per_second() const { return wall > 0 ? static_cast<double>(samples) / wall : 0; }
};

// Since the last progress line.
struct ProgressWindow {
  LossParts loss;        // summed over the applied updates
  double grad_norm = 0;  // summed over the applied updates
  int64_t updates = 0;   // applied updates (skipped ones have no finite loss)
  Timing cost;           // every batch, skipped ones too
};

// One batch: its samples as drawn on every rank, and the frames of this rank's.
struct Batch {
  int64_t begin = 0;                      // position of sample 0 in the epoch's order
  std::vector<SampleRef> refs;            // (n,) sequence and loss frame t of sample i
  std::vector<int> self_fed;              // (n,) T_n of sample i
  std::vector<std::vector<float>> noise;  // (n,) input noise of sample i, (garment vertices · 3,); empty when off
  std::vector<Window> windows;            // this rank's samples' frames, local j = sample rank + j·R

  int size() const { return static_cast<int>(refs.size()); }
  int64_t self_fed_steps() const {
    int64_t steps = 0;
    for (const int n : self_fed) steps += n;
    return steps;
  }
};

// The batch's mean loss and gradient norm, and whether the update may be applied.
struct BatchLoss {
  LossParts mean;
  double grad_norm = 0;
  bool finite = true;  // every sample's loss and gradient, and the norm
};

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
  void record_validation(double val, const std::string& when);
  bool run_batch(int epoch, int ngs, const std::vector<int64_t>& order);  // false: max_steps reached
  // The steps of run_batch, in order.
  Batch draw_batch(int ngs, const std::vector<int64_t>& order);
  void read_windows(Batch& batch);
  void replicate_weights();
  std::vector<SampleOutcome> train_samples(Batch& batch);
  std::vector<SampleOutcome> reduce_gradients(const std::vector<SampleOutcome>& local, int n, int64_t& sent_bytes);
  BatchLoss batch_loss(const std::vector<SampleOutcome>& outcomes) const;
  void apply_update(const BatchLoss& loss);
  void skip_update(int epoch, const Batch& batch, const std::vector<SampleOutcome>& outcomes, double grad_norm);
  void record(Timing cost, const Batch& batch, const std::vector<SampleOutcome>& outcomes);
  bool step_cap_reached() const {
    return config_.train.max_steps > 0 && batches_before_ + summary_.batches >= config_.train.max_steps;
  }
  double validate();
  double validate_rollouts();  // train.val_rollout_frames > 0
  // `averaged`: the moving average of the weights as the file's weights (best.h5), without /ema.
  void save(const std::string& path, bool averaged = false);
  // Moves the weights' average in after an update (train.ema_decay > 0).
  void update_average();
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
  std::vector<float> ema_;  // the weights' moving average (train.ema_decay > 0), else empty
  std::vector<std::unique_ptr<ad::ParamStore<float>>> slots_;  // one gradient buffer per local batch slot
  std::vector<std::unique_ptr<ad::Tape<float>>> tapes_;        // one per thread
  GslRandom shuffle_rng_, rollout_rng_;
  std::vector<uint8_t> shuffle_at_epoch_start_;
  TrainingState state_;
  int64_t batches_per_epoch_ = 0;
  int64_t epoch_samples_ = 0;  // samples per epoch: the first ones of the epoch's shuffled order
  int64_t batches_before_ = 0;  // batches of the run before this process started (resume)
  TrainSummary summary_;
  ProgressWindow window_;  // since the last progress line
  Timing total_;           // every batch of this process
  TrainingEta eta_;        // the run's time left, from the cost of each batch's samples and self-fed steps
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
                             std::to_string(config_.data.max_frames) +
                             (config_.data.after_ramp ? " after each file's ramp (data.after_ramp = true)" : "") +
                             " (sequences too short?)");
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
  ema_ = config_.train.ema_decay > 0 ? cp.ema : std::vector<float>{};
  if (config_.train.ema_decay > 0 && ema_.empty())
    out_ << "warning: " << path << " holds no average of the weights (train.ema_decay was 0 when it was written); "
         << "the average starts from its weights\n";
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
  // A fine-tuning run is a new run: the optimizer and its schedule start over (moments zeroed).
  const WeightsByName theirs = read_weights_by_name(path, params_);
  const Checkpoint& cp = theirs.checkpoint;
  if (!same_model_section(theirs.config, config_))
    out_ << "warning: " << path << " was trained with another [model] config than this run's; its weights are "
         << "copied by name, but its radii or options differ\n";
  // The weights expect inputs normalised as they were trained.
  stats_ = stats_from_arrays(cp.stats, path);
  out_ << "starting from the weights of " << path << " (" << cp.state.global_step << " updates)\n";
  for (const auto& name : theirs.added) out_ << "  " << name << ": not in that checkpoint, starts at zero\n";
  metric({{"event", "init_from"}, {"checkpoint", path}, {"updates", cp.state.global_step}});
}

// Swaps `other` into the parameter values for the scope (validating or writing the average).
class SwappedWeights {
 public:
  SwappedWeights(std::span<float> values, std::vector<float>& other) : values_(values), other_(other) {
    if (!other_.empty()) std::swap_ranges(values_.begin(), values_.end(), other_.begin());
  }
  ~SwappedWeights() {
    if (!other_.empty()) std::swap_ranges(values_.begin(), values_.end(), other_.begin());
  }
  SwappedWeights(const SwappedWeights&) = delete;
  SwappedWeights& operator=(const SwappedWeights&) = delete;

 private:
  std::span<float> values_;
  std::vector<float>& other_;
};

void Run::update_average() {
  if (ema_.empty()) return;
  const float d = static_cast<float>(config_.train.ema_decay);
  const std::span<const float> w = params_.values();
  for (std::size_t i = 0; i < ema_.size(); ++i) ema_[i] = d * ema_[i] + (1.0f - d) * w[i];
}

void Run::save(const std::string& path, bool averaged) {
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
  std::optional<SwappedWeights> average_as_weights;
  if (averaged) average_as_weights.emplace(params_.values(), ema_);  // a no-op without an average
  else cp.ema = ema_;
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
  if (tc.ema_decay > 0 && ema_.empty()) ema_.assign(params_.values().begin(), params_.values().end());
  open_data();  // after restore: samples are built with the run's own statistics
  epoch_samples_ = tc.epoch_samples > 0 ? std::min<int64_t>(tc.epoch_samples, train_->num_samples()) : train_->num_samples();
  batches_per_epoch_ = (epoch_samples_ + tc.batch_size - 1) / tc.batch_size;
  if (!resumed_from.empty()) {
    if (state_.position > epoch_samples_)
      throw CheckpointError(resumed_from + ": position " + std::to_string(state_.position) + " is beyond the " +
                            std::to_string(epoch_samples_) + " samples of an epoch (data set or train.epoch_samples changed?)");
    out_ << "resuming " << resumed_from << ": epoch " << state_.epoch + 1 << ", sample " << state_.position << " of "
         << epoch_samples_ << ", " << state_.global_step << " updates\n";
    metric({{"event", "resume"}, {"checkpoint", resumed_from}, {"epoch", state_.epoch + 1}, {"position", state_.position}});
  }
  for (int s = 0; s < ranks_.local_count(tc.batch_size); ++s) {
    slots_.push_back(std::make_unique<ad::ParamStore<float>>());
    model::register_params(*slots_.back(), config_.model);
  }
  for (int t = 0; t < threads_; ++t) tapes_.push_back(std::make_unique<ad::Tape<float>>());
  out_ << "training " << epoch_samples_ << " samples/epoch"
       << (epoch_samples_ < train_->num_samples() ? " of " + std::to_string(train_->num_samples()) : std::string())
       << " (" << train_->ids().size() << " sequences), "
       << batches_per_epoch_ << " batches of " << tc.batch_size << ", " << tc.epochs << " epochs, " << threads_
       << " threads" << (ranks_.distributed() ? " per rank, " + std::to_string(ranks_.size()) + " ranks" : std::string())
       << ", " << params_.total_size() << " parameter slots -> " << options_.run_dir << "\n";

  // max_steps counts every batch of the run, those before a resume too.
  batches_before_ = state_.epoch * batches_per_epoch_ + (state_.position + tc.batch_size - 1) / tc.batch_size;
  // The model before any update is a candidate too: its zero-initialised output layer predicts
  // the velocity base, which a strong base (the physics step) may leave unbeaten on validation.
  if (resumed_from.empty() && tc.validate_initial)
    record_validation(validate(), "before the first update,");
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
  summary_.samples_per_second = total_.samples_per_second();
  summary_.wall_seconds = total_.wall;
  summary_.read_seconds = total_.read;
  summary_.build_seconds = total_.build;
  summary_.model_seconds = total_.model;
  summary_.optimizer_seconds = total_.optimizer;
  summary_.reduce_seconds = total_.reduce;
  summary_.sent_bytes = total_.sent_bytes;
  metric({{"event", "stop"},
          {"updates", summary_.updates},
          {"epoch", state_.epoch},
          {"samples_per_s", json_number(summary_.samples_per_second)}});
  return summary_;
}

void Run::run_epoch(int epoch) {
  const TrainConfig& tc = config_.train;
  const int ngs = rollout_steps_at(tc, epoch);
  // The order of the epoch: regenerated from the saved generator state on resume.
  shuffle_at_epoch_start_ = shuffle_rng_.state();
  std::vector<int64_t> order(train_->samples().size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int64_t>(i);
  shuffle_rng_.shuffle(order);
  while (state_.position < epoch_samples_) {
    if (!run_batch(epoch, ngs, order)) return;
    const int64_t done = state_.epoch * batches_per_epoch_ +
                         (state_.position + tc.batch_size - 1) / tc.batch_size;
    if (state_.position < epoch_samples_ && tc.checkpoint_every > 0 && done % tc.checkpoint_every == 0)
      save_step_checkpoint();
  }
  const double val = validate();
  state_.epoch = epoch + 1;
  state_.position = 0;
  // best.h5 first: a kill between the two writes resumes from the previous checkpoint and
  // writes both again.
  record_validation(val, "epoch " + std::to_string(epoch + 1));
  if (config_.train.epoch_checkpoints || state_.epoch == config_.train.epochs) save_step_checkpoint();
}

// Keeps best.h5 when `val` (negative: no validation) is the lowest so far.
void Run::record_validation(double val, const std::string& when) {
  if (val < 0) return;
  summary_.last_val_error = val;
  const bool best = state_.best_val_error < 0 || val < state_.best_val_error;
  if (best) state_.best_val_error = val;
  summary_.best_val_error = state_.best_val_error;
  const bool by_rollout = config_.train.val_rollout_frames > 0;
  out_ << when << " validation" << (ema_.empty() ? "" : " of the weights' average") << ": "
       << (by_rollout ? "rollout" : "one-step") << " error " << val << " (best "
       << state_.best_val_error << ")\n";
  metric({{"event", "val"},
          {"epoch", state_.epoch},
          {"step", adam_->step_count()},
          {by_rollout ? "rollout_error" : "one_step_error", json_number(val)},
          {"best", best}});
  if (best) save(best_checkpoint_path(options_.run_dir), /*averaged=*/true);
}

// One update, as its steps: draw the batch, read this rank's frames, train its samples, reduce
// the gradients, then apply the update (or skip a non-finite one) and record what it cost.
bool Run::run_batch(int epoch, int ngs, const std::vector<int64_t>& order) {
  if (step_cap_reached()) return false;
  Stopwatch clock;
  Timing cost;
  Batch batch = draw_batch(ngs, order);
  read_windows(batch);
  replicate_weights();
  cost.read = clock.lap();
  const std::vector<SampleOutcome> local = train_samples(batch);
  clock.lap();  // the samples time their own building and model
  const std::vector<SampleOutcome> outcomes = reduce_gradients(local, batch.size(), cost.sent_bytes);
  cost.reduce = clock.lap();
  if (options_.after_gradients) options_.after_gradients(summary_.batches, params_);
  const BatchLoss loss = batch_loss(outcomes);
  ++summary_.batches;
  state_.position = batch.begin + batch.size();
  if (loss.finite) apply_update(loss);
  else skip_update(epoch, batch, outcomes, loss.grad_norm);
  cost.optimizer = clock.lap();
  cost.wall = clock.total();
  record(cost, batch, outcomes);
  if (summary_.batches % config_.train.log_every == 0 || state_.position >= epoch_samples_) log_progress(epoch);
  return true;
}

// The next batch_size samples of the epoch's order, each with T_n ~ U{0..ngs} (clipped so that
// no rollout starts before the sequence's first sample frame) and its input noise. Drawn on this
// thread in sample order for the whole batch on every rank: the generators stay in step, and the
// numbers are the same for any thread or rank count.
Batch Run::draw_batch(int ngs, const std::vector<int64_t>& order) {
  const TrainConfig& tc = config_.train;
  Batch batch;
  batch.begin = state_.position;
  const int64_t n = std::min<int64_t>(tc.batch_size, epoch_samples_ - batch.begin);
  for (int64_t i = batch.begin; i < batch.begin + n; ++i) {
    const SampleRef r = element(train_->samples(), element(order, i));
    const int drawn = rollout_rng_.uniform_int_inclusive(ngs);
    std::vector<float> noise;
    if (tc.input_noise > 0) {
      noise.resize(static_cast<std::size_t>(train_->garment_vertices(r.sequence)) * 3);
      for (float& e : noise) e = static_cast<float>(gsl_ran_gaussian(rollout_rng_.get(), tc.input_noise));
    }
    batch.refs.push_back(r);
    batch.self_fed.push_back(std::min(drawn, r.t - train_->first_t(r.sequence)));
    batch.noise.push_back(std::move(noise));
  }
  return batch;
}

// The frames of this rank's samples, t − T_n − 2 .. t + 1, read on this thread (HDF5 is not
// thread-safe), with their input noise.
void Run::read_windows(Batch& batch) {
  const std::size_t local = static_cast<std::size_t>(ranks_.local_count(batch.size()));
  for (std::size_t j = 0; j < local; ++j) {
    const std::size_t i = item_of_local(ranks_, j);
    const SampleRef r = batch.refs[i];
    batch.windows.push_back(train_->read_window(r.sequence, r.t - batch.self_fed[i], r.t));
    batch.windows.back().input_noise = std::move(batch.noise[i]);
  }
}

// Every local batch slot starts from the current weights (each gets its own gradient buffer).
void Run::replicate_weights() {
  for (auto& slot : slots_) {
    auto dst = slot->values();
    std::copy(params_.values().begin(), params_.values().end(), dst.begin());
  }
}

// This rank's samples on the threads, each into its own slot's gradient buffer.
std::vector<SampleOutcome> Run::train_samples(Batch& batch) {
  const PhysicsStep physics = physics_step_at(config_.physics, adam_->step_count());
  std::vector<SampleOutcome> local(batch.windows.size());
  // A sample costs about one model step per self-fed step, plus its trained step: longest first.
  std::vector<std::size_t> longest_first(local.size());
  std::iota(longest_first.begin(), longest_first.end(), std::size_t{0});
  std::stable_sort(longest_first.begin(), longest_first.end(), [&](std::size_t a, std::size_t b) {
    return batch.self_fed[item_of_local(ranks_, a)] > batch.self_fed[item_of_local(ranks_, b)];
  });
  for_each_on_threads(
      local.size(), tapes_,
      [&](std::size_t j, ad::Tape<float>& tape) {
        const std::size_t i = item_of_local(ranks_, j);
        local[j] = train_sample(*train_, batch.windows[j], batch.refs[i].t, batch.self_fed[i], config_, tape,
                                *slots_[j], physics);
      },
      longest_first);
  return local;
}

// params.grads() = the mean gradient of the n samples, summed in sample order (across ranks too:
// bit-identical to one process); returns every sample's outcome, in sample order, and the bytes
// this rank sent.
std::vector<SampleOutcome> Run::reduce_gradients(const std::vector<SampleOutcome>& local, int n, int64_t& sent_bytes) {
  std::vector<std::span<const float>> grads;
  for (std::size_t j = 0; j < local.size(); ++j) grads.push_back(slots_[j]->grads());
  sent_bytes = ranks_.mean_in_sample_order(params_.grads(), grads, n);
  return gather_outcomes(ranks_, local, n);
}

BatchLoss Run::batch_loss(const std::vector<SampleOutcome>& outcomes) const {
  BatchLoss loss;
  const double n = static_cast<double>(outcomes.size());
  for (const auto& o : outcomes) {
    loss.mean += o.loss.scaled(1.0 / n);
    loss.finite = loss.finite && o.loss_finite && o.grad_finite;
  }
  loss.grad_norm = ad::grad_norm(params_);
  loss.finite = loss.finite && std::isfinite(loss.grad_norm);
  return loss;
}

// Clips the gradient to train.grad_clip (when set), steps Adam and adds the loss to the window.
void Run::apply_update(const BatchLoss& loss) {
  const TrainConfig& tc = config_.train;
  state_.nonfinite_in_row = 0;
  if (tc.grad_clip > 0 && loss.grad_norm > tc.grad_clip) {
    const float s = static_cast<float>(tc.grad_clip / loss.grad_norm);
    for (float& x : params_.grads()) x *= s;
  }
  adam_->set_lr(learning_rate_at(tc, state_.epoch, adam_->step_count()));
  adam_->step();
  update_average();
  if (summary_.first_loss < 0) summary_.first_loss = loss.mean.total;
  summary_.last_loss = loss.mean.total;
  window_.loss += loss.mean;
  window_.grad_norm += loss.grad_norm;
  ++window_.updates;
}

// Logs the skipped update with its samples; stops the run after train.max_nonfinite_in_row in a row.
void Run::skip_update(int epoch, const Batch& batch, const std::vector<SampleOutcome>& outcomes, double grad_norm) {
  const TrainConfig& tc = config_.train;
  ++summary_.skipped;
  ++state_.nonfinite_in_row;
  std::ostringstream samples;
  nlohmann::ordered_json records = nlohmann::ordered_json::array();
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    const SampleRef r = batch.refs[i];
    const auto& id = element(train_->ids(), r.sequence);
    samples << (i ? ", " : "") << id << " t=" << r.t << " self-fed " << batch.self_fed[i] << " loss "
            << outcomes[i].loss.total << (outcomes[i].grad_finite ? "" : " (non-finite gradient)");
    records.push_back({{"sequence", id},
                       {"t", r.t},
                       {"self_fed", batch.self_fed[i]},
                       {"loss", json_number(outcomes[i].loss.total)},
                       {"grad_finite", outcomes[i].grad_finite}});
  }
  out_ << "epoch " << epoch + 1 << " batch " << summary_.batches << ": non-finite loss or gradient, update skipped ("
       << state_.nonfinite_in_row << " in a row); samples: " << samples.str() << "\n";
  metric({{"event", "nonfinite"},
          {"epoch", epoch + 1},
          {"in_row", state_.nonfinite_in_row},
          {"grad_norm", json_number(grad_norm)},
          {"samples", records}});
  if (state_.nonfinite_in_row >= tc.max_nonfinite_in_row) {
    throw TrainingStopped(std::to_string(state_.nonfinite_in_row) +
                          " updates in a row had a non-finite loss or gradient (train.max_nonfinite_in_row = " +
                          std::to_string(tc.max_nonfinite_in_row) + "); stopped. " +
                          divergence_advice(options_.run_dir));
  }
}

// One timing record per batch, added to the progress window and to the run's totals.
void Run::record(Timing cost, const Batch& batch, const std::vector<SampleOutcome>& outcomes) {
  cost.samples = batch.size();
  for (const auto& o : outcomes) cost.build += o.build_seconds, cost.model += o.model_seconds;
  window_.cost += cost;
  total_ += cost;
  eta_.add_batch(cost.wall, batch.size(), batch.self_fed_steps());
}

void Run::log_progress(int epoch) {
  const TrainConfig& tc = config_.train;
  const Timing& cost = window_.cost;
  const double rate = cost.samples_per_second();
  // Later epochs run longer self-fed rollouts: their cost comes from the fitted cost per step.
  std::vector<int> later_steps;
  for (int e = epoch + 1; e < tc.epochs; ++e) later_steps.push_back(rollout_steps_at(tc, e));
  const double eta = eta_.remaining_seconds(epoch_samples_ - state_.position, rollout_steps_at(tc, epoch),
                                            epoch_samples_, later_steps);
  const LossParts loss = window_.updates > 0 ? window_.loss.scaled(1.0 / static_cast<double>(window_.updates)) : LossParts{};
  const LossParts weighted = loss.weighted(config_.loss);
  // The penalty's floor is a constant Σ(d − c) (312 at the default sizes) that would hide every
  // other term: show how far above it the maps are.
  const double orth_floor = config_.loss.orthogonality != 0 ? model::orthogonality_floor(config_.model) : 0.0;
  const double orth_excess = window_.updates > 0 ? loss.orthogonality - orth_floor : 0.0;
  // Thread-seconds outside the model (reading, sample building, optimizer) over all.
  const double outside = cost.read + cost.build + cost.optimizer + cost.reduce;
  const double share = outside + cost.model > 0 ? outside / (outside + cost.model) : 0;
  char line[512];
  std::snprintf(line, sizeof line,
                "epoch %d/%d  step %lld  sample %lld/%lld  %.2f samples/s  ETA %s  lr %.3g  loss above floor %.5g "
                "(vertex %.4g patch %.4g normal %.4g body %.4g layer %.4g orth excess %.4g strain %.4g)  outside model %.0f%%",
                epoch + 1, tc.epochs, static_cast<long long>(adam_->step_count()), static_cast<long long>(state_.position),
                static_cast<long long>(epoch_samples_), rate, duration_text(eta).c_str(),
                adam_->options().lr, loss.total - config_.loss.orthogonality * orth_floor, loss.vertex, loss.patch, loss.normal, loss.collision_body,
                loss.collision_layer, orth_excess, loss.edge_strain, 100 * share);
  out_ << line;
  if (config_.physics.weight > 0) out_ << "  physics " << loss.physics << " (weighted " << loss.physics_weighted << ")";
  out_ << std::endl;
  metric({{"event", "train"},
          {"epoch", epoch + 1},
          {"step", adam_->step_count()},
          {"batch", summary_.batches},
          {"position", state_.position},
          {"lr", json_number(adam_->options().lr)},  // the last update's
          {"rollout_max", rollout_steps_at(tc, epoch)},
          {"loss", json_parts(loss, orth_excess)},
          {"loss_weighted", json_parts(weighted, config_.loss.orthogonality * orth_excess)},
          {"grad_norm", json_number(window_.updates > 0 ? window_.grad_norm / static_cast<double>(window_.updates) : 0)},
          {"samples_per_s", json_number(rate)},
          {"eta_s", json_number(eta)},
          {"threads", threads_},
          {"seconds",
           {{"wall", json_number(cost.wall)},
            {"read", json_number(cost.read)},
            {"build", json_number(cost.build)},
            {"model", json_number(cost.model)},
            {"optimizer", json_number(cost.optimizer)},
            {"reduce", json_number(cost.reduce)}}},
          {"share_outside_model", json_number(share)},
          {"ranks", ranks_.size()},
          {"sent_bytes", cost.sent_bytes}});
  window_ = {};
}

// sum + score(0, tape) + ... + score(m − 1, tape). This rank scores its items k (k mod R =
// rank, each read first by read(k) on this thread) on the OpenMP threads, each on its own tape;
// the scores of all ranks are gathered and added in index order, so the sum does not depend on
// the thread or rank count. The first error (by index) is rethrown.
template <class Read, class Score>
double sum_in_parallel(double sum, int m, const Ranks& ranks, const std::vector<std::unique_ptr<ad::Tape<float>>>& tapes,
                       Read&& read, Score&& score) {
  const std::size_t local = static_cast<std::size_t>(ranks.local_count(m));
  for (std::size_t j = 0; j < local; ++j) read(item_of_local(ranks, j));
  std::vector<double> values(local);
  for_each_on_threads(local, tapes, [&](std::size_t j, ad::Tape<float>& tape) {
    values[j] = score(item_of_local(ranks, j), tape);
  });
  for (double v : ranks.gather_items(values, m, 1)) sum += v;
  return sum;
}

double Run::validate() {
  if (!val_ || val_->num_samples() == 0) return -1;
  SwappedWeights averaged(params_.values(), ema_);  // validates the average when there is one
  if (config_.train.val_rollout_frames > 0) return validate_rollouts();
  const auto start = Clock::now();
  // Evenly spaced subset when val_samples limits it (deterministic, no generator).
  const int64_t total = val_->num_samples();
  const int64_t n = config_.train.val_samples > 0 ? std::min<int64_t>(config_.train.val_samples, total) : total;
  std::vector<int64_t> picks;
  for (int64_t i = 0; i < n; ++i) picks.push_back(i * total / n);
  double sum = 0;
  const int64_t chunk = 4 * threads_;
  for (int64_t b = 0; b < n; b += chunk) {
    const int m = static_cast<int>(std::min(chunk, n - b));
    std::vector<Window> windows(static_cast<std::size_t>(m));
    std::vector<int> ts(windows.size());
    auto read = [&](std::size_t k) {
      const SampleRef r = element(val_->samples(), element(picks, b + static_cast<int64_t>(k)));
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
  std::vector<int> last_t(val_->ids().size(), -1);  // per sequence
  for (const SampleRef& r : val_->samples()) {
    int& last = element(last_t, r.sequence);
    last = std::max(last, r.t);
  }
  std::vector<int> sequences, t0, steps;
  for (std::size_t i = 0; i < last_t.size(); ++i) {
    if (last_t[i] < 0) continue;
    const int sequence = static_cast<int>(i);
    const int first = val_->rollout_start(sequence);
    sequences.push_back(sequence);
    t0.push_back(first);
    steps.push_back(std::min(config_.train.val_rollout_frames, last_t[i] - first + 1));
  }
  const int m = static_cast<int>(sequences.size());
  std::vector<Window> windows(sequences.size());
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
