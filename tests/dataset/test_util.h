#pragma once
// Helpers shared by the data-layer tests: a fresh temporary folder per test and a runner
// for the project's Python validator (dataset/check_dlayers_h5.py, independent of the C++ reader).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>

namespace layersnet::dataset::testing {

// A temporary folder removed when the object goes out of scope.
struct TempDir : std::filesystem::path {
  explicit TempDir(std::filesystem::path p) : std::filesystem::path(std::move(p)) {}
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(*this, ec);
  }
};

inline std::filesystem::path temp_path(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::filesystem::path p = std::filesystem::temp_directory_path() /
                            ("layersnet_ds_" + std::to_string(::getpid()) + "_" + info->name() + "_" + name);
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p;
}

inline TempDir temp_dir(const std::string& name) { return TempDir(temp_path(name)); }

inline std::string validator_path() {
  return std::string(LAYERSNET_SOURCE_DIR) + "/dataset/check_dlayers_h5.py";
}

// Runs the validator on `path`; returns its exit status and its output in `out`.
inline int run_validator(const std::string& path, std::string* out) {
  const std::string cmd = "/usr/bin/python3 '" + validator_path() + "' '" + path + "' 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return -1;
  char buf[512];
  while (fgets(buf, sizeof buf, pipe)) *out += buf;
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace layersnet::dataset::testing
