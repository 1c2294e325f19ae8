#include "train/train_data.h"

#include "dataset/garments.h"
#include "losses/physics_step.h"
#include "model/sample_input.h"

#include <algorithm>

namespace layersnet {

namespace {

// Calls set(x, i) for every coordinate x of the garments of frame f, i = its index in the
// layer-ordered (N·3,) row-major layout.
template <class Set>
void for_each_garment_coordinate(Window& w, int f, Set&& set) {
  int64_t row = 0;
  for (int g = 0; g < w.info->num_garments(); ++g) {
    const int n = w.info->garments[static_cast<std::size_t>(g)].num_vertices;
    auto rows = w.frames.garments[static_cast<std::size_t>(g)].middleRows(
        static_cast<Eigen::Index>(f - w.frames.first) * n, n);
    for (int v = 0; v < n; ++v, ++row)
      for (int c = 0; c < 3; ++c) set(rows(v, c), static_cast<std::size_t>(row * 3 + c));
  }
}

}  // namespace

void Window::set_garments_relative(int f, const float* relative) {
  const Eigen::Vector3f r = info->translation.row(f).transpose();
  for_each_garment_coordinate(*this, f, [&](float& x, std::size_t i) { x = relative[i] + r[static_cast<int>(i % 3)]; });
}

void Window::feed_back(int f, const float* relative) {
  if (!constraints) return set_garments_relative(f, relative);
  dataset::Points x = Eigen::Map<const dataset::Points>(relative, info->total_garment_vertices(), 3);
  x.rowwise() += info->translation.row(f);  // world, as set_garments_relative writes it
  dataset::Points before(x.rows(), 3);  // frame f - 1 as fed: the friction step needs its motion
  for_each_garment_coordinate(*this, f - 1, [&](float& v, std::size_t i) { before.data()[i] = v; });
  constraints->apply(frames.body_at(f, info->num_body_vertices), x, frames.body_at(f - 1, info->num_body_vertices), before);
  for_each_garment_coordinate(*this, f, [&](float& v, std::size_t i) { v = x.data()[i]; });
}

void Window::add_input_noise(int f) {
  if (input_noise.empty()) return;
  for_each_garment_coordinate(*this, f, [&](float& x, std::size_t i) { x += input_noise[i]; });
}

TrainData::TrainData(const dataset::DatasetManifest& manifest, const std::string& split,
                     const dataset::NormalisationStats& stats, const Config& config)
    : manifest_(manifest),
      split_(split),
      stats_(stats),
      sample_options_(model::sample_options_for(config.model)),
      model_(config.model),
      max_open_files_(std::max(config.data.cache_sequences, 1)),
      constraint_settings_(config.train.rollout_constraints ? std::optional<EvalConfig>(config.eval) : std::nullopt),
      file_ids_(manifest.split(split)),
      ids_(file_ids_),
      patch_size_(static_cast<float>(config.model.patch_size)) {
  const bool mirror = config.data.mirror && split == "train";
  const int n = static_cast<int>(file_ids_.size());
  if (mirror) {
    max_open_files_ *= 2;
    for (const std::string& id : file_ids_) ids_.push_back(id + " mirrored");
  }
  const dataset::FrameSelection selection = frame_selection_for(config.data);
  std::vector<std::shared_ptr<dataset::SequenceFile>> kept(static_cast<std::size_t>(n));
  std::vector<std::vector<int>> frames(static_cast<std::size_t>(n));
  for (int s = 0; s < n; ++s) {
    auto f = std::make_shared<dataset::SequenceFile>(manifest_.sequence_path(file_ids_[static_cast<std::size_t>(s)]));
    std::vector<int> ts = dataset::sample_frames(f->info().num_frames, selection);
    const int after_ramp = f->info().settled_frame() - 1;
    if (config.data.after_ramp && after_ramp >= 2) std::erase_if(ts, [&](int t) { return t < after_ramp; });
    first_t_.push_back(ts.empty() ? 0 : ts.front());
    rollout_start_.push_back(std::find(ts.begin(), ts.end(), after_ramp) != ts.end() ? after_ramp : first_t_.back());
    garment_vertices_.push_back(static_cast<int>(f->info().total_garment_vertices()));
    frames[static_cast<std::size_t>(s)] = std::move(ts);
    if (s < max_open_files_) kept[static_cast<std::size_t>(s)] = std::move(f);
  }
  const int sequences = static_cast<int>(ids_.size());
  for (int s = n; s < sequences; ++s) {  // mirror images: the same frames
    first_t_.push_back(first_t_[static_cast<std::size_t>(s - n)]);
    rollout_start_.push_back(rollout_start_[static_cast<std::size_t>(s - n)]);
    garment_vertices_.push_back(garment_vertices_[static_cast<std::size_t>(s - n)]);
  }
  for (int s = 0; s < sequences; ++s)
    for (int t : frames[static_cast<std::size_t>(s % std::max(n, 1))]) samples_.push_back({s, t});
  // The first cache_sequences sequences stay open with their structures (an image shares its
  // file's handle): a cache as large as the split then never reopens a file or rebuilds a
  // structure during training.
  for (int s = 0; s < std::min(sequences, max_open_files_); ++s) {
    auto& f = kept[static_cast<std::size_t>(s % n)];
    keep_open(s, f ? f : std::make_shared<dataset::SequenceFile>(manifest_.sequence_path(file_ids_[static_cast<std::size_t>(s % n)])));
  }
}

TrainData::OpenFile& TrainData::keep_open(int sequence, std::shared_ptr<dataset::SequenceFile> file) {
  ++reads_.files_opened;
  auto info = std::make_shared<const dataset::SequenceInfo>(mirrored(sequence) ? dataset::mirrored(file->info()) : file->info());
  std::shared_ptr<const ClothConstraints> constraints;
  if (constraint_settings_) {
    dataset::FrameWindow frame0 = file->read_frames(0, 1);
    if (mirrored(sequence)) dataset::mirror_positions(frame0);
    const dataset::Points first = dataset::garments_at(*info, frame0, 0);
    constraints = std::make_shared<const ClothConstraints>(*info, dataset::rest_shapes(*info, first),
                                                           frame0.body_at(0, info->num_body_vertices), first, *constraint_settings_);
  }
  auto structure = dataset::build_structure(*info, patch_size_);
  files_.push_front({sequence, std::move(file), std::move(info), std::move(constraints), std::move(structure)});
  while (static_cast<int>(files_.size()) > max_open_files_) files_.pop_back();
  return files_.front();
}

TrainData::OpenFile& TrainData::open(int sequence) {
  for (auto it = files_.begin(); it != files_.end(); ++it)
    if (it->sequence == sequence) {
      files_.splice(files_.begin(), files_, it);
      return files_.front();
    }
  const std::string& id = file_ids_.at(static_cast<std::size_t>(sequence) % file_ids_.size());
  return keep_open(sequence, std::make_shared<dataset::SequenceFile>(manifest_.sequence_path(id)));
}

Window TrainData::read_window(int sequence, int t_first, int t_last) {
  OpenFile& f = open(sequence);
  Window w;
  w.sequence_id = ids_.at(static_cast<std::size_t>(sequence));
  w.info = f.info;
  w.constraints = f.constraints;
  w.structure = f.structure;
  w.frames = f.file->read_frames(t_first - 2, t_last - t_first + 4);
  if (mirrored(sequence)) dataset::mirror_positions(w.frames);
  ++reads_.windows;
  reads_.bytes += w.frames.bytes();
  return w;
}

dataset::TrainingSample TrainData::build(const Window& w, int t) const {
  dataset::TrainingSample s = dataset::build_sample(*w.info, w.frames, t, stats_, w.structure, sample_options_);
  s.sequence_id = w.sequence_id;
  losses::add_physics_step(s, *w.info, model_);
  return s;
}

}  // namespace layersnet
