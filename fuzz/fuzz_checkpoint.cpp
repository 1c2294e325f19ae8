// libFuzzer target over checkpoint loading (scripts/fuzz.sh builds and runs it). The input is
// the bytes of a checkpoint file, loaded as `eval`, `export`, `simulate` and `train --resume`
// load one (load_model: config text, parameter layout, weights, Adam moments, statistics,
// checksum), through the same HDF5 guard. Every rejection must be an exception; a crash, hang,
// leak or sanitizer report is a finding.
#include "run/checkpoint.h"

#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "fuzz_checkpoint_" + std::to_string(::getpid()) + ".h5";
  {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  try {
    (void)layersnet::load_model(path);
  } catch (const std::exception&) {
  }
  return 0;
}
