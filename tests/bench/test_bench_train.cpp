// `layersnet bench train --dataset DIR`: the training throughput of a config measured on a given
// data set (through `train` itself), so that the cost of reading real files is in the figure.
#include "tests/dataset/test_util.h"
#include "tests/eval/cli_test_util.h"

#include <gtest/gtest.h>

namespace layersnet {
namespace {

TEST(BenchTrain, MeasuresOnAGivenDataSet) {
  const auto root = dataset::testing::temp_dir("bench_train");
  eval::cli_test::write_tiny_data_and_checkpoint(root, 2, 1, 0, /*wind=*/false);
  int code = 0;
  const std::string text = eval::cli_test::run_cli("bench train --config " + std::string(LAYERSNET_SOURCE_DIR) +
                                                 "/configs/tiny.toml --set data.first_frame=2 --dataset " +
                                                 (root / "data").string() + " --threads 1 --steps 2 --rollout 1",
                                             &code);
  EXPECT_EQ(code, 0) << text;
  EXPECT_NE(text.find("on " + (root / "data").string()), std::string::npos) << text;
  EXPECT_NE(text.find("samples/s"), std::string::npos) << text;
  int missing = 0;
  EXPECT_NE(eval::cli_test::run_cli("bench train --dataset " + (root / "absent").string(), &missing).find("absent"),
            std::string::npos);
  EXPECT_NE(missing, 0);
}

}  // namespace
}  // namespace layersnet
