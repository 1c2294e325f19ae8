// `layersnet prepare` then `layersnet inspect` on a synthetic data set: what it reports about
// sequences, garments, wind, statistics, patches, world edges and margins, and a broken file named.
#include "dataset/manifest.h"
#include "dataset/sequence.h"
#include "dataset/synthetic.h"
#include "inspect/inspect.h"
#include "tests/dataset/test_util.h"

#include <cmath>
#include <cstdio>
#include <random>
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
  // Motion: every frame after the ramp (no ramp attrs: from frame 0, so T - 1 steps each).
  out = run(std::string(LAYERSNET_BINARY) + " inspect --brief --motion " + dir.string(), &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("train 2 sequences, " + std::to_string(2 * (o.frames - 1)) + " frames"), std::string::npos) << out;
  EXPECT_NE(out.find("body speed, m/s: mean "), std::string::npos) << out;
  EXPECT_NE(out.find("garment speed against the body"), std::string::npos) << out;
  // A broken data set: the error names the file and the problem, exit status 1.
  std::filesystem::resize_file(dir / "s0001.h5", 100);
  out = run(std::string(LAYERSNET_BINARY) + " inspect " + dir.string(), &status);
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("s0001.h5: /: cannot be opened as HDF5"), std::string::npos) << out;
}

// A cloud turned about the up axis and moved: the step recovers speed and turn rate, for z up
// and y up, and a still body has neither.
TEST(Inspect, BodyStepRecoversSpeedAndTurnRate) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-2.f, 2.f);
  Points before(200, 3);
  for (Eigen::Index i = 0; i < before.rows(); ++i) before.row(i) << u(rng), u(rng), u(rng);
  before.rowwise() -= before.colwise().mean().eval();  // turned about its centroid, which stays put
  const double yaw = 0.05, fps = 30, scale = 10;
  for (char up : {'z', 'y'}) {
    const int a = up == 'z' ? 0 : 2, b = up == 'z' ? 1 : 0;
    Points after = before;
    for (Eigen::Index i = 0; i < before.rows(); ++i) {
      after(i, a) = static_cast<float>(std::cos(yaw) * before(i, a) - std::sin(yaw) * before(i, b));
      after(i, b) = static_cast<float>(std::sin(yaw) * before(i, a) + std::cos(yaw) * before(i, b));
    }
    after.col(a).array() += 0.06f, after.col(b).array() -= 0.08f;  // 0.1 units per frame
    const eval::BodyStep step = eval::body_step(before, after, up, fps, scale);
    EXPECT_NEAR(step.speed, 0.1 * fps / scale, 1e-5) << up;
    EXPECT_NEAR(step.turn_rate, yaw / (2 * M_PI) * fps, 1e-5) << up;
    const eval::BodyStep still = eval::body_step(before, before, up, fps, scale);
    EXPECT_EQ(still.speed, 0.0);
    EXPECT_NEAR(still.turn_rate, 0.0, 1e-9);
  }
}

}  // namespace
}  // namespace layersnet::dataset
