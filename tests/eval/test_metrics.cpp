// Metric code on hand-built cases with known answers.
#include "dataset/neighbours.h"
#include "eval/metrics.h"

#include <gtest/gtest.h>

namespace layersnet::eval {
namespace {

// Regular octahedron of "radius" r centred at c: vertices ±x, ±y, ±z; faces counter-clockwise
// seen from outside, so every vertex normal is the unit direction of the vertex from c.
void octahedron(float r, const Eigen::Vector3f& c, Points& x, Faces& f) {
  x.resize(6, 3);
  x << r, 0, 0, -r, 0, 0, 0, r, 0, 0, -r, 0, 0, 0, r, 0, 0, -r;
  x.rowwise() += c.transpose();
  f.resize(8, 3);
  f << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
}

TEST(Metrics, OctahedronNormalsPointOutward) {
  Points x;
  Faces f;
  octahedron(1.f, Eigen::Vector3f::Zero(), x, f);
  const Points n = dataset::vertex_normals(x, f);
  for (int v = 0; v < 6; ++v) EXPECT_NEAR((n.row(v) - x.row(v)).norm(), 0.f, 1e-6f) << v;
}

TEST(Metrics, RigidShiftGivesExactlyTheShift) {
  Points truth(5, 3);
  truth << 0, 0, 0, 1, 2, 3, -4, 5, 6, 7, -8, 9, 0.5, 0.25, -0.125;
  Points pred = truth;
  pred.rowwise() += Eigen::RowVector3f(0.3f, -0.4f, 0.f);  // length 0.5
  EXPECT_NEAR(mean_vertex_error(pred, truth), 0.5, 1e-6);
  EXPECT_EQ(mean_vertex_error(truth, truth), 0.0);
  // Vertex-weighted: one vertex off by 1 of 4 gives 0.25.
  Points p4 = Points::Zero(4, 3), t4 = Points::Zero(4, 3);
  p4(2, 1) = 1.f;
  EXPECT_DOUBLE_EQ(mean_vertex_error(p4, t4), 0.25);
  EXPECT_THROW(mean_vertex_error(p4, truth), std::invalid_argument);
}

TEST(Metrics, VertexJustInsideTheBodyCountsJustOutsideDoesNot) {
  Points body;
  Faces faces;
  octahedron(1.f, Eigen::Vector3f(10, 20, 30), body, faces);
  Points g(4, 3);
  g << 10.99f, 20, 30,   // just inside, nearest +x: counts
      11.01f, 20, 30,    // just outside: no
      10, 20, 30.995f,   // just inside below +z: counts
      10, 18.9f, 30;     // outside beyond -y: no
  EXPECT_EQ(count_body_collisions(g, body, faces, 5.0), 2);
  // Distance limit: a vertex 0.5 inside from +x (its nearest) counts only when 0.5 <= limit.
  Points deep(1, 3);
  deep << 10.5f, 20, 30;
  EXPECT_EQ(count_body_collisions(deep, body, faces, 5.0), 1);
  EXPECT_EQ(count_body_collisions(deep, body, faces, 0.4), 0);
  EXPECT_EQ(count_body_collisions(deep, body, faces, -1), 1);  // no limit
}

TEST(Metrics, OuterVertexInsideTheInnerLayerCounts) {
  Points inner;
  Faces faces;
  octahedron(2.f, Eigen::Vector3f::Zero(), inner, faces);
  Points outer(3, 3);
  outer << 2.1f, 0, 0,  // outside: no
      0, 1.9f, 0,       // inside: counts
      0, 0, -2.05f;     // outside: no
  EXPECT_EQ(count_layer_collisions(outer, inner, faces), 1);
  // 0.7 inside: counts without a distance limit, not within 0.5 ("near").
  Points far(1, 3);
  far << 0, 1.3f, 0;
  EXPECT_EQ(count_layer_collisions(far, inner, faces), 1);
  EXPECT_EQ(count_layer_collisions(far, inner, faces, 0.5), 0);
  EXPECT_EQ(count_layer_collisions(far, inner, faces, 0.8), 1);
}

TEST(Metrics, FrameMetricsDenominators) {
  // Garment 0 (inner): octahedron radius 2; garment 1 (outer): octahedron radius 3 with two
  // vertices pushed inside the inner layer; body: octahedron radius 1 with one inner-garment
  // vertex pushed inside it.
  Points inner, outer, body;
  Faces fi, fo, fb;
  octahedron(2.f, Eigen::Vector3f::Zero(), inner, fi);
  octahedron(3.f, Eigen::Vector3f::Zero(), outer, fo);
  octahedron(1.f, Eigen::Vector3f::Zero(), body, fb);
  GarmentLayout L;
  L.offsets = {0, 6, 12};
  L.faces = {fi, fo};
  L.types = {"tee", "jacket"};
  Points truth(12, 3);
  truth << inner, outer;
  Points pred = truth;
  pred.row(0) << 0.9f, 0, 0;      // inner +x inside the body
  pred.row(6 + 2) << 0, 1.5f, 0;  // outer +y inside the inner layer
  pred.row(6 + 5) << 0, 0, -1.8f; // outer -z inside the inner layer
  CollisionOptions co;
  co.max_layer_distance = 0.3;  // the +y vertex is 0.5 inside, the -z one 0.2
  const FrameMetrics m = frame_metrics(L, pred, truth, body, fb, co);
  EXPECT_EQ(m.layer_collisions_near, 1);
  EXPECT_DOUBLE_EQ(m.l_rate_outer_near, 1.0 / 6);
  EXPECT_EQ(m.body_collisions, 1);
  EXPECT_DOUBLE_EQ(m.h_rate, 1.0 / 12);
  EXPECT_EQ(m.layer_collisions, 2);
  EXPECT_DOUBLE_EQ(m.l_rate_outer, 2.0 / 6);
  EXPECT_DOUBLE_EQ(m.l_rate_all, 2.0 / 12);
  ASSERT_EQ(m.garment_error.size(), 2u);
  EXPECT_NEAR(m.garment_error[0], 1.1 / 6, 1e-6);
  EXPECT_NEAR(m.garment_error[1], (1.5 + 1.2) / 6, 1e-6);
  EXPECT_NEAR(m.inner_error, m.garment_error[0], 1e-12);
  EXPECT_NEAR(m.outer_error, m.garment_error[1], 1e-12);
  EXPECT_NEAR(m.error, (1.1 + 2.7) / 12, 1e-6);
  // The ground truth itself: no collisions here (the floor).
  const FrameMetrics floor = frame_metrics(L, truth, truth, body, fb);
  EXPECT_EQ(floor.body_collisions, 0);
  EXPECT_EQ(floor.layer_collisions, 0);
  EXPECT_EQ(floor.error, 0.0);
  // One garment: no layer metrics.
  GarmentLayout one;
  one.offsets = {0, 6};
  one.faces = {fi};
  one.types = {"tee"};
  const FrameMetrics single = frame_metrics(one, pred.topRows(6), truth.topRows(6), body, fb);
  EXPECT_EQ(single.layer_collisions, -1);
  EXPECT_EQ(single.l_rate_outer, -1);
  EXPECT_EQ(single.outer_error, -1);
  EXPECT_DOUBLE_EQ(single.h_rate, 1.0 / 6);
}

TEST(Metrics, MeanStdIsPopulation) {
  const MeanStd r = mean_std({1, 2, 3, 4});
  EXPECT_DOUBLE_EQ(r.mean, 2.5);
  EXPECT_DOUBLE_EQ(r.std, std::sqrt(1.25));
  EXPECT_EQ(r.count, 4);
  EXPECT_EQ(mean_std({}).count, 0);
}

}  // namespace
}  // namespace layersnet::eval
