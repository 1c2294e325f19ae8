// `layersnet bench model`'s choice of the reference's BLAS kernel: the probe's parsing, the
// kernels offered for this CPU, and the whole choice end to end against a stand-in python whose
// GEMM rate depends on OPENBLAS_CORETYPE; and an unknown float32 GEMM kernel in LAYERSNET_F32_GEMM.
#include "bench/bench_model.h"

#include "tests/eval/cli_test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

using layersnet::eval::openblas_cores_for_this_cpu;
using layersnet::eval::parse_blas_probe;
namespace fs = std::filesystem;

TEST(BenchModelBlas, ParsesTheKernelAndTheRate) {
  const auto p = parse_blas_probe("Core not found: Cooperlake\nCore: SkylakeX\ngemm_gflops 183.25\n");
  EXPECT_EQ(p.core, "SkylakeX");
  EXPECT_DOUBLE_EQ(p.gflops, 183.25);
}

TEST(BenchModelBlas, MissingOrBrokenLinesGiveNothing) {
  EXPECT_EQ(parse_blas_probe("").core, "");
  EXPECT_EQ(parse_blas_probe("Traceback: no module named torch\n").gflops, 0.0);
  EXPECT_EQ(parse_blas_probe("gemm_gflops 12x\n").gflops, 0.0);
  EXPECT_EQ(parse_blas_probe("gemm_gflops nan\n").gflops, 0.0);
  EXPECT_EQ(parse_blas_probe("gemm_gflops -3\n").gflops, 0.0);
}

TEST(BenchModelBlas, KernelsComeOldestFirstAndNeedTheirPredecessors) {
  const auto cores = openblas_cores_for_this_cpu();
  const std::vector<std::string> order = {"Haswell", "SkylakeX", "Cooperlake", "SapphireRapids"};
  // Each kernel offered implies every older one: they are cumulative instruction sets.
  ASSERT_LE(cores.size(), order.size());
  for (std::size_t i = 0; i < cores.size(); ++i) EXPECT_EQ(cores[i], order[i]);
}

// The stand-in reports OPENBLAS_CORETYPE (Prescott when unset) at a rate that rises with the
// kernel's age rank, and as the reference it writes timings whose peak memory is that rank, so
// the report shows which kernel the reference itself ran with.
TEST(BenchModelBlas, TheReferenceRunsOnTheFastestProbedKernel) {
  const fs::path dir = fs::temp_directory_path() / ("layersnet_bench_blas_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path python = dir / "python", reference = dir / "layersnet_torch.py", report = dir / "out.json";
  std::ofstream(reference) << "# stand-in\n";
  std::ofstream(python) << R"sh(#!/bin/bash
core=${OPENBLAS_CORETYPE:-Prescott}
rank=0
for k in Prescott Haswell SkylakeX Cooperlake SapphireRapids; do [ "$k" = "$core" ] && break; rank=$((rank + 1)); done
case "$2" in
  *gemm_gflops*) echo "Core: $core"; echo "gemm_gflops $((100 + 10 * rank))" ;;
  *) json=$(echo "$2" | sed -n "s/.*'--json', '\([^']*\)'.*/\1/p")
     echo "{\"timing\": {\"train_step\": {\"median_ms\": 500}, \"rollout_step\": {\"median_ms\": 100}},
       \"flops_forward\": {\"total\": 1e9}, \"peak_rss_mib\": $rank, \"scene\": {}}" > "$json" ;;
esac
)sh";
  fs::permissions(python, fs::perms::owner_all);
  int code = 0;
  const std::string out = layersnet::eval::cli_test::run_cli(
      "bench model --size small --threads 1 --passes 1 --iters 1 --warmup 0 --reference " + reference.string() +
          " --python " + python.string() + " --json " + report.string(),
      &code);
  ASSERT_EQ(code, 0) << out;
  const auto j = nlohmann::json::parse(layersnet::eval::cli_test::slurp(report));
  const auto cores = openblas_cores_for_this_cpu();
  // With OPENBLAS_CORETYPE set for the whole test run, the environment's kernel is a candidate too.
  const char* env = std::getenv("OPENBLAS_CORETYPE");
  std::string expected = cores.empty() ? "" : cores.back();
  const std::vector<std::string> order = {"Prescott", "Haswell", "SkylakeX", "Cooperlake", "SapphireRapids"};
  auto rank = [&](const std::string& k) { return std::find(order.begin(), order.end(), k) - order.begin(); };
  const std::string own = env && *env ? env : "Prescott";
  if (expected.empty() || rank(own) >= rank(expected)) expected = "";  // the environment's is fastest
  EXPECT_EQ(j["reference_blas"]["openblas_coretype"], expected) << out;
  EXPECT_EQ(j["reference_blas"]["core"], expected.empty() ? own : expected) << out;
  EXPECT_EQ(j["reference_blas"]["probes"].size(), cores.size() + 1) << out;
  const double expected_rank = rank(expected.empty() ? own : expected);
  EXPECT_EQ(j["rows"][0]["torch_peak_rss_mib"].get<double>(), expected_rank) << out;
  fs::remove_all(dir);
}

// A float32 GEMM kernel named in LAYERSNET_F32_GEMM that does not exist is an error naming the
// variable and the choices, before any work.
TEST(BenchModelGemmKernel, AnUnknownKernelIsAnErrorNamingTheVariable) {
  const char* before = std::getenv("LAYERSNET_F32_GEMM");
  const std::string saved = before ? before : "";
  ::setenv("LAYERSNET_F32_GEMM", "sse", 1);
  int code = 0;
  const std::string out = layersnet::eval::cli_test::run_cli(
      "bench model --size small --threads 1 --no-reference --passes 1 --iters 1 --warmup 0", &code);
  if (before) ::setenv("LAYERSNET_F32_GEMM", saved.c_str(), 1);
  else ::unsetenv("LAYERSNET_F32_GEMM");
  EXPECT_EQ(code, 1) << out;
  EXPECT_NE(out.find("LAYERSNET_F32_GEMM=sse"), std::string::npos) << out;
  EXPECT_NE(out.find("choose avx512, avx2 or eigen"), std::string::npos) << out;
}

}  // namespace
