// Training samples: every tensor checked against its definition in dataset/sample.h.
#include "dataset/sample.h"
#include "dataset/synthetic.h"
#include "dataset/wind.h"

#include <gtest/gtest.h>
#include <omp.h>

namespace layersnet::dataset {
namespace {

NormalisationStats simple_stats() {
  NormalisationStats s;
  s.position = {Eigen::Vector3d(0.1, 0.2, 1.0), Eigen::Vector3d(2, 2, 4), 1};
  s.velocity = {Eigen::Vector3d(0.0, 0.01, 0.0), Eigen::Vector3d(0.5, 0.5, 0.25), 1};
  s.acceleration = {Eigen::Vector3d(0, 0, -0.1), Eigen::Vector3d(0.1, 0.1, 0.2), 1};
  s.root_velocity = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.1, 0.1, 1), 1};
  s.root_acceleration = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.01, 0.01, 1), 1};
  return s;
}

Sequence scene(int garments, bool wind) {
  SyntheticOptions o;
  o.garments = garments;
  o.wind = wind;
  o.frames = 10;
  return make_synthetic_sequence(o);
}

TEST(Sample, StatesTargetsAndBodyFollowTheirDefinitions) {
  const Sequence seq = scene(2, true);
  const auto st = simple_stats();
  const int t = 5;
  const TrainingSample s = build_sample(seq.info, seq.frames, t, st, nullptr);
  const int N = 2 * seq.info.garments[0].num_vertices, B = seq.info.num_body_vertices;
  ASSERT_EQ(s.state.rows(), N);
  ASSERT_EQ(s.state.cols(), 12);
  ASSERT_EQ(s.body_state.rows(), B);
  ASSERT_EQ(s.target.cols(), 6);
  auto rel = [&](int g, int v, int f) {
    return Eigen::RowVector3f(seq.garment_at(g, f).row(v) - seq.info.translation.row(f));
  };
  const int n0 = seq.info.garments[0].num_vertices;
  for (int v : {0, 17, n0 + 3}) {  // a vertex of each garment
    const int g = v < n0 ? 0 : 1, lv = v < n0 ? v : v - n0;
    EXPECT_TRUE(s.state.row(v).segment<3>(0).isApprox(rel(g, lv, t)));
    EXPECT_TRUE(s.state.row(v).segment<3>(3).isApprox(rel(g, lv, t) - rel(g, lv, t - 1), 1e-4f));
    EXPECT_TRUE(s.state.row(v).segment<3>(6).isApprox(rel(g, lv, t - 1)));
    EXPECT_TRUE(s.state.row(v).segment<3>(9).isApprox(rel(g, lv, t - 1) - rel(g, lv, t - 2), 1e-4f));
    EXPECT_TRUE(s.target.row(v).segment<3>(0).isApprox(rel(g, lv, t + 1)));
    EXPECT_TRUE(s.target.row(v).segment<3>(3).isApprox(rel(g, lv, t + 1) - rel(g, lv, t), 1e-4f));
    // Normalised: position columns with position stats, velocity columns with velocity stats.
    EXPECT_NEAR(s.state_norm(v, 2), (s.state(v, 2) - 1.0f) / 4.f, 1e-5f);
    EXPECT_NEAR(s.state_norm(v, 4), (s.state(v, 4) - 0.01f) / 0.5f, 1e-5f);
    EXPECT_NEAR(s.state_norm(v, 11), s.state(v, 11) / 0.25f, 1e-5f);
  }
  const Eigen::RowVector3f b_next = seq.body_at(t + 1).row(7) - seq.info.translation.row(t + 1);
  const Eigen::RowVector3f b_now = seq.body_at(t).row(7) - seq.info.translation.row(t);
  EXPECT_TRUE(s.body_state.row(7).segment<3>(0).isApprox(b_next));
  EXPECT_TRUE(s.body_state.row(7).segment<3>(3).isApprox(b_next - b_now, 1e-4f));
  EXPECT_TRUE(s.body_state.row(7).segment<3>(6).isApprox(b_now));
  EXPECT_TRUE(s.root_translation_next.isApprox(seq.info.translation.row(t + 1).transpose()));
}

TEST(Sample, PatchesAttributesAndNeighbours) {
  const Sequence seq = scene(2, false);
  const TrainingSample s = build_sample(seq.info, seq.frames, 4, simple_stats(), nullptr);
  const SequenceStructure& S = *s.structure;
  ASSERT_EQ(s.patch_state.rows(), S.num_patches());
  EXPECT_EQ(S.patch_offsets.size(), 3u);
  EXPECT_EQ(S.vertex_garment.back(), 1);
  // Patch state = mean of member states.
  const int p = S.num_patches() - 1;
  Eigen::Matrix<float, 1, 12> mean = Eigen::Matrix<float, 1, 12>::Zero();
  for (const int32_t* v = S.all.patch_vertices.begin(p); v != S.all.patch_vertices.end(p); ++v) mean += s.state.row(*v);
  mean /= static_cast<float>(S.all.patch_vertices.size(p));
  EXPECT_TRUE(s.patch_state.row(p).isApprox(mean, 1e-5f));
  // Attributes: official ranges, one row per distinct garment.
  const auto& a = seq.info.garments[1].attributes;
  EXPECT_NEAR(S.attributes(S.garment_attribute[1], 2), (a.mass - 0.2f) / 0.6f, 1e-6f);
  EXPECT_NEAR(S.attributes(S.garment_attribute[1], 4), (seq.info.body_friction - 40.f) / 40.f, 1e-6f);
  EXPECT_EQ(S.attributes.rows(), 2);
  // World edges: within R, never mesh-adjacent; inner-outer layer pairs appear.
  int cross_layer = 0;
  for (int i = 0; i < s.num_patches(); ++i)
    for (const int32_t* j = s.world_edges.begin(i); j != s.world_edges.end(i); ++j) {
      EXPECT_LT((s.patch_state.row(i).head<3>() - s.patch_state.row(*j).head<3>()).norm(), 0.4f);
      EXPECT_FALSE(std::binary_search(S.all.adjacency.begin(i), S.all.adjacency.end(i), *j));
      cross_layer += S.patch_garment[i] != S.patch_garment[*j];
    }
  EXPECT_GT(cross_layer, 0);
  // Body neighbours and nearest-body normals.
  EXPECT_EQ(s.body_neighbours.index.rows(), s.num_patches());
  EXPECT_EQ(s.body_neighbours.index.cols(), 16);
  EXPECT_EQ(s.vertex_body_normal.rows(), s.num_vertices());
  EXPECT_TRUE(s.vertex_body_normal.allFinite());
  EXPECT_NEAR(s.patch_body_normal.row(0).norm(), 1.f, 1e-5f);
  EXPECT_TRUE(s.has_layers);
  EXPECT_FALSE(s.has_wind);
  EXPECT_EQ(s.wind.rows(), 0);
}

// outer_to_inner_world_edges against an all-pairs count of patch centres (means of member
// vertices, in double): a radius below the layer gap gives none, a huge one every inner patch.
TEST(Sample, CrossGarmentWorldEdgesMatchAHandCount) {
  const Sequence seq = scene(2, false);
  const int t = 5;
  const auto structure = build_structure(seq.info, kDefaultPatchSize);
  const PatchStructure& inner = structure->garments[0];
  const PatchStructure& outer = structure->garments[1];
  auto centres = [&](int g, const PatchStructure& ps) {
    std::vector<Eigen::Vector3d> c;
    for (int p = 0; p < ps.num_patches; ++p) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (const int32_t* v = ps.patch_vertices.begin(p); v != ps.patch_vertices.end(p); ++v)
        sum += seq.garment_at(g, t).row(*v).transpose().cast<double>();
      c.push_back(sum / ps.patch_vertices.size(p));
    }
    return c;
  };
  const auto ci = centres(0, inner), co = centres(1, outer);
  double closest = 1e9;
  for (const auto& a : co)
    for (const auto& b : ci) closest = std::min(closest, (a - b).norm());
  ASSERT_GT(closest, 0.1);  // the tubes are a layer gap (0.25) apart
  for (const double radius : {0.05, 0.6, 1e3}) {
    SCOPED_TRACE("radius " + std::to_string(radius));
    SampleOptions o;
    o.neighbours.world_radius = static_cast<float>(radius);
    const auto counts = outer_to_inner_world_edges(build_sample(seq.info, seq.frames, t, simple_stats(), structure, o));
    ASSERT_EQ(counts.size(), static_cast<std::size_t>(outer.num_patches));
    int64_t total = 0;
    for (int p = 0; p < outer.num_patches; ++p) {
      int expected = 0;
      for (const auto& b : ci) {
        const double d = (co[static_cast<std::size_t>(p)] - b).norm();
        ASSERT_GT(std::abs(d - radius), 1e-4) << "a pair on the radius: the count would hang on rounding";
        expected += d < radius;
      }
      EXPECT_EQ(counts[static_cast<std::size_t>(p)], expected) << "outer patch " << p;
      total += counts[static_cast<std::size_t>(p)];
    }
    if (radius < closest) {
      EXPECT_EQ(total, 0);
    } else if (radius > 100) {
      EXPECT_EQ(total, int64_t{outer.num_patches} * inner.num_patches);
    } else {
      EXPECT_GT(total, 0);
    }
  }
  // One garment: no outer layer.
  const Sequence single = scene(1, false);
  EXPECT_TRUE(outer_to_inner_world_edges(build_sample(single.info, single.frames, t, simple_stats(), nullptr)).empty());
}

TEST(Sample, WindGravityAndRootMotionRows) {
  const Sequence seq = scene(1, true);
  const auto st = simple_stats();
  const int t = 7;  // frames 6..8 are in the third wind segment (strength 300)
  const TrainingSample s = build_sample(seq.info, seq.frames, t, st, nullptr);
  EXPECT_FALSE(s.has_layers);  // one garment: no layer structure
  ASSERT_TRUE(s.has_wind);
  ASSERT_EQ(s.wind.rows(), 2);
  EXPECT_NEAR(s.wind(0, 4), 300.f / 400.f, 1e-6f);
  EXPECT_TRUE(s.wind.row(1).head<4>().isApprox(seq.info.wind_rotation.row(t)));
  EXPECT_TRUE(s.wind_rotation[0].isUnitary(1e-5f));
  // gravity row for t: (g / fps - a_root(t) - mean_acc) / std_acc
  const Eigen::Vector3f ra = (seq.info.translation.row(t) - 2 * seq.info.translation.row(t - 1) +
                              seq.info.translation.row(t - 2)).transpose();
  const Eigen::Vector3f g = seq.info.gravity / seq.info.fps;
  EXPECT_NEAR(s.gravity_norm(1, 2), (g.z() - ra.z() + 0.1f) / 0.2f, 1e-4f);
  EXPECT_NEAR(s.gravity_norm(1, 0), (g.x() - ra.x()) / 0.1f, 1e-3f);
  const Eigen::Vector3f rv = (seq.info.translation.row(t + 1) - seq.info.translation.row(t)).transpose();
  EXPECT_NEAR(s.root_motion_norm(0, 0), rv.x() / 0.1f, 1e-4f);
  // Without wind the root motion is still there.
  const TrainingSample calm = build_sample(scene(1, false).info, scene(1, false).frames, t, st, nullptr);
  EXPECT_FALSE(calm.has_wind);
  EXPECT_NE(calm.root_motion_norm.norm(), 0.f);
}

// Sum over mesh edges (each counted from both ends) of the squared difference of a field.
double roughness(const Points& u, const Csr& neighbours) {
  double sum = 0;
  for (int v = 0; v < neighbours.rows(); ++v)
    for (const int32_t* n = neighbours.begin(v); n != neighbours.end(v); ++n) sum += (u.row(v) - u.row(*n)).squaredNorm();
  return sum;
}

TEST(Sample, SmoothingKeepsAUniformFieldAndEvensOutASpike) {
  const Sequence seq = scene(2, false);
  const auto S = build_structure(seq.info, kDefaultPatchSize);
  const int N = S->num_vertices();
  Points uniform = Points::Zero(N, 3);
  uniform.rowwise() += Eigen::RowVector3f(0.3f, -0.2f, 0.1f);
  Points smoothed = uniform;
  smooth_over_mesh(smoothed, S->vertex_neighbours, 7);
  EXPECT_LT((smoothed - uniform).cwiseAbs().maxCoeff(), 1e-6f);

  Points spike = uniform;
  spike(N / 3, 2) += 1.f;
  const double before = roughness(spike, S->vertex_neighbours);
  Points once = spike, many = spike;
  smooth_over_mesh(once, S->vertex_neighbours, 1);
  smooth_over_mesh(many, S->vertex_neighbours, 10);
  EXPECT_LT(roughness(once, S->vertex_neighbours), 0.5 * before);
  EXPECT_LT(roughness(many, S->vertex_neighbours), roughness(once, S->vertex_neighbours));
  EXPECT_LT(many(N / 3, 2) - 0.1f, once(N / 3, 2));  // the spike spreads
  Points none = spike;
  smooth_over_mesh(none, S->vertex_neighbours, 0);
  EXPECT_EQ(none, spike);
}

// Frame 6's body is frame 5's turned by 0.4 rad about z (around the root), so that the carry from
// frame 5 to 6 differs from vertex to vertex.
void turn_body_after_frame_5(Sequence& seq) {
  const int B = seq.info.num_body_vertices;
  const Eigen::Matrix3f turn = Eigen::AngleAxisf(0.4f, Eigen::Vector3f::UnitZ()).toRotationMatrix();
  Points body = seq.body_at(5);
  body.rowwise() -= seq.info.translation.row(5);
  Points turned = body * turn.transpose();
  turned.rowwise() += seq.info.translation.row(6);
  seq.frames.body.middleRows(6 * static_cast<Eigen::Index>(B), B) = turned;
}

TEST(Sample, SmoothedCarryIsTheCarryAveragedOverTheMesh) {
  Sequence seq = scene(2, false);
  turn_body_after_frame_5(seq);
  const auto st = simple_stats();
  SampleOptions o;
  o.body_carry = true;
  const TrainingSample raw = build_sample(seq.info, seq.frames, 5, st, nullptr, o);
  o.carry_smoothing = 3;
  const TrainingSample smooth = build_sample(seq.info, seq.frames, 5, st, nullptr, o);
  Points expected = raw.body_carry;
  smooth_over_mesh(expected, raw.structure->vertex_neighbours, 3);
  ASSERT_EQ(smooth.body_carry.rows(), raw.body_carry.rows());
  EXPECT_LT((smooth.body_carry - expected).cwiseAbs().maxCoeff(), 1e-6f);
  EXPECT_GT((raw.body_carry - expected).cwiseAbs().maxCoeff(), 1e-4f);  // the body's motion is not uniform
}

// The skin binding and the carry run on the threads point by point: the same bits on any thread
// count. 1,536 garment points and 642 body vertices, so that each loop forks.
TEST(Sample, CarryIsTheSameBitsOnAnyThreadCount) {
  SyntheticOptions so;
  so.garments = 2, so.rings = 24, so.segments = 32, so.body_rings = 20, so.body_segments = 32;
  Sequence seq = make_synthetic_sequence(so);
  ASSERT_GT(seq.info.num_body_vertices, 512);
  turn_body_after_frame_5(seq);
  SampleOptions o;
  o.body_carry = o.body_carry_prev = true;
  const int threads_before = omp_get_max_threads();
  omp_set_num_threads(1);
  const TrainingSample one = build_sample(seq.info, seq.frames, 5, simple_stats(), nullptr, o);
  ASSERT_GT(one.num_vertices(), 512);
  EXPECT_GT(one.body_carry.cwiseAbs().maxCoeff(), 1e-4f);  // the body moves, so the carry does
  for (int threads : {2, 3}) {
    omp_set_num_threads(threads);
    const TrainingSample many = build_sample(seq.info, seq.frames, 5, simple_stats(), nullptr, o);
    EXPECT_EQ(many.body_carry, one.body_carry) << threads << " threads";
    EXPECT_EQ(many.body_carry_prev, one.body_carry_prev) << threads << " threads";
  }
  omp_set_num_threads(threads_before);
}

TEST(Sample, StaticStructureIsBuiltOncePerSequence) {
  const Sequence seq = scene(2, false);
  StructureCache cache;
  const auto st = simple_stats();
  std::vector<TrainingSample> samples;
  for (int t : sample_frames(seq.info.num_frames, {}))
    samples.push_back(build_sample(seq.info, seq.frames, t, st, cache.get("a", seq.info)));
  EXPECT_EQ(samples.size(), 7u);  // t = 2..8 of 10 frames
  EXPECT_EQ(cache.builds(), 1);
  EXPECT_EQ(samples.front().structure.get(), samples.back().structure.get());
}

TEST(Sample, OfficialFrameSelectionAndRangeErrors) {
  const auto f = sample_frames(150, FrameSelection::official());
  ASSERT_EQ(f.size(), 36u);  // official ep1: inputs 63..98
  EXPECT_EQ(f.front(), 63);
  EXPECT_EQ(f.back(), 98);
  EXPECT_TRUE(sample_frames(60, FrameSelection::official()).empty());
  const Sequence seq = scene(1, false);
  EXPECT_THROW(build_sample(seq.info, seq.frames, 1, simple_stats(), nullptr), DatasetError);
  EXPECT_THROW(build_sample(seq.info, seq.frames, 9, simple_stats(), nullptr), DatasetError);
  FrameWindow partial = seq.frames;
  partial.first = 3;  // pretend the window starts at 3: t = 4 lacks t-2 = 2
  EXPECT_THROW(build_sample(seq.info, partial, 4, simple_stats(), nullptr), DatasetError);
}

}  // namespace
// A unit square of two triangles in the z = 0 plane (one wound each way): facing the wind, each
// corner gets its faces' area/3 along z, whatever the winding; edge-on, nothing; at 60° from the
// normal, half the strength along the normal.
TEST(FaceWind, SquareFacingEdgeOnAndOblique) {
  Points x(4, 3);
  x << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  const std::vector<int32_t> faces{0, 1, 2, 0, 3, 2};  // normals +z and −z
  Eigen::VectorXd area;
  const Points facing = face_wind_force(x, faces, Eigen::Vector3d(0, 0, 2), &area);
  const double share[4] = {1.0 / 3, 1.0 / 6, 1.0 / 3, 1.0 / 6};  // corners 0 and 2 are in both faces
  for (int v = 0; v < 4; ++v) {
    EXPECT_NEAR(area[v], share[v], 1e-12) << v;
    EXPECT_NEAR(facing(v, 2), 2 * share[v], 1e-6) << v;
    EXPECT_NEAR(facing(v, 0), 0, 1e-7) << v;
    EXPECT_NEAR(facing(v, 1), 0, 1e-7) << v;
  }
  EXPECT_EQ(face_wind_force(x, faces, Eigen::Vector3d(3, -1, 0)).cwiseAbs().maxCoeff(), 0.f);
  const Points oblique = face_wind_force(x, faces, Eigen::Vector3d(std::sqrt(3.0), 0, 1));  // |w| 2, 60° off
  for (int v = 0; v < 4; ++v) {
    EXPECT_NEAR(oblique(v, 2), share[v], 1e-6) << v;
    EXPECT_NEAR(oblique(v, 0), 0, 1e-6) << v;
  }
}

}  // namespace layersnet::dataset
