#pragma once
// Helpers of the eval suite's end-to-end tests: run the `layersnet` binary, read a file.
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace layersnet::eval::cli_test {

// Runs `layersnet ARGS` (stderr merged into the returned text); *code = its exit status (-1 if killed).
inline std::string run_cli(const std::string& args, int* code) {
  const std::string cmd = std::string(LAYERSNET_BINARY) + " " + args + " 2>&1";
  std::FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  while (std::fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  *code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace layersnet::eval::cli_test
