// Normalisation statistics: streamed over frame windows of the training split.
#include "dataset/stats.h"

#include "dataset/h5.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

namespace layersnet::dataset {
namespace {

// Adds one sequence's quantities to the six accumulators; read(first, count) gives a
// window holding frames [first, first + count).
template <class ReadFrames>
void accumulate_sequence(const SequenceInfo& info, const ReadFrames& read, const StatsOptions& o, StatsAccumulator acc[6]) {
  const int T = info.num_frames;
  const int64_t n_rows = info.total_garment_vertices() + (o.include_body ? info.num_body_vertices : 0);
  // Root-relative positions of the two previous frames (rows: garments then body).
  Eigen::MatrixX3d prev, prev_vel;
  for (int first = 0; first < T; first += o.window_frames) {
    const int count = std::min(o.window_frames, T - first);
    const FrameWindow& w = read(first, count);
    for (int t = first; t < first + count; ++t) {
      const Eigen::RowVector3d root = info.translation.row(t).cast<double>();
      Eigen::MatrixX3d x(n_rows, 3);
      Eigen::Index r = 0;
      for (int g = 0; g < info.num_garments(); ++g) {
        const int n = info.garments[g].num_vertices;
        x.middleRows(r, n) = w.garment_at(g, t, n).cast<double>();
        r += n;
      }
      if (o.include_body) x.middleRows(r, info.num_body_vertices) = w.body_at(t, info.num_body_vertices).cast<double>();
      x.rowwise() -= root;
      for (Eigen::Index i = 0; i < n_rows; ++i) acc[0].add(x.row(i).transpose());
      acc[3].add(root.transpose());
      if (t >= 1) {
        const Eigen::MatrixX3d vel = x - prev;
        for (Eigen::Index i = 0; i < n_rows; ++i) acc[1].add(vel.row(i).transpose());
        const Eigen::RowVector3d rv = root - info.translation.row(t - 1).cast<double>();
        acc[4].add(rv.transpose());
        if (t >= 2) {
          const Eigen::MatrixX3d a = vel - prev_vel;
          for (Eigen::Index i = 0; i < n_rows; ++i) acc[2].add(a.row(i).transpose());
          const Eigen::RowVector3d rv1 = (info.translation.row(t - 1) - info.translation.row(t - 2)).cast<double>();
          acc[5].add((rv - rv1).transpose());
        }
        prev_vel = vel;
      }
      prev = std::move(x);
    }
  }
}

}  // namespace

void StatsAccumulator::add(const Eigen::Vector3d& v) {
  sum_ += v;
  sum_sq_ += v.cwiseProduct(v);
  ++n_;
}

MeanStd StatsAccumulator::result() const {
  MeanStd r;
  r.count = n_;
  if (n_ == 0) return r;
  r.mean = sum_ / static_cast<double>(n_);
  for (int k = 0; k < 3; ++k) {
    const double var = std::max(0.0, sum_sq_[k] / static_cast<double>(n_) - r.mean[k] * r.mean[k]);
    const double sd = std::sqrt(var);
    r.std[k] = sd > 0 && std::isfinite(sd) ? sd : 1.0;
  }
  return r;
}

NormalisationStats compute_stats(const DatasetManifest& m, const StatsOptions& o) {
  if (m.train.empty())
    throw DatasetError(m.manifest_path(), "/splits/train", "is empty: statistics come from the training split only");
  StatsAccumulator acc[6];
  for (const auto& id : m.train) {
    const SequenceFile file(m.sequence_path(id));
    accumulate_sequence(file.info(), [&](int first, int count) { return file.read_frames(first, count); }, o, acc);
  }
  NormalisationStats s;
  for (std::size_t i = 0; i < kStatQuantities.size(); ++i) s.*kStatQuantities[i].field = acc[i].result();
  s.sequences = m.train;
  return s;
}

NormalisationStats compute_stats(const Sequence& seq, const StatsOptions& o) {
  StatsAccumulator acc[6];
  accumulate_sequence(seq.info, [&](int, int) -> const FrameWindow& { return seq.frames; }, o, acc);
  NormalisationStats s;
  for (std::size_t i = 0; i < kStatQuantities.size(); ++i) s.*kStatQuantities[i].field = acc[i].result();
  s.sequences = {seq.info.path};
  return s;
}

void write_stats(const std::string& path, const NormalisationStats& s) {
  h5::write_file(path, [&](hid_t f) {
    h5::write_string_attr(f, "format", "dlayers-h5-stats");
    h5::write_int_attr(f, "version", 1);
    h5::write_string_array_attr(f, "sequences", s.sequences);
    h5::write_string_attr(f, "units",
                          "scene units relative to the body root translation; velocity per frame, "
                          "acceleration per frame^2 (dt = 1 frame)");
    for (const auto& [name, field] : kStatQuantities) {
      const MeanStd& q = s.*field;
      h5::Handle g = h5::create_group(f, name, h5::Where{path, std::string("/") + name});
      Eigen::Vector3d sd = q.std;
      for (int k = 0; k < 3; ++k)
        if (!(sd[k] != 0)) sd[k] = 1.0;
      h5::write_doubles(g.get(), "mean", q.mean.data(), {3});
      h5::write_doubles(g.get(), "std", sd.data(), {3});
      h5::write_int64_scalar(g.get(), "count", q.count);
    }
  });
}

NormalisationStats read_stats(const std::string& path) {
  h5::Handle f = h5::open_file(path);
  const h5::Where root{path, "/"};
  const std::string format = h5::read_string_attr(f.get(), "format", root);
  if (format != "dlayers-h5-stats") root.fail("attribute 'format' is '" + format + "', must be 'dlayers-h5-stats'");
  const int64_t version = h5::read_int_attr(f.get(), "version", root);
  if (version != 1) root.fail("attribute 'version' is " + std::to_string(version) + ", must be 1");
  NormalisationStats s;
  s.sequences = h5::read_string_array_attr(f.get(), "sequences", root);
  for (const auto& [quantity, field] : kStatQuantities) {
    const std::string gp = std::string("/") + quantity;
    h5::Handle g = h5::open_group(f.get(), quantity, h5::Where{path, gp});
    MeanStd& q = s.*field;
    for (const char* name : {"mean", "std"}) {
      const h5::Where w{path, gp + "/" + name};
      h5::Handle ds = h5::open_dataset(g.get(), name, w);
      const h5::ArrayInfo info = h5::dataset_info(ds.get(), w);
      h5::check_array(info, h5::Kind::kFloat, {3}, w);
      const std::vector<float> v = h5::read_floats(ds.get(), info, w);
      Eigen::Vector3d& dst = std::string(name) == "mean" ? q.mean : q.std;
      dst = Eigen::Vector3d(v[0], v[1], v[2]);
      // Re-read as double for full precision (read_floats already checked finiteness).
      H5Dread(ds.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, dst.data());
    }
    for (int k = 0; k < 3; ++k)
      if (!(q.std[k] > 0)) h5::Where{path, gp + "/std"}.fail("standard deviation must be > 0 (0 is stored as 1)");
    const h5::Where wc{path, gp + "/count"};
    h5::Handle c = h5::open_dataset(g.get(), "count", wc);
    const h5::ArrayInfo ci = h5::dataset_info(c.get(), wc);
    if (ci.type.kind != h5::Kind::kInt || !ci.dims.empty() || ci.null_space) wc.fail("must be a scalar integer");
    if (H5Dread(c.get(), H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, &q.count) < 0) wc.fail("cannot be read");
  }
  return s;
}

std::string stats_split_mismatch(const NormalisationStats& s, const DatasetManifest& m) {
  for (const auto& id : s.sequences)
    if (std::find(m.train.begin(), m.train.end(), id) == m.train.end())
      return "computed from sequence '" + id + "' which is not in the train split";
  for (const auto& id : m.train)
    if (std::find(s.sequences.begin(), s.sequences.end(), id) == s.sequences.end())
      return "computed from " + std::to_string(s.sequences.size()) + " of the " + std::to_string(m.train.size()) +
             " training sequences (not from '" + id + "')";
  return "";
}

NormalisationStats load_training_stats(const DatasetManifest& m, const std::string& explicit_path,
                                       bool require_training_split, std::string* note) {
  if (explicit_path.empty()) return load_stats_or_explain(m, require_training_split);
  if (!std::filesystem::exists(explicit_path))
    throw DatasetError(explicit_path, "/", "missing: data.stats names no file; give an existing stats.h5 or leave it empty");
  NormalisationStats s = read_stats(explicit_path);
  const std::string mismatch = stats_split_mismatch(s, m);
  if (note && !mismatch.empty())
    *note = "normalising with " + explicit_path + " (data.stats), " + mismatch + " of " + m.root;
  return s;
}

NormalisationStats load_stats_or_explain(const DatasetManifest& m, bool require_training_split) {
  const std::string p = m.stats_path();
  if (!std::filesystem::exists(p))
    throw DatasetError(p, "/", "missing normalisation statistics; create them with `layersnet prepare " + m.root + "`");
  NormalisationStats s = read_stats(p);
  if (require_training_split) {
    const std::string mismatch = stats_split_mismatch(s, m);
    if (!mismatch.empty()) throw DatasetError(p, "/", mismatch + "; rerun `layersnet prepare " + m.root + "`");
  }
  return s;
}

}  // namespace layersnet::dataset
