#include "run/checkpoint.h"

#include "dataset/h5.h"
#include "dataset/h5_guard.h"
#include "model/params_layout.h"
#include "layersnet_version.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <span>
#include <sstream>
#include <utility>

namespace layersnet {

namespace {

namespace h5 = dataset::h5;

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw CheckpointError(path + ": " + what);
}

void write_bytes(hid_t loc, const std::string& name, const std::vector<uint8_t>& bytes) {
  const hsize_t dims[1] = {bytes.size()};
  h5::Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose);
  h5::Handle ds(H5Dcreate2(loc, name.c_str(), H5T_STD_U8LE, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                H5Dclose);
  if (!ds.valid() || (!bytes.empty() && H5Dwrite(ds.get(), H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                                                  bytes.data()) < 0))
    throw CheckpointError("cannot write byte array " + name);
}

std::vector<uint8_t> read_bytes(hid_t loc, const std::string& name, const h5::Where& where) {
  h5::Handle ds(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!ds.valid()) where.fail("cannot be opened");
  h5::Handle space(H5Dget_space(ds.get()), H5Sclose);
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n < 0 || n > (hssize_t{1} << 30)) where.fail("has an unreadable size");
  std::vector<uint8_t> bytes(static_cast<std::size_t>(n));
  if (n > 0 && H5Dread(ds.get(), H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, bytes.data()) < 0)
    where.fail("cannot be read (truncated or corrupted file?)");
  return bytes;
}

std::vector<double> read_doubles(hid_t ds, const h5::Where& where) {
  h5::Handle space(H5Dget_space(ds), H5Sclose);
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n < 0 || n > (hssize_t{1} << 30)) where.fail("has an unreadable size");
  std::vector<double> values(static_cast<std::size_t>(n));
  if (n > 0 && H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) < 0)
    where.fail("cannot be read (truncated or corrupted file?)");
  return values;
}

void write_tensor_group(hid_t file, const std::string& group, const ad::ParamStore<float>& params,
                        std::span<const float> flat) {
  h5::Handle g = h5::create_group(file, group, {"", group});
  for (const auto& e : params.entries()) {
    h5::write_floats(g.get(), e.name, flat.data() + e.offset,
                     {static_cast<uint64_t>(e.rows), static_cast<uint64_t>(e.cols)}, {});
  }
}

// Reads every tensor of `group` into `flat`, checking names and shapes against `params`.
void read_tensor_group(hid_t file, const std::string& path, const std::string& group,
                       const ad::ParamStore<float>& params, std::span<float> flat) {
  const h5::Where gw{path, "/" + group};
  h5::Handle g = h5::open_group(file, group, gw);
  const auto names = h5::member_names(g.get(), gw);
  std::ostringstream diff;
  int n_diff = 0;
  for (const auto& e : params.entries()) {
    if (std::find(names.begin(), names.end(), e.name) == names.end()) {
      if (n_diff++ < 10) diff << "\n  missing in the checkpoint: " << e.name << " (" << e.rows << ", " << e.cols << ")";
      continue;
    }
    const h5::Where w{path, "/" + group + "/" + e.name};
    h5::Handle ds = h5::open_dataset(g.get(), e.name, w);
    const h5::ArrayInfo info = h5::dataset_info(ds.get(), w);
    if (info.dims.size() != 2 || info.dims[0] != static_cast<uint64_t>(e.rows) ||
        info.dims[1] != static_cast<uint64_t>(e.cols)) {
      if (n_diff++ < 10)
        diff << "\n  " << e.name << ": checkpoint " << h5::shape_string(info.dims) << ", model (" << e.rows << ", "
             << e.cols << ")";
      continue;
    }
    const std::vector<float> values = h5::read_floats(ds.get(), info, w);
    std::copy(values.begin(), values.end(), flat.begin() + static_cast<std::ptrdiff_t>(e.offset));
  }
  for (const auto& name : names) {
    bool known = false;
    for (const auto& e : params.entries()) known |= e.name == name;
    if (!known && n_diff++ < 10) diff << "\n  not in this model: " << name;
  }
  if (n_diff > 0)
    fail(path, "/" + group + " does not match the model (" + std::to_string(n_diff) +
                   " difference(s); was it trained with another model size?):" + diff.str());
}

// FNV-1a, 64 bit: cheap, dependency-free, and enough to see a changed byte (not an attacker).
class Fnv1a64 {
 public:
  void bytes(const void* data, std::size_t n) {
    const auto* p = static_cast<const uint8_t*>(data);
    for (std::size_t i = 0; i < n; ++i) h_ = (h_ ^ p[i]) * 0x100000001b3ull;
  }
  template <class T>
  void value(const T& v) { bytes(&v, sizeof v); }
  void text(const std::string& s) { value(s.size()), bytes(s.data(), s.size()); }
  std::string hex() const {
    char out[32];
    std::snprintf(out, sizeof out, "fnv1a64:%016llx", static_cast<unsigned long long>(h_));
    return out;
  }

 private:
  uint64_t h_ = 0xcbf29ce484222325ull;
};

// What the checksum covers: everything a checkpoint holds, in one fixed order, from the
// in-memory values (so writer and reader hash the same thing).
std::string content_checksum(const ad::ParamStore<float>& params, const Checkpoint& cp) {
  Fnv1a64 h;
  h.text(cp.config_toml);
  h.value(cp.has_optimizer);
  const auto tensors = [&](std::span<const float> flat) {
    for (const auto& e : params.entries()) {
      h.text(e.name);
      h.bytes(flat.data() + e.offset, static_cast<std::size_t>(e.rows * e.cols) * sizeof(float));
    }
  };
  tensors(params.values());
  if (cp.has_optimizer) {
    tensors(params.moment1());
    tensors(params.moment2());
  }
  if (!cp.ema.empty()) {
    h.text("ema");
    tensors(cp.ema);
  }
  const TrainingState& s = cp.state;
  for (const int64_t v : {s.epoch, s.position, s.global_step, s.nonfinite_in_row}) h.value(v);
  h.value(s.best_val_error);
  for (const auto& [name, bytes] : s.rng) {
    h.text(name);
    h.value(bytes.size());
    h.bytes(bytes.data(), bytes.size());
  }
  for (const auto& [name, values] : cp.stats) {
    h.text(name);
    h.value(values.size());
    h.bytes(values.data(), values.size() * sizeof(double));
  }
  return h.hex();
}

// Values no training run writes: a file that holds them was damaged or edited.
void check_plausible(const std::string& path, const ad::ParamStore<float>& params, const Checkpoint& cp) {
  const auto first_bad = [&](std::span<const float> flat, auto bad) -> std::string {
    for (const auto& e : params.entries())
      for (int64_t i = 0; i < e.rows * e.cols; ++i)
        if (bad(flat[static_cast<std::size_t>(e.offset + i)])) return e.name;
    return "";
  };
  const auto non_finite = [](float v) { return !std::isfinite(v); };
  if (const std::string n = first_bad(params.values(), non_finite); !n.empty())
    fail(path, "/weights/" + n + " holds non-finite values; use an earlier checkpoint");
  if (!cp.ema.empty())
    if (const std::string n = first_bad(cp.ema, non_finite); !n.empty())
      fail(path, "/ema/" + n + " holds non-finite values; use an earlier checkpoint");
  if (cp.has_optimizer) {
    if (const std::string n = first_bad(params.moment1(), non_finite); !n.empty())
      fail(path, "/adam/m/" + n + " holds non-finite values; use an earlier checkpoint");
    if (const std::string n = first_bad(params.moment2(), [](float v) { return !(v >= 0) || !std::isfinite(v); });
        !n.empty())
      fail(path, "/adam/v/" + n + " holds a negative or non-finite second moment (never written by Adam); use an "
                 "earlier checkpoint");
  }
  for (const auto& [name, values] : cp.stats)
    for (const double v : values) {
      const bool is_std = name.size() > 4 && name.compare(name.size() - 4, 4, ".std") == 0;
      if (!std::isfinite(v) || (is_std && v <= 0))
        fail(path, "/stats/" + name + " holds " + std::to_string(v) +
                       (is_std ? " (a std must be finite and > 0)" : " (must be finite)") +
                       "; the normalisation statistics are damaged");
    }
}

}  // namespace

void write_checkpoint(const std::string& path, const ad::ParamStore<float>& params, const Checkpoint& cp) {
  h5::write_file(path, [&](hid_t f) {
    h5::write_string_attr(f, "format", kCheckpointFormat);
    h5::write_int_attr(f, "version", kCheckpointVersion);
    h5::write_string_attr(f, "program", std::string("layersnet ") + LAYERSNET_VERSION);
    h5::write_string_attr(f, "checksum", content_checksum(params, cp));
    {
      h5::Handle g = h5::create_group(f, "config", {path, "/config"});
      h5::write_string_attr(g.get(), "toml", cp.config_toml);
    }
    write_tensor_group(f, "weights", params, params.values());
    if (cp.has_optimizer) {
      h5::Handle adam = h5::create_group(f, "adam", {path, "/adam"});
      h5::write_int_attr(adam.get(), "step", cp.state.global_step);
      write_tensor_group(adam.get(), "m", params, params.moment1());
      write_tensor_group(adam.get(), "v", params, params.moment2());
    }
    if (!cp.ema.empty()) {
      if (cp.ema.size() != params.values().size())
        fail(path, "not written: the weights' average has " + std::to_string(cp.ema.size()) + " values for " +
                       std::to_string(params.values().size()) + " parameters");
      write_tensor_group(f, "ema", params, cp.ema);
    }
    {
      h5::Handle st = h5::create_group(f, "state", {path, "/state"});
      h5::write_int_attr(st.get(), "epoch", cp.state.epoch);
      h5::write_int_attr(st.get(), "position", cp.state.position);
      h5::write_int_attr(st.get(), "global_step", cp.state.global_step);
      h5::write_float_attr(st.get(), "best_val_error", cp.state.best_val_error);
      h5::write_int_attr(st.get(), "nonfinite_in_row", cp.state.nonfinite_in_row);
      h5::Handle rng = h5::create_group(st.get(), "rng", {path, "/state/rng"});
      for (const auto& [name, bytes] : cp.state.rng) write_bytes(rng.get(), name, bytes);
    }
    {
      h5::Handle stats = h5::create_group(f, "stats", {path, "/stats"});
      for (const auto& [name, values] : cp.stats)
        h5::write_doubles(stats.get(), name, values.data(), {static_cast<uint64_t>(values.size())});
    }
  });
}

namespace {

h5::Handle open_checked(const std::string& path) {
  if (!std::filesystem::exists(path)) fail(path, "checkpoint not found");
  h5::guard_file(path, [&] { (void)load_model(path); });  // every read a command makes of it
  h5::Handle file;
  try {
    file = h5::open_file(path);
  } catch (const std::exception& e) {
    fail(path, std::string("not a readable HDF5 checkpoint (truncated or corrupted?): ") + e.what());
  }
  const h5::Where root{path, "/"};
  if (!h5::has_attr(file.get(), "format")) fail(path, "not a LayersNet checkpoint (no 'format' attribute)");
  const std::string format = h5::read_string_attr(file.get(), "format", root);
  if (format != kCheckpointFormat)
    fail(path, "format is '" + format + "', expected '" + std::string(kCheckpointFormat) + "'");
  const int64_t version = h5::read_int_attr(file.get(), "version", root);
  if (version != kCheckpointVersion)
    fail(path, "checkpoint format version " + std::to_string(version) + ", this program reads version " +
                   std::to_string(kCheckpointVersion));
  return file;
}

}  // namespace

std::string read_checkpoint_config(const std::string& path) {
  h5::Handle file = open_checked(path);
  h5::Handle g = h5::open_group(file.get(), "config", {path, "/config"});
  return h5::read_string_attr(g.get(), "toml", {path, "/config"});
}

Checkpoint read_checkpoint(const std::string& path, ad::ParamStore<float>& params) {
  try {
    h5::Handle file = open_checked(path);
    const hid_t f = file.get();
    Checkpoint cp;
    {
      h5::Handle g = h5::open_group(f, "config", {path, "/config"});
      cp.config_toml = h5::read_string_attr(g.get(), "toml", {path, "/config"});
    }
    read_tensor_group(f, path, "weights", params, params.values());
    cp.has_optimizer = h5::has_link(f, "adam");
    if (!cp.has_optimizer) {
      std::fill(params.moment1().begin(), params.moment1().end(), 0.0f);
      std::fill(params.moment2().begin(), params.moment2().end(), 0.0f);
    } else {
      const h5::Where aw{path, "/adam"};
      h5::Handle adam = h5::open_group(f, "adam", aw);
      cp.state.global_step = h5::read_int_attr(adam.get(), "step", aw);
      read_tensor_group(adam.get(), path, "m", params, params.moment1());
      read_tensor_group(adam.get(), path, "v", params, params.moment2());
    }
    if (h5::has_link(f, "ema")) {
      cp.ema.resize(params.values().size());
      read_tensor_group(f, path, "ema", params, cp.ema);
    }
    {
      const h5::Where sw{path, "/state"};
      h5::Handle st = h5::open_group(f, "state", sw);
      cp.state.epoch = h5::read_int_attr(st.get(), "epoch", sw);
      cp.state.position = h5::read_int_attr(st.get(), "position", sw);
      if (h5::has_attr(st.get(), "global_step")) cp.state.global_step = h5::read_int_attr(st.get(), "global_step", sw);
      cp.state.best_val_error = h5::read_float_attr(st.get(), "best_val_error", sw);
      cp.state.nonfinite_in_row = h5::read_int_attr(st.get(), "nonfinite_in_row", sw);
      const h5::Where rw{path, "/state/rng"};
      h5::Handle rng = h5::open_group(st.get(), "rng", rw);
      for (const auto& name : h5::member_names(rng.get(), rw))
        cp.state.rng[name] = read_bytes(rng.get(), name, {path, "/state/rng/" + name});
    }
    {
      const h5::Where tw{path, "/stats"};
      h5::Handle stats = h5::open_group(f, "stats", tw);
      for (const auto& name : h5::member_names(stats.get(), tw)) {
        const h5::Where w{path, "/stats/" + name};
        h5::Handle ds = h5::open_dataset(stats.get(), name, w);
        cp.stats[name] = read_doubles(ds.get(), w);
      }
    }
    if (h5::has_attr(f, "checksum")) {
      const std::string stored = h5::read_string_attr(f, "checksum", {path, "/"});
      const std::string actual = content_checksum(params, cp);
      if (stored != actual)
        fail(path, "content does not match its checksum (stored " + stored + ", computed " + actual +
                       "): the file was damaged after it was written; use an earlier checkpoint");
    }
    check_plausible(path, params, cp);
    return cp;
  } catch (const dataset::DatasetError& e) {
    throw CheckpointError(std::string("checkpoint is incomplete or corrupted: ") + e.what());
  }
}

bool same_model_section(const Config& a, const Config& b) {
  Config a_with_b_rest = a;
  a_with_b_rest.loss = b.loss;
  a_with_b_rest.physics = b.physics;
  a_with_b_rest.data = b.data;
  a_with_b_rest.train = b.train;
  a_with_b_rest.eval = b.eval;
  return to_toml(a_with_b_rest) == to_toml(b);
}

WeightsByName read_weights_by_name(const std::string& path, ad::ParamStore<float>& params) {
  LoadedModel theirs = load_model(path);
  std::ostringstream unfit;
  for (const auto& e : theirs.params.entries()) {
    const int mine = params.find(e.name);
    if (mine < 0) {
      unfit << "\n  " << e.name << " (" << e.rows << ", " << e.cols << "): not in this model";
      continue;
    }
    const ad::ParamEntry& m = params.entries()[static_cast<std::size_t>(mine)];
    if (m.rows != e.rows || m.cols != e.cols)
      unfit << "\n  " << e.name << ": checkpoint (" << e.rows << ", " << e.cols << "), model (" << m.rows << ", " << m.cols
            << ")";
  }
  if (!unfit.str().empty())
    fail(path, "its weights do not fit this model's [model] config:" + unfit.str() +
                   "\n  start from a checkpoint of a model that has every one of them, or change [model] to match");
  WeightsByName out;
  for (std::size_t i = 0; i < params.entries().size(); ++i) {
    const ad::ParamEntry& e = params.entries()[i];
    const auto to = params.value(static_cast<int>(i));
    if (const int t = theirs.params.find(e.name); t >= 0) {
      const auto from = theirs.params.value(t);
      std::copy(from.begin(), from.end(), to.begin());
    } else {
      std::fill(to.begin(), to.end(), 0.0f);
      out.added.push_back(e.name);
    }
  }
  std::fill(params.moment1().begin(), params.moment1().end(), 0.0f);
  std::fill(params.moment2().begin(), params.moment2().end(), 0.0f);
  out.checkpoint = std::move(theirs.checkpoint);
  out.config = std::move(theirs.config);
  return out;
}

LoadedModel load_model(const std::string& checkpoint_path) {
  LoadedModel m;
  m.config = parse_config_text(read_checkpoint_config(checkpoint_path), checkpoint_path + ":/config");
  model::register_params(m.params, m.config.model);
  m.checkpoint = read_checkpoint(checkpoint_path, m.params);
  return m;
}

LoadedModel average_models(const std::vector<std::string>& checkpoint_paths) {
  if (checkpoint_paths.empty()) throw CheckpointError("average_models: no checkpoint given");
  LoadedModel mean = load_model(checkpoint_paths.front());
  mean.checkpoint.has_optimizer = false;
  mean.checkpoint.state.rng.clear();
  std::vector<double> sum(mean.params.values().begin(), mean.params.values().end());
  for (std::size_t k = 1; k < checkpoint_paths.size(); ++k) {
    const std::string& path = checkpoint_paths[k];
    Config other = parse_config_text(read_checkpoint_config(path), path + ":/config");
    if (!same_model_section(other, mean.config))
      throw CheckpointError(path + ": its [model] settings differ from " + checkpoint_paths.front() +
                            "'s; only checkpoints of one model can be averaged");
    ad::ParamStore<float> params;
    model::register_params(params, other.model);
    const Checkpoint c = read_checkpoint(path, params);
    if (c.stats != mean.checkpoint.stats)
      throw CheckpointError(path + ": its normalisation statistics (/stats) differ from " + checkpoint_paths.front() +
                            "'s; average checkpoints of runs on the same data");
    const std::span<const float> v = std::as_const(params).values();
    for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += v[i];
  }
  const double n = static_cast<double>(checkpoint_paths.size());
  std::span<float> out = mean.params.values();
  for (std::size_t i = 0; i < sum.size(); ++i) out[i] = static_cast<float>(sum[i] / n);
  return mean;
}

}  // namespace layersnet
