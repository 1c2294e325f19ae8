// Data-parallel training under mpirun on tiny synthetic data sets, through the real program:
// R ranks against one process at the same global batch (bit-identical parameters, metrics and
// validation errors), one writer, a killed rank or a failing rank ending the whole job in
// bounded time, and a run resumed under another rank count.
#include "dataset/manifest.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "run/run_dir.h"
#include "train/trainer.h"
#include "tests/train/child_process.h"

#include <gtest/gtest.h>
#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

namespace layersnet {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The launcher with the flags a root CI container needs (oversubscribing its cores), and a
// session folder of this test process's own: two launchers started at once (ctest -j2) race to
// create the shared default /tmp/ompi.HOST.UID and one fails in orte_init.
fs::path mpi_session_dir() { return fs::temp_directory_path() / ("layersnet_ompi_" + std::to_string(::getpid())); }

std::vector<std::string> mpirun(int ranks) {
  const fs::path session = mpi_session_dir();
  fs::create_directories(session);
  return {LAYERSNET_MPIEXEC, "-np", std::to_string(ranks), "--oversubscribe", "--allow-run-as-root",
          "--mca", "btl_vader_single_copy_mechanism", "none", "--mca", "orte_tmpdir_base", session.string()};
}

using testing::spawn;
using testing::wait_exit;

// The pid of the process whose environment says OMPI_COMM_WORLD_RANK=rank under `launcher`.
pid_t find_rank(pid_t launcher, int rank) {
  const std::string want = "OMPI_COMM_WORLD_RANK=" + std::to_string(rank);
  DIR* d = ::opendir("/proc");
  pid_t found = -1;
  while (dirent* e = d ? ::readdir(d) : nullptr) {
    const pid_t pid = static_cast<pid_t>(std::atoi(e->d_name));
    if (pid <= 0) continue;
    std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
    std::string line;
    std::getline(stat, line);
    const auto close = line.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream rest(line.substr(close + 2));
    char state;
    pid_t ppid = 0;
    rest >> state >> ppid;
    if (ppid != launcher) continue;
    const std::string env = read_text("/proc/" + std::to_string(pid) + "/environ");
    std::string entry;
    for (std::istringstream in(env); std::getline(in, entry, '\0');)
      if (entry == want) found = pid;
  }
  if (d) ::closedir(d);
  return found;
}

int count(const std::string& text, const std::string& what) {
  int n = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

class TrainMpiTest : public ::testing::Test {
 protected:
  fs::path dir_ = fs::temp_directory_path() / ("layersnet_train_mpi_" + std::to_string(::getpid()) + "_" +
                                               ::testing::UnitTest::GetInstance()->current_test_info()->name());
  void SetUp() override {
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    dataset::SyntheticOptions o;
    o.frames = 8;
    o.garments = 2;
    o.rings = 4;
    o.segments = 12;
    o.body_rings = 4;
    o.body_segments = 12;
    o.wind = true;
    o.motion = 0.3f;
    const auto manifest = dataset::write_synthetic_dataset(data_, 3, 2, 1, o);
    dataset::write_stats(manifest.stats_path(), dataset::compute_stats(manifest));
  }
  void TearDown() override {
    fs::remove_all(dir_);
    fs::remove_all(mpi_session_dir());
  }

  // `layersnet train` on configs/tiny.toml, one thread per process; batch 3 splits unevenly
  // over 2 ranks (2 + 1 samples) and the epoch's last batch is short.
  std::vector<std::string> train_args(const std::string& run, std::vector<std::string> sets) const {
    std::vector<std::string> all = {"data.dataset=" + data_, "data.first_frame=2", "data.max_frames=0",
                                    "train.threads=1", "train.batch_size=3", "train.rollout_steps=[0, 1]",
                                    "train.input_noise=0.001", "train.checkpoint_every=2", "train.keep_checkpoints=2"};
    all.insert(all.end(), sets.begin(), sets.end());
    std::vector<std::string> a = {LAYERSNET_BINARY, "train", "--config",
                                  std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml", "--run", (dir_ / run).string()};
    for (const auto& s : all) a.insert(a.end(), {"--set", s});
    return a;
  }
  static std::vector<std::string> under(std::vector<std::string> launcher, const std::vector<std::string>& args) {
    launcher.insert(launcher.end(), args.begin(), args.end());
    return launcher;
  }
  int run(const std::vector<std::string>& args, const std::string& log, std::chrono::seconds limit = std::chrono::seconds(60)) {
    const auto status = wait_exit(spawn(args, dir_ / log), limit);
    EXPECT_TRUE(status.has_value()) << log << " did not end within " << limit.count() << " s:\n" << read_text(dir_ / log);
    return status.value_or(-1000);
  }

  // Parameters, Adam moments and step of a run's newest checkpoint.
  struct Final {
    std::vector<float> values, m, v;
    int64_t step = -1;
    std::string name;
  };
  Final final_state(const std::string& run) const {
    Final f;
    const auto all = list_checkpoints((dir_ / run).string());
    EXPECT_FALSE(all.empty()) << run;
    if (all.empty()) return f;
    const Config c = run_config((dir_ / run).string(), {});
    ad::ParamStore<float> p;
    model::register_params(p, c.model);
    f.step = read_checkpoint(all.back(), p).state.global_step;
    f.values.assign(p.values().begin(), p.values().end());
    f.m.assign(p.moment1().begin(), p.moment1().end());
    f.v.assign(p.moment2().begin(), p.moment2().end());
    f.name = fs::path(all.back()).filename().string();
    return f;
  }
  static void expect_bitwise(const Final& a, const Final& b) {
    EXPECT_EQ(a.step, b.step);
    EXPECT_EQ(a.name, b.name);
    ASSERT_EQ(a.values.size(), b.values.size());
    ASSERT_FALSE(a.values.empty());
    EXPECT_EQ(std::memcmp(a.values.data(), b.values.data(), a.values.size() * sizeof(float)), 0) << "weights differ";
    EXPECT_EQ(std::memcmp(a.m.data(), b.m.data(), a.m.size() * sizeof(float)), 0) << "Adam m differs";
    EXPECT_EQ(std::memcmp(a.v.data(), b.v.data(), a.v.size() * sizeof(float)), 0) << "Adam v differs";
  }
  // The metrics lines with the timing fields (which differ run to run) removed.
  std::vector<std::string> metrics_without_timing(const std::string& run) const {
    std::vector<std::string> out;
    std::istringstream in(read_text(dir_ / run / "metrics.jsonl"));
    for (std::string line; std::getline(in, line);) {
      const auto at = line.find(",\"samples_per_s\"");  // the rest is timing, thread and rank counts
      if (at != std::string::npos) line = line.substr(0, at);
      out.push_back(line);
    }
    return out;
  }

  std::string data_ = (dir_ / "data").string();
};

TEST_F(TrainMpiTest, TwoRanksMatchOneProcessBitwise) {
  ASSERT_EQ(run(train_args("one", {}), "one.log"), 0) << read_text(dir_ / "one.log");
  ASSERT_EQ(run(under(mpirun(2), train_args("two", {})), "two.log"), 0) << read_text(dir_ / "two.log");
  expect_bitwise(final_state("one"), final_state("two"));
  // The same losses, gradient norms and validation errors, logged once (rank 0 only).
  const auto a = metrics_without_timing("one"), b = metrics_without_timing("two");
  ASSERT_FALSE(a.empty());
  EXPECT_EQ(a, b);
  const std::string log = read_text(dir_ / "two.log");
  EXPECT_EQ(count(log, "done: "), 1) << log;
  EXPECT_NE(log.find("2 ranks"), std::string::npos) << log;
  EXPECT_EQ(count(read_text(dir_ / "two" / "metrics.jsonl"), "\"event\":\"val\""),
            count(read_text(dir_ / "one" / "metrics.jsonl"), "\"event\":\"val\""));
}

TEST_F(TrainMpiTest, ResumeUnderAnotherRankCountMatchesTheUninterruptedRun) {
  ASSERT_EQ(run(train_args("whole", {}), "whole.log"), 0) << read_text(dir_ / "whole.log");
  // 1 process stops after 3 updates (inside the second epoch), 2 ranks finish the run.
  ASSERT_EQ(run(train_args("part", {"train.max_steps=3"}), "part.log"), 0) << read_text(dir_ / "part.log");
  ASSERT_EQ(final_state("part").step, 3);
  const std::vector<std::string> resume = {LAYERSNET_BINARY, "train", "--resume", (dir_ / "part").string(), "--set",
                                           "train.max_steps=0"};
  ASSERT_EQ(run(under(mpirun(2), resume), "resumed.log"), 0) << read_text(dir_ / "resumed.log");
  EXPECT_NE(read_text(dir_ / "resumed.log").find("resuming"), std::string::npos) << read_text(dir_ / "resumed.log");
  expect_bitwise(final_state("whole"), final_state("part"));
}

TEST_F(TrainMpiTest, AKilledRankEndsTheJobInBoundedTime) {
  const pid_t launcher = spawn(under(mpirun(2), train_args("killed", {"train.epochs=1000"})), dir_ / "killed.log");
  // Kill rank 1 once training is under way.
  const auto deadline = Clock::now() + std::chrono::seconds(60);
  while (Clock::now() < deadline && read_text(dir_ / "killed" / "metrics.jsonl").find("\"event\":\"train\"") == std::string::npos)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const pid_t rank1 = find_rank(launcher, 1);
  ASSERT_GT(rank1, 0) << read_text(dir_ / "killed.log");
  const auto killed_at = Clock::now();
  ::kill(rank1, SIGKILL);
  const auto status = wait_exit(launcher, std::chrono::seconds(30));
  const double seconds = std::chrono::duration<double>(Clock::now() - killed_at).count();
  ASSERT_TRUE(status.has_value()) << "the job hung after rank 1 was killed:\n" << read_text(dir_ / "killed.log");
  EXPECT_NE(*status, 0);
  std::cout << "[ info ] the job ended " << seconds << " s after rank 1 was killed, status " << *status << "\n";
  EXPECT_EQ(find_rank(launcher, 0), -1);  // no rank left behind
}

TEST_F(TrainMpiTest, AFailingRankEndsTheJobWithOneMessage) {
  ASSERT_EQ(run(train_args("run", {"train.epochs=1"}), "first.log"), 0) << read_text(dir_ / "first.log");
  // Rank 0 refuses the existing run while rank 1, which does not look at the run directory,
  // goes on to its first collective: the job must end, not wait there.
  const auto start = Clock::now();
  const int status = run(under(mpirun(2), train_args("run", {"train.epochs=1"})), "refused.log", std::chrono::seconds(30));
  const std::string log = read_text(dir_ / "refused.log");
  EXPECT_EQ(status, 1) << log;
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - start).count(), 30.0);
  EXPECT_EQ(count(log, "already holds a run"), 1) << log;
  EXPECT_NE(log.find("rank 0 of 2"), std::string::npos) << log;

  // A bad --set value is refused by every rank alike: reported once, by rank 0.
  const int bad = run(under(mpirun(2), train_args("bad", {"train.learning_rate=1e38"})), "bad.log", std::chrono::seconds(30));
  const std::string log1 = read_text(dir_ / "bad.log");
  EXPECT_EQ(bad, 1) << log1;
  EXPECT_EQ(count(log1, "out of range"), 1) << log1;

  // A data set without stats.h5 fails on every rank alike: reported once, by rank 0.
  fs::remove(dataset::read_manifest(data_).stats_path());
  const int none = run(under(mpirun(2), train_args("nostats", {})), "nostats.log", std::chrono::seconds(30));
  const std::string log2 = read_text(dir_ / "nostats.log");
  EXPECT_EQ(none, 1) << log2;
  EXPECT_EQ(count(log2, "layersnet prepare"), 1) << log2;
}

}  // namespace
}  // namespace layersnet
