#include "run/run_dir.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

namespace layersnet {

namespace fs = std::filesystem;

std::string checkpoint_path(const std::string& run_dir, int64_t batches) {
  char name[64];
  std::snprintf(name, sizeof name, "step_%08lld.h5", static_cast<long long>(batches));
  return (fs::path(run_dir) / "checkpoints" / name).string();
}

std::vector<std::string> list_checkpoints(const std::string& run_dir) {
  std::vector<std::string> out;
  const fs::path dir = fs::path(run_dir) / "checkpoints";
  if (!fs::is_directory(dir)) return out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.rfind("step_", 0) == 0 && e.path().extension() == ".h5") out.push_back(e.path().string());
  }
  std::sort(out.begin(), out.end());  // zero-padded numbers sort as text
  return out;
}

std::string best_checkpoint_path(const std::string& run_dir) { return (fs::path(run_dir) / "best.h5").string(); }

std::string run_checkpoint(const std::string& run_dir) {
  if (fs::exists(best_checkpoint_path(run_dir))) return best_checkpoint_path(run_dir);
  const auto all = list_checkpoints(run_dir);
  if (all.empty())
    throw std::runtime_error(run_dir + ": no best.h5 and no checkpoints/step_*.h5 — is this a run directory of "
                             "`layersnet train`? Give --checkpoint FILE instead");
  return all.back();
}

void prune_checkpoints(const std::string& run_dir, int keep) {
  const auto all = list_checkpoints(run_dir);
  for (std::size_t i = 0; i + static_cast<std::size_t>(std::max(keep, 1)) < all.size(); ++i) fs::remove(all[i]);
  const fs::path dir = fs::path(run_dir) / "checkpoints";
  if (fs::is_directory(dir))
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().extension() == ".tmp") fs::remove(e.path());
}

bool holds_run(const std::string& run_dir) {
  const fs::path d(run_dir);
  return fs::exists(d / "config.toml") || fs::exists(d / "metrics.jsonl") || !list_checkpoints(run_dir).empty() ||
         fs::exists(best_checkpoint_path(run_dir));
}

RunLock::RunLock(const std::string& run_dir) {
  const std::string path = (fs::path(run_dir) / "lock").string();
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw std::runtime_error(path + ": cannot open the run's lock file: " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char holder[256] = {};
    const ssize_t n = ::pread(fd_, holder, sizeof holder - 1, 0);
    ::close(fd_);
    fd_ = -1;
    if (err != EWOULDBLOCK) throw std::runtime_error(path + ": cannot lock the run directory: " + std::strerror(err));
    std::string who = n > 0 ? std::string(holder, static_cast<size_t>(n)) : "another process";
    while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
    throw std::runtime_error(run_dir + " is in use by a running `layersnet train` (" + who +
                             "); wait for it to finish or stop it, then --resume, or choose another --run directory");
  }
  char host[128] = {};
  ::gethostname(host, sizeof host - 1);
  char when[32] = {};
  const std::time_t now = std::time(nullptr);
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", std::localtime(&now));
  const std::string me = "pid " + std::to_string(::getpid()) + " on " + host + " since " + when + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, me.data(), me.size(), 0) != static_cast<ssize_t>(me.size())) {
    // The lock holds without its note; only the next process's message is poorer.
  }
}

RunLock::~RunLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the flock
}

std::map<std::string, std::vector<double>> stats_to_arrays(const dataset::NormalisationStats& s) {
  std::map<std::string, std::vector<double>> out;
  for (const auto& [quantity, field] : dataset::kStatQuantities) {
    const std::string name = quantity;
    const dataset::MeanStd& m = s.*field;
    out[name + ".mean"] = {m.mean[0], m.mean[1], m.mean[2]};
    out[name + ".std"] = {m.std[0], m.std[1], m.std[2]};
    out[name + ".count"] = {static_cast<double>(m.count)};
  }
  return out;
}

dataset::NormalisationStats stats_from_arrays(const std::map<std::string, std::vector<double>>& a,
                                              const std::string& origin) {
  dataset::NormalisationStats s;
  // "<quantity>.<what>", or "<quantity>_<what>" as other writers spell it.
  auto find = [&](const std::string& name, const std::string& what) {
    const auto it = a.find(name + "." + what);
    return it != a.end() ? it : a.find(name + "_" + what);
  };
  auto get = [&](const std::string& name, const std::string& what) -> const std::vector<double>& {
    const auto it = find(name, what);
    if (it == a.end() || it->second.size() != 3)
      throw std::runtime_error(origin + ": /stats/" + name + "." + what +
                               " is missing or not 3 values (checkpoint written by another program version?)");
    return it->second;
  };
  for (const auto& [quantity, field] : dataset::kStatQuantities) {
    const std::string name = quantity;
    dataset::MeanStd& m = s.*field;
    const auto& mean = get(name, "mean");
    const auto& std = get(name, "std");
    m.mean = {mean[0], mean[1], mean[2]};
    m.std = {std[0], std[1], std[2]};
    if (const auto c = find(name, "count"); c != a.end() && !c->second.empty()) m.count = static_cast<int64_t>(c->second[0]);
  }
  return s;
}

}  // namespace layersnet
