// Normalisation statistics against a brute-force computation, stats.h5 round trip and
// validator (`layersnet inspect` on a prepared data set: tests/inspect).
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "dataset/wind.h"
#include "test_util.h"

#include <array>
#include <filesystem>

namespace layersnet::dataset {
namespace {

TEST(Stats, MatchesBruteForceOverTheTrainingSplitOnly) {
  const auto dir = testing::temp_dir("stats");
  SyntheticOptions o;
  o.garments = 2;
  o.frames = 7;
  const DatasetManifest m = write_synthetic_dataset(dir.string(), 2, 1, 0, o);
  StatsOptions so;
  so.window_frames = 3;  // windows split the sequence: differences must still cross them
  const NormalisationStats s = compute_stats(m, so);
  // Brute force in double over train sequences, garments and body.
  std::vector<Eigen::Vector3d> pos, vel, acc;
  for (const auto& id : m.train) {
    const Sequence q = read_sequence(m.sequence_path(id));
    auto rel = [&](int t) {
      Eigen::MatrixX3d x(q.info.total_garment_vertices() + q.info.num_body_vertices, 3);
      x << q.garment_at(0, t).cast<double>(), q.garment_at(1, t).cast<double>(), q.body_at(t).cast<double>();
      x.rowwise() -= q.info.translation.row(t).cast<double>();
      return x;
    };
    for (int t = 0; t < q.info.num_frames; ++t) {
      const Eigen::MatrixX3d x = rel(t);
      for (Eigen::Index i = 0; i < x.rows(); ++i) {
        pos.push_back(x.row(i).transpose());
        if (t >= 1) vel.push_back((x.row(i) - rel(t - 1).row(i)).transpose());
        if (t >= 2) acc.push_back((x.row(i) - 2 * rel(t - 1).row(i) + rel(t - 2).row(i)).transpose());
      }
    }
  }
  auto check = [](const std::vector<Eigen::Vector3d>& v, const MeanStd& got) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero(), var = Eigen::Vector3d::Zero();
    for (const auto& x : v) mean += x;
    mean /= static_cast<double>(v.size());
    for (const auto& x : v) var += (x - mean).cwiseAbs2();
    var /= static_cast<double>(v.size());
    EXPECT_EQ(got.count, static_cast<int64_t>(v.size()));
    EXPECT_TRUE(got.mean.isApprox(mean, 1e-6) || (got.mean - mean).norm() < 1e-9);
    EXPECT_TRUE(got.std.isApprox(var.cwiseSqrt(), 1e-5));
  };
  check(pos, s.position);
  check(vel, s.velocity);
  check(acc, s.acceleration);
  EXPECT_EQ(s.sequences, m.train);
  EXPECT_EQ(s.root_velocity.count, 2 * 6);
}

TEST(Stats, RoundTripZeroStdStoredAsOneAndValidatorAgrees) {
  const auto dir = testing::temp_dir("statsrt");
  const DatasetManifest m = write_synthetic_dataset(dir.string(), 1, 1, 0);
  NormalisationStats s = compute_stats(m);
  // The synthetic root moves in x and y only: root z velocity has std 0 -> stored as 1.
  EXPECT_EQ(s.root_velocity.std[2], 1.0);
  write_stats(m.stats_path(), s);
  const NormalisationStats r = load_stats_or_explain(m);
  EXPECT_TRUE(r.position.mean.isApprox(s.position.mean));
  EXPECT_TRUE(r.velocity.std.isApprox(s.velocity.std));
  EXPECT_EQ(r.acceleration.count, s.acceleration.count);
  EXPECT_EQ(r.sequences, m.train);
  std::string out;
  EXPECT_EQ(testing::run_validator(dir.string(), &out), 0) << out;
}

TEST(Stats, MissingStatsSaysWhichCommandMakesThem) {
  const auto dir = testing::temp_dir("nostats");
  const DatasetManifest m = write_synthetic_dataset(dir.string(), 1, 0, 0);
  try {
    load_stats_or_explain(m);
    FAIL() << "accepted a data set without stats.h5";
  } catch (const DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("layersnet prepare " + dir.string()), std::string::npos) << e.what();
  }
}

TEST(Stats, StatisticsOfAnotherTrainingSplitAreRefusedWithTheFix) {
  const auto dir = testing::temp_dir("stalestats");
  const DatasetManifest m = write_synthetic_dataset(dir.string(), 2, 0, 0);
  NormalisationStats s = compute_stats(m);
  EXPECT_EQ(stats_split_mismatch(s, m), "");
  s.sequences.pop_back();  // as if copied from a set with one training sequence fewer
  write_stats(m.stats_path(), s);
  try {
    load_stats_or_explain(m);
    FAIL() << "accepted statistics of a smaller training split";
  } catch (const DatasetError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("computed from 1 of the 2 training sequences (not from '" + m.train[1] + "')"), std::string::npos)
        << what;
    EXPECT_NE(what.find("layersnet prepare " + dir.string()), std::string::npos) << what;
  }
  EXPECT_EQ(load_stats_or_explain(m, /*require_training_split=*/false).sequences.size(), 1u);
  s.sequences = {m.train[0], "elsewhere"};
  EXPECT_NE(stats_split_mismatch(s, m).find("'elsewhere' which is not in the train split"), std::string::npos);
}

TEST(Stats, ANamedStatisticsFileIsUsedWithANoteAndAMissingOneNamed) {
  const auto dir = testing::temp_dir("namedstats");
  const DatasetManifest m = write_synthetic_dataset(dir.string(), 2, 0, 0);
  NormalisationStats s = compute_stats(m);
  s.sequences.pop_back();  // the statistics of the set this one grew from
  const std::string parent = (dir / "parent_stats.h5").string();
  write_stats(parent, s);
  std::string note;
  EXPECT_EQ(load_training_stats(m, parent, true, &note).sequences.size(), 1u);
  EXPECT_NE(note.find(parent), std::string::npos) << note;
  EXPECT_NE(note.find("computed from 1 of the 2 training sequences"), std::string::npos) << note;
  note.clear();
  write_stats(parent, compute_stats(m));
  load_training_stats(m, parent, true, &note);
  EXPECT_EQ(note, "");  // from the training split: nothing to say
  try {
    load_training_stats(m, (dir / "nowhere.h5").string(), true, &note);
    FAIL() << "accepted a missing statistics file";
  } catch (const DatasetError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("nowhere.h5"), std::string::npos) << what;
    EXPECT_NE(what.find("data.stats"), std::string::npos) << what;
  }
}

TEST(Wind, SegmentsAndDirections) {
  SyntheticOptions o;
  o.wind = true;
  o.frames = 9;
  const Sequence s = make_synthetic_sequence(o);
  const auto seg = wind_segments(s.info);
  ASSERT_EQ(seg.size(), 3u);
  EXPECT_EQ(seg[0].begin, 0);
  EXPECT_EQ(seg[0].end, 3);
  EXPECT_EQ(seg[0].strength, 0.f);
  EXPECT_EQ(seg[2].strength, 300.f);
  // Identity quaternion blows along +z; the all-zero quaternion is the identity.
  EXPECT_TRUE(wind_direction(Eigen::Vector4f(1, 0, 0, 0)).isApprox(Eigen::Vector3f(0, 0, 1)));
  EXPECT_TRUE(quaternion_matrix(Eigen::Vector4f::Zero()).isIdentity());
  // 90 degrees about x: +z -> -y.
  const float h = std::sqrt(0.5f);
  EXPECT_TRUE(wind_direction(Eigen::Vector4f(h, h, 0, 0)).isApprox(Eigen::Vector3f(0, -1, 0), 1e-5f));
  o.wind = false;
  EXPECT_TRUE(wind_segments(make_synthetic_sequence(o).info).empty());
}

}  // namespace
}  // namespace layersnet::dataset
