// The program as a user meets it when things go wrong: bad arguments, corrupt or hostile files,
// damaged checkpoints, a full disk, a run directory in use. Every case runs the real
// `layersnet` binary and asserts its exit status (cli/exit_codes.h) and the message it prints.
// A full disk is a small tmpfs where the test may mount one (root), else a file-size limit
// (`ulimit -f`), which fails the same writes with EFBIG.
#include "dataset/h5.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "eval/rollout.h"
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "run/config.h"

#include "tests/eval/cli_test_util.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <string>
#include <vector>

namespace layersnet {
namespace {

namespace fs = std::filesystem;
using eval::cli_test::slurp;

struct Case {
  std::string name;
  std::string args;      // after `layersnet`; {root} {data} {ckpt} {case} are substituted
  int code;              // expected exit status
  std::string message;   // ECMAScript regex the output must contain
  std::function<void(const fs::path& case_dir)> setup = nullptr;
  std::string env = "";  // shell prefix, e.g. "LAYERSNET_HDF5_GUARD_SECONDS=2 "
};

class Reliability : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("layersnet_reliability_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    eval::cli_test::write_tiny_data_and_checkpoint(root_, 2, 0, 2, /*wind=*/false);
  }
  static void TearDownTestSuite() {
    for (const auto& m : mounts_) std::system(("umount '" + m + "' 2>/dev/null").c_str());
    fs::remove_all(root_);
  }

  // A copy of the data set in its own folder, with sequence s0000.h5 replaced by `bytes`.
  static void data_with_first_sequence(const fs::path& dir, const std::string& bytes) {
    fs::copy(root_ / "data", dir / "data", fs::copy_options::recursive);
    std::ofstream(dir / "data" / "s0000.h5", std::ios::binary | std::ios::trunc) << bytes;
  }
  // A copy of the data set whose s0000.h5 `edit` changed in place (HDF5 opened read-write).
  static void data_with_edited_sequence(const fs::path& dir, const std::function<void(hid_t file)>& edit) {
    fs::copy(root_ / "data", dir / "data", fs::copy_options::recursive);
    const hid_t f = H5Fopen((dir / "data" / "s0000.h5").c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    edit(f);
    H5Fclose(f);
  }
  // Sets element 0 of a float dataset.
  static void set_first_value(hid_t f, const char* path, float value) {
    const hid_t ds = H5Dopen2(f, path, H5P_DEFAULT);
    ASSERT_GE(ds, 0) << path;
    const hid_t space = H5Dget_space(ds);
    std::vector<float> v(static_cast<std::size_t>(H5Sget_simple_extent_npoints(space)));
    H5Dread(ds, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
    v[0] = value;
    H5Dwrite(ds, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
    H5Sclose(space);
    H5Dclose(ds);
  }
  // A file kept in fuzz/known_hdf5_issues/: byte 0 selects the fuzzer's mode, the rest is the HDF5 image.
  static std::string known_issue(const std::string& name) {
    return slurp(fs::path(LAYERSNET_SOURCE_DIR) / "fuzz" / "known_hdf5_issues" / name).substr(1);
  }
  // Makes `dir` a tmpfs of `kib` KiB and returns "", or, where mounting is not allowed,
  // returns the shell prefix that limits every written file to `limit_kib` KiB instead.
  static std::string full_disk(const fs::path& dir, int kib, int limit_kib) {
    fs::create_directories(dir);
    const std::string cmd = "mount -t tmpfs -o size=" + std::to_string(kib) + "k tmpfs '" + dir.string() + "' 2>/dev/null";
    if (std::system(cmd.c_str()) == 0) {
      mounts_.push_back(dir.string());
      return "";
    }
    return "ulimit -f " + std::to_string(limit_kib) + "; ";  // 1 KiB blocks in bash
  }

  // Takes the free space of a tmpfs.
  static void fill(const fs::path& disk) {
    std::ofstream f(disk / "filler", std::ios::binary);
    const std::string block(4096, '\0');
    while (f.write(block.data(), static_cast<std::streamsize>(block.size()))) {
    }
  }

  static int run_case(const Case& c, std::string* out) {
    const fs::path dir = root_ / c.name;
    fs::create_directories(dir);
    if (c.setup) c.setup(dir);
    std::string args = c.args;
    const std::pair<std::string, std::string> subs[] = {{"{root}", root_.string()},
                                                        {"{data}", (root_ / "data").string()},
                                                        {"{ckpt}", (root_ / "tiny.h5").string()},
                                                        {"{case}", dir.string()}};
    for (const auto& [key, value] : subs)
      for (std::size_t p; (p = args.find(key)) != std::string::npos;) args.replace(p, key.size(), value);
    const std::string cmd = "cd '" + dir.string() + "' && " + c.env + LAYERSNET_BINARY + " " + args + " 2>&1";
    std::FILE* p = popen(("bash -c \"" + cmd + "\"").c_str(), "r");
    std::array<char, 4096> buf;
    while (std::fgets(buf.data(), buf.size(), p)) *out += buf.data();
    const int status = pclose(p);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

  static void expect_case(const Case& c) {
    std::string out;
    const int code = run_case(c, &out);
    EXPECT_EQ(code, c.code) << c.name << ": " << c.args << "\n" << out;
    EXPECT_TRUE(std::regex_search(out, std::regex(c.message))) << c.name << ": expected /" << c.message << "/ in\n" << out;
  }

  static fs::path root_;
  static std::vector<std::string> mounts_;
};
fs::path Reliability::root_;
std::vector<std::string> Reliability::mounts_;

TEST_F(Reliability, BadArgumentsExitWithTheUsageStatus) {
  const std::vector<Case> cases = {
      {"unknown_command", "no-such-command", 2, "no-such-command"},
      {"unknown_option", "inspect {data} --no-such-option", 2, "no-such-option"},
      {"inspect_without_dataset", "inspect", 2, "dataset is required"},
      {"train_without_config", "train", 2, "give --config"},
      {"train_resume_and_config", "train --resume {case}/run --config x.toml", 2, "drop --config"},
      {"eval_without_model", "eval", 2, "give --run or --checkpoint"},
      {"eval_zero_speed_frames", "eval --checkpoint {ckpt} --speed-frames 0", 2, "speed-frames"},
      {"eval_bad_precision_word", "eval --checkpoint {ckpt} --precision float16", 2, "float16"},
      {"help_is_success", "--help", 0, "Exit status: 0 success"},
      {"version_is_success", "--version", 0, "^layersnet [0-9]"},
  };
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, ConfigsTheModelCannotBuildAreRefusedAtLoadNamingTheKey) {
  const std::string tiny = "config --config " + std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml --set ";
  const std::vector<Case> cases = {
      {"width_not_multiple_of_heads", tiny + "model.width=18 --set model.heads=4", 1,
       "model.width = 18 .*not a multiple of model.heads = 4"},
      {"odd_heads", tiny + "model.heads=3", 1, "model.heads = 3 .*must be even"},
      {"ret_channels_beyond_width", tiny + "model.decoder_ret_channels=100", 1, "model.decoder_ret_channels = 100"},
      {"huge_batch", tiny + "train.batch_size=1000000000", 1, "train.batch_size.*out of range"},
      {"no_body_neighbours", tiny + "model.body_neighbors=0", 1, "model.body_neighbors.*out of range"},
      {"negative_learning_rate", tiny + "train.learning_rate=-1", 1, "train.learning_rate.*out of range"},
      {"zero_epochs", tiny + "train.epochs=0", 1, "train.epochs.*out of range"},
      {"zero_patch_size", tiny + "model.patch_size=0", 1, "model.patch_size.*out of range"},
      {"nan_margin", tiny + "loss.collision_eps=nan", 1, "loss.collision_eps.*must be finite"},
      {"unknown_key", tiny + "nosuch.key=1", 1, "unknown key 'nosuch.key'"},
      {"text_for_integer", tiny + "train.seed=abc", 1, "train.seed"},
      {"include_of_a_folder", "config --config {case}/c.toml", 1, "is a directory, not a config file",
       [](const fs::path& d) { std::ofstream(d / "c.toml") << "include = \"" << d.string() << "\"\n"; }},
      {"missing_config", "config --config {case}/none.toml", 1, "none.toml"},
      {"toml_syntax_error", "config --config {case}/c.toml", 1, "c.toml",
       [](const fs::path& d) { std::ofstream(d / "c.toml") << "[model\nwidth = 3\n"; }},
  };
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, StressArgumentsAreRefusedBeforeAnyWork) {
  const std::vector<Case> cases = {
      {"stress_nan_wind", "stress --checkpoint {ckpt} --dataset {data} --winds nan", 2, "winds"},
      {"stress_negative_tether", "stress --checkpoint {ckpt} --dataset {data} --tether -1", 2, "tether"},
      {"stress_missing_checkpoint", "stress --checkpoint {case}/none.h5 --dataset {data}", 1, "none.h5"},
  };
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, CorruptHdf5IsRefusedNamingTheFileNotCrashed) {
  const std::vector<Case> cases = {
      {"segv_inspect", "inspect --check {case}/data", 1, "s0000.h5.*libhdf5 crashed reading this file.*corrupt",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("h5hg_read_segv")); }},
      {"segv_train", "train --config {root}/tiny.toml.dir/tiny.toml --set data.dataset={case}/data --run {case}/run", 1,
       "s0000.h5.*libhdf5 crashed",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("h5hg_read_segv")); }},
      {"segv_eval", "eval --checkpoint {ckpt} --dataset {case}/data --split train --out {case}/ev", 1,
       "s0000.h5.*libhdf5 crashed",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("h5hg_read_segv")); }},
      {"overlap_inspect", "inspect --check {case}/data", 1, "s0000.h5.*libhdf5 crashed",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("h5hg_read_memcpy_overlap")); }},
      {"hang_inspect", "inspect --check {case}/data", 1, "s0000.h5.*did not finish within 2 s",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("vlen_global_heap_hang")); },
       "LAYERSNET_HDF5_GUARD_SECONDS=2 "},
      {"hang_prepare", "prepare {case}/data", 1, "s0000.h5.*did not finish within 2 s",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("vlen_global_heap_hang")); },
       "LAYERSNET_HDF5_GUARD_SECONDS=2 "},
      {"huge_malloc_inspect", "inspect {case}/data", 1, "s0000.h5.*cannot be opened as HDF5",
       [](const fs::path& d) { data_with_first_sequence(d, known_issue("h5c_protect_huge_malloc")); }},
      {"truncated_sequence", "inspect {case}/data", 1, "s0000.h5.*(cannot be opened|corrupt)",
       [](const fs::path& d) { data_with_first_sequence(d, slurp(root_ / "data" / "s0000.h5").substr(0, 4000)); }},
      {"text_as_sequence", "inspect {case}/data", 1, "s0000.h5.*cannot be opened as HDF5",
       [](const fs::path& d) { data_with_first_sequence(d, "this is not HDF5\n"); }},
      {"empty_sequence", "inspect {case}/data", 1, "s0000.h5.*cannot be opened as HDF5",
       [](const fs::path& d) { data_with_first_sequence(d, ""); }},
      {"missing_dataset_json", "inspect {case}", 1, "dataset.json.*missing dataset.json"},
      {"corrupt_stats_h5", "eval --checkpoint {ckpt} --dataset {case}/data --split train --out {case}/ev", 1,
       "stats.h5.*cannot be opened as HDF5",
       [](const fs::path& d) {
         data_with_first_sequence(d, slurp(root_ / "data" / "s0000.h5"));
         std::ofstream(d / "data" / "stats.h5", std::ios::trunc) << "garbage";
       }},
  };
  // The training case needs a config that names the data set; written once.
  fs::create_directories(root_ / "tiny.toml.dir");
  std::ofstream(root_ / "tiny.toml.dir" / "tiny.toml")
      << "include = \"" << LAYERSNET_SOURCE_DIR << "/configs/tiny.toml\"\n";
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, AbsurdValuesAreRefusedNamingTheFileAndTheObject) {
  const auto edited = [](std::function<void(hid_t)> edit) {
    return [edit](const fs::path& d) { data_with_edited_sequence(d, edit); };
  };
  const std::vector<Case> cases = {
      {"garment_vertex_3e38", "inspect --check {case}/data", 1, "s0000.h5.*/garments/g0_tee/vertices",
       edited([](hid_t f) { set_first_value(f, "/garments/g0_tee/vertices", 3e38f); })},
      {"body_vertex_nan", "inspect --check {case}/data", 1, "s0000.h5.*/body/vertices",
       edited([](hid_t f) { set_first_value(f, "/body/vertices", std::nanf("")); })},
      {"body_vertex_3e38_prepare", "prepare {case}/data", 1, "s0000.h5.*/body/vertices",
       edited([](hid_t f) { set_first_value(f, "/body/vertices", 3e38f); })},
      {"mass_1e300", "inspect {case}/data", 1, "s0000.h5.*mass",
       edited([](hid_t f) {
         const hid_t g = H5Gopen2(f, "/garments/g0_tee", H5P_DEFAULT);
         dataset::h5::write_float_attr(g, "mass", 1e300);
         H5Gclose(g);
       })},
      {"negative_mass", "inspect {case}/data", 1, "s0000.h5.*mass",
       edited([](hid_t f) {
         const hid_t g = H5Gopen2(f, "/garments/g0_tee", H5P_DEFAULT);
         dataset::h5::write_float_attr(g, "mass", -1.0);
         H5Gclose(g);
       })},
      {"wrong_format_name", "inspect {case}/data", 1, "s0000.h5.*format",
       edited([](hid_t f) { dataset::h5::write_string_attr(f, "format", "not-dlayers"); })},
  };
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, MissingThingsAreNamed) {
  const std::vector<Case> cases = {
      {"resume_missing_run", "train --resume {case}/none", 1, "none"},
      {"eval_missing_run", "eval --run {case}/none", 1, "none"},
      {"prepare_missing_folder", "prepare {case}/none", 1, "none/dataset.json"},
      {"export_unknown_sequence", "export --checkpoint {ckpt} --dataset {data} --sequence nosuch --out {case}/x", 1,
       "nosuch"},
      // One line: the path, what the file is, that it is not in the repository, the way out.
      {"bench_model_missing_reference", "bench model --reference {case}/layersnet_torch.py", 2,
       "^[^\n]*--reference [^\n]*/layersnet_torch.py is missing: [^\n]*PyTorch port[^\n]*not in it[^\n]*"
       "--no-reference\n$"},
  };
  for (const auto& c : cases) expect_case(c);
}

// Each case runs in its own folder outside the sources: relative config paths the user's
// folder lacks are the program's own (configs/ beside the program); a missing one is named as typed.
TEST_F(Reliability, ConfigsAreFoundFromAnyFolder) {
  const std::vector<Case> cases = {
      {"shipped_config_by_relative_path", "config --config configs/tiny.toml", 0, "width = 16"},
      {"missing_config_named_as_typed", "config --config configs/none.toml", 1, "configs/none.toml"},
  };
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, DamagedCheckpointsAreRefused) {
  const auto damaged = [](std::size_t keep, const std::string& tail) {
    return [keep, tail](const fs::path& d) {
      std::ofstream(d / "c.h5", std::ios::binary | std::ios::trunc) << slurp(root_ / "tiny.h5").substr(0, keep) << tail;
    };
  };
  const auto flipped = [](const fs::path& d) {  // one byte of the first weight tensor's values
    std::string bytes = slurp(root_ / "tiny.h5");
    const hid_t f = H5Fopen((root_ / "tiny.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t g = H5Gopen2(f, "weights", H5P_DEFAULT);
    char name[256] = {};
    H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, 0, name, sizeof name, H5P_DEFAULT);
    const hid_t ds = H5Dopen2(g, name, H5P_DEFAULT);
    const haddr_t at = H5Dget_offset(ds);
    H5Dclose(ds);
    H5Gclose(g);
    H5Fclose(f);
    ASSERT_NE(at, HADDR_UNDEF);
    bytes[at + 1] = static_cast<char>(bytes[at + 1] ^ 0x5a);
    std::ofstream(d / "c.h5", std::ios::binary | std::ios::trunc) << bytes;
  };
  const std::vector<Case> cases = {
      {"missing_checkpoint", "eval --checkpoint {case}/none.h5 --dataset {data} --out {case}/ev", 1,
       "none.h5.*checkpoint not found"},
      {"truncated_checkpoint", "eval --checkpoint {case}/c.h5 --dataset {data} --out {case}/ev", 1,
       "c.h5.*(truncated|corrupt)", damaged(3000, "")},
      {"text_checkpoint", "eval --checkpoint {case}/c.h5 --dataset {data} --out {case}/ev", 1, "c.h5",
       damaged(0, "not a checkpoint")},
      {"flipped_byte_checkpoint", "eval --checkpoint {case}/c.h5 --dataset {data} --out {case}/ev", 1,
       "c.h5.*(checksum|corrupt)", flipped},
      {"hanging_checkpoint",
       "eval --checkpoint " + std::string(LAYERSNET_SOURCE_DIR) +
           "/fuzz/known_hdf5_issues/checkpoint_vlen_global_heap_hang.h5 --dataset {data} --out {case}/ev",
       1, "checkpoint_vlen_global_heap_hang.h5.*did not finish within 2 s", nullptr, "LAYERSNET_HDF5_GUARD_SECONDS=2 "},
      {"sequence_as_checkpoint", "eval --checkpoint {data}/s0000.h5 --dataset {data} --out {case}/ev", 1,
       "s0000.h5: format is 'dlayers-h5', expected 'layersnet-checkpoint'"},
  };
  for (const auto& c : cases) expect_case(c);
}

TEST_F(Reliability, AFullDiskIsOneClearErrorAndLosesNothing) {
  const std::string train = "train --config {root}/full.toml --set train.checkpoint_every=1 --run {case}/disk/run";
  std::ofstream(root_ / "full.toml") << "include = \"" << LAYERSNET_SOURCE_DIR << "/configs/tiny.toml\"\n"
                                     << "[data]\ndataset = \"" << (root_ / "data").string() << "\"\n";
  {  // training: the checkpoint that does not fit is an error; no temporary left, no crash at exit
    Case c{"full_train", train, 1, "step_0+[0-9]+\\.h5: cannot be written: (No space left on device|File too large)"};
    c.env = full_disk(root_ / c.name / "disk", 300, 100);  // a checkpoint is about 190 KiB
    expect_case(c);
    for (const auto& e : fs::recursive_directory_iterator(root_ / c.name / "disk"))
      EXPECT_NE(e.path().extension(), ".tmp") << e.path();
    Case resume{"full_train", "train --resume {case}/disk/run", 1, "cannot be written"};
    resume.env = c.env;
    expect_case(resume);
  }
  {  // prepare: the old statistics stay intact and readable
    Case c{"full_prepare", "prepare {case}/disk/data", 1, "stats.h5: cannot be written: (No space left|File too large)"};
    const fs::path disk = root_ / c.name / "disk";
    c.env = full_disk(disk, 200, 1);
    fs::copy(root_ / "data", disk / "data", fs::copy_options::recursive);
    if (c.env.empty()) fill(disk);
    const std::string before = slurp(disk / "data" / "stats.h5");
    expect_case(c);
    EXPECT_EQ(slurp(disk / "data" / "stats.h5"), before);
    EXPECT_FALSE(fs::exists(disk / "data" / "stats.h5.tmp"));
  }
  {  // eval: no empty eval.json is left, and the error names the file and the cause
    Case c{"full_eval", "eval --checkpoint {ckpt} --dataset {data} --speed-frames 2 --out {case}/disk/ev", 1,
           "eval.json: cannot be written: (No space left|File too large)"};
    const fs::path disk = root_ / c.name / "disk";
    c.env = full_disk(disk, 64, 1);
    if (c.env.empty()) fill(disk);
    expect_case(c);
    EXPECT_FALSE(fs::exists(disk / "ev" / "eval.json"));
    EXPECT_FALSE(fs::exists(disk / "ev" / "eval.json.tmp"));
  }
}

TEST_F(Reliability, ARunDirectoryInUseNamesItsHolder) {
  const fs::path run = root_ / "locked" / "run";
  {
    Case fresh{"locked", "train --config {root}/full.toml --set train.epochs=1 --run {case}/run", 0, "done:"};
    std::ofstream(root_ / "full.toml") << "include = \"" << LAYERSNET_SOURCE_DIR << "/configs/tiny.toml\"\n"
                                       << "[data]\ndataset = \"" << (root_ / "data").string() << "\"\n";
    expect_case(fresh);
    expect_case({"locked", "train --config {root}/full.toml --run {case}/run", 1, "already holds a run.*--resume"});
  }
  const int fd = ::open((run / "lock").c_str(), O_RDWR);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);  // as a running trainer holds it
  expect_case({"locked", "train --resume {case}/run --set train.epochs=2", 1, "is in use by a running `layersnet train`"});
  ::close(fd);
  expect_case({"locked", "train --resume {case}/run --set train.epochs=2", 0, "done:"});
}

}  // namespace
}  // namespace layersnet
