// The run directory's layout: which checkpoint stands for a run.
#include "run/run_dir.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace layersnet {
namespace {

namespace fs = std::filesystem;

TEST(RunDir, BestElseNewestCheckpointElseAnErrorNamingTheFolder) {
  const fs::path run = fs::temp_directory_path() / ("layersnet_run_dir_" + std::to_string(::getpid()));
  fs::remove_all(run);
  fs::create_directories(run / "checkpoints");
  EXPECT_FALSE(holds_run(run.string()));
  try {
    (void)run_checkpoint(run.string());
    ADD_FAILURE() << "no checkpoint, no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(run.string() + ": no best.h5"), std::string::npos) << e.what();
  }
  for (int64_t step : {20, 100, 3}) std::ofstream(checkpoint_path(run.string(), step)) << "x";
  std::ofstream(run / "checkpoints" / "step_00000200.h5.tmp") << "x";  // a write cut short
  EXPECT_EQ(run_checkpoint(run.string()), checkpoint_path(run.string(), 100));
  std::ofstream(best_checkpoint_path(run.string())) << "x";
  EXPECT_EQ(run_checkpoint(run.string()), (run / "best.h5").string());
  EXPECT_TRUE(holds_run(run.string()));
  fs::remove_all(run);
}

}  // namespace
}  // namespace layersnet
