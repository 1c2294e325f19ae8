// `layersnet prepare` then `layersnet inspect` on a synthetic data set: what it reports about
// sequences, garments, wind, statistics, patches, world edges and margins, and a broken file named.
#include "dataset/manifest.h"
#include "dataset/sequence.h"
#include "dataset/synthetic.h"
#include "tests/dataset/test_util.h"

#include <cstdio>
#include <filesystem>
#include <string>

namespace layersnet::dataset {
namespace {

std::string run(const std::string& cmd, int* status) {
  std::string out;
  FILE* pipe = popen((cmd + " 2>&1").c_str(), "r");
  char buf[512];
  while (pipe && fgets(buf, sizeof buf, pipe)) out += buf;
  const int s = pipe ? pclose(pipe) : -1;
  *status = WIFEXITED(s) ? WEXITSTATUS(s) : -1;
  return out;
}

TEST(Inspect, AfterPrepare) {
  if (!std::filesystem::exists(LAYERSNET_BINARY)) GTEST_SKIP() << "layersnet binary not built";
  const auto dir = testing::temp_dir("cli");
  SyntheticOptions o;
  o.garments = 2;
  o.wind = true;
  write_synthetic_dataset(dir.string(), 2, 1, 1, o);
  int status = 0;
  std::string out = run(std::string(LAYERSNET_BINARY) + " inspect " + dir.string(), &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("4 sequences (train 2, val 1, test 1)"), std::string::npos) << out;
  EXPECT_NE(out.find("stats.h5: missing (create it with `layersnet prepare"), std::string::npos) << out;
  EXPECT_NE(out.find("garment g1_jacket"), std::string::npos) << out;
  EXPECT_NE(out.find("wind: 3 segment(s)"), std::string::npos) << out;
  EXPECT_NE(out.find("wind: none"), std::string::npos) << out;
  out = run(std::string(LAYERSNET_BINARY) + " prepare " + dir.string(), &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_TRUE(std::filesystem::exists(dir / "stats.h5"));
  out = run(std::string(LAYERSNET_BINARY) + " inspect --check " + dir.string(), &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("stats.h5: from 2 training sequences"), std::string::npos) << out;
  // Patch size and world radius from a config; a flag overrides the config. The synthetic tubes
  // have no rest/ramp attrs: edges at the first sample frame.
  const std::string quick = std::string(LAYERSNET_SOURCE_DIR) + "/configs/quick.toml";
  out = run(std::string(LAYERSNET_BINARY) + " inspect --brief " + dir.string() + " --config " + quick, &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("patches (size 0.1)"), std::string::npos) << out;
  EXPECT_NE(out.find("cross-garment world edges (world radius 0.4, "), std::string::npos) << out;
  out = run(std::string(LAYERSNET_BINARY) + " inspect " + dir.string() + " --config " + quick + " --world-radius 1000", &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("at frame 2: "), std::string::npos) << out;
  EXPECT_NE(out.find("(min "), std::string::npos) << out;
  EXPECT_NE(out.find("world radius 1000, at the first frame after each ramp, else 2): "), std::string::npos) << out;
  EXPECT_NE(out.find("0.0% with none"), std::string::npos) << out;
  // Margins: every garment vertex of every training frame (no ramp attrs: from frame 0) is
  // measured against the body; outer-garment vertices against the inner garment.
  out = run(std::string(LAYERSNET_BINARY) + " inspect --brief --margins " + dir.string(), &status);
  EXPECT_EQ(status, 0) << out;
  int64_t all = 0, outer = 0;
  for (const auto& id : read_manifest(dir.string()).train) {
    const SequenceInfo info = SequenceFile((dir / (id + ".h5")).string()).info();
    for (const auto& g : info.garments) all += static_cast<int64_t>(g.num_vertices) * info.num_frames;
    outer += static_cast<int64_t>(info.garments.back().num_vertices) * info.num_frames;
  }
  EXPECT_NE(out.find("garment to nearest body vertex (" + std::to_string(all) + " vertex-frames)"), std::string::npos) << out;
  EXPECT_NE(out.find("outer garment to nearest inner vertex (" + std::to_string(outer) + " vertex-frames)"), std::string::npos)
      << out;
  // A broken data set: the error names the file and the problem, exit status 1.
  std::filesystem::resize_file(dir / "s0001.h5", 100);
  out = run(std::string(LAYERSNET_BINARY) + " inspect " + dir.string(), &status);
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("s0001.h5: /: cannot be opened as HDF5"), std::string::npos) << out;
}

}  // namespace
}  // namespace layersnet::dataset
