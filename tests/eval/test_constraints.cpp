// Cloth constraints (run/cloth_constraints.h): cloth that already holds them is not moved; stretched
// edges come back within the limit; vertices inside the body or the inner layer are pushed onto
// the shell; and a model's rollout with eval.constraints keeps every frame within them.
#include "dataset/neighbours.h"
#include "dataset/pin_carry.h"
#include "dataset/synthetic.h"
#include "run/cloth_constraints.h"
#include "eval/metrics.h"
#include "eval/rollout.h"
#include "eval/stress.h"
#include "model/params_layout.h"
#include "run/config.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace layersnet::eval {
namespace {

// Two tubes (radius 1.5 and 1.75 scene units) around a body cylinder of radius 1.2.
dataset::Sequence tubes() {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 8;
  return dataset::make_synthetic_sequence(o);
}

double worst_strain(const dataset::Sequence& seq, const Points& x) {
  const std::vector<double> s = edge_strains(garment_edges(seq), x);
  return *std::max_element(s.begin(), s.end());
}

// Frame 3 with every other vertex pulled 0.3 units sideways: crumpled, stretched cloth.
Points crumpled(const dataset::Sequence& seq) {
  Points x = garments_at(seq, 3);
  for (Eigen::Index v = 0; v < x.rows(); v += 2) x(v, 0) += 0.3f;
  return x;
}

// (x − a)·n_a with a the nearest anchor (within reach) of x and n_a its vertex normal.
double signed_distance(const Eigen::RowVector3f& x, const Points& anchors, const dataset::Faces& faces) {
  const Points normals = dataset::vertex_normals(anchors, faces);
  const dataset::NearestBody nb = dataset::nearest_body(x, anchors);
  return (x - anchors.row(nb.index[0])).dot(normals.row(nb.index[0]));
}

TEST(ClothConstraints, ClothThatHoldsThemIsNotMoved) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.strain_limit = 1.1 * worst_strain(seq, garments_at(seq, 3));  // the data's own strain fits
  ASSERT_GT(s.strain_limit, 0.0);
  const ClothConstraints constraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s);
  Points x = garments_at(seq, 3);
  const Points before = x;
  const ConstraintMoves moves = constraints.apply(seq.body_at(3), x);
  EXPECT_EQ(moves.edges + moves.body + moves.layer, 0);
  EXPECT_EQ(x, before);
}

TEST(ClothConstraints, StretchedEdgesComeBackWithinTheLimit) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.strain_limit = 0.05;
  s.collision_shell = 0;  // edges only
  s.constraint_iterations = 40;
  Points x = crumpled(seq);
  ASSERT_GT(worst_strain(seq, x), 0.2);
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(seq.body_at(3), x);
  EXPECT_GT(moves.edges, 0);
  EXPECT_LE(worst_strain(seq, x), s.strain_limit + 0.01);
}

TEST(ClothConstraints, FewPassesStillShrinkTheWorstStrain) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.collision_shell = 0;
  s.constraint_iterations = 1;
  Points x = crumpled(seq);
  const double before = worst_strain(seq, x);
  ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(seq.body_at(3), x);
  EXPECT_LT(worst_strain(seq, x), 0.75 * before);
}

TEST(ClothConstraints, FarCornersPairTheTwoTrianglesOfEachInteriorEdge) {
  dataset::Faces quad(2, 3);
  quad << 0, 1, 2, 0, 2, 3;  // a square split along 0-2: the far corners are 1 and 3
  const auto pairs = far_corners(quad);
  ASSERT_EQ(pairs.size(), 1u);
  EXPECT_EQ(std::min(pairs[0].first, pairs[0].second), 1);
  EXPECT_EQ(std::max(pairs[0].first, pairs[0].second), 3);
  dataset::Faces fan(3, 3);
  fan << 0, 1, 2, 0, 2, 3, 0, 3, 4;  // two interior edges, 0-2 and 0-3
  EXPECT_EQ(far_corners(fan).size(), 2u);
}

TEST(ClothConstraints, FoldedTrianglePairsOpenToTheFoldLimit) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.strain_limit = 0;
  s.fold_limit = 0.15;
  s.collision_shell = 0;
  s.constraint_iterations = 40;
  Points x = garments_at(seq, 3);
  x.col(0) *= 0.3f;  // flattened tubes: far corners across the flattened sides come closer
  const Points rest = rest_garments(seq);
  auto shortest = [&](const Points& y) {
    double worst = 1e9;
    Eigen::Index offset = 0;
    for (const auto& mesh : seq.info.garments) {
      for (const auto& [a, b] : far_corners(mesh.faces))
        worst = std::min(worst, double((y.row(offset + a) - y.row(offset + b)).norm() /
                                       (rest.row(offset + a) - rest.row(offset + b)).norm()));
      offset += mesh.num_vertices;
    }
    return worst;
  };
  ASSERT_LT(shortest(x), 1 - s.fold_limit - 0.1);
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(seq.body_at(3), x);
  EXPECT_GT(moves.folds, 0);
  EXPECT_EQ(moves.edges, 0);
  EXPECT_GE(shortest(x), 1 - s.fold_limit - 0.01);
}

TEST(ClothConstraints, AVertexInsideTheBodyEndsOnTheShell) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.strain_limit = 0;  // collisions only
  s.collision_shell = 0.05;
  const Points body = seq.body_at(3);
  const Points body_normals = dataset::vertex_normals(body, seq.info.body_faces);
  Points x = garments_at(seq, 3);
  const Points before = x;
  const Eigen::Index v = 5, h = 20;  // an inner-garment vertex, moved 0.1 inside body vertex h
  x.row(v) = body.row(h) - 0.1f * body_normals.row(h);
  ASSERT_LT(signed_distance(x.row(v), body, seq.info.body_faces), 0.0);
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, x);
  EXPECT_EQ(moves.body, 1);
  EXPECT_NEAR(signed_distance(x.row(v), body, seq.info.body_faces), s.collision_shell, 1e-5);
  for (Eigen::Index u = 0; u < x.rows(); ++u) {
    if (u == v) continue;
    ASSERT_EQ(x.row(u), before.row(u)) << u;
  }
}

TEST(ClothConstraints, AnOuterVertexInsideTheInnerLayerEndsOnTheShell) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.strain_limit = 0;
  s.collision_shell = 0.05;
  Points x = garments_at(seq, 3);
  const GarmentLayout layout = garment_layout(seq.info);
  const Eigen::Index outer_begin = layout.offsets[1];
  const Points inner = x.topRows(outer_begin);
  const Faces faces = inner_faces(layout);
  const Points inner_normals = dataset::vertex_normals(inner, faces);
  const Eigen::Index v = outer_begin + 7, y = 9;
  x.row(v) = inner.row(y) - 0.1f * inner_normals.row(y);
  ASSERT_LT(signed_distance(x.row(v), inner, faces), 0.0);
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(seq.body_at(3), x);
  EXPECT_EQ(moves.layer, 1);
  EXPECT_NEAR(signed_distance(x.row(v), x.topRows(outer_begin), faces), s.collision_shell, 1e-5);
  // The shell is the same rule the layer-collision metric counts: no collision left.
  EXPECT_EQ(count_layer_collisions(x.bottomRows(x.rows() - outer_begin), x.topRows(outer_begin), faces), 0);
}

// The passes stop after one that moves nothing, with what every pass would have given (the
// collision steps alone, as the shipped models run them): cloth that holds the constraints takes
// one pass; cloth pushed into the body and into the inner layer takes more, and its result equals
// that of single passes applied until one moves nothing.
TEST(ClothConstraints, ThePassesStopAfterOneThatMovesNothing) {
  const dataset::Sequence seq = tubes();
  EvalConfig s;
  s.strain_limit = 0;
  s.collision_shell = 0.05;
  s.constraint_iterations = 50;
  const Points body = seq.body_at(3);
  Points held = garments_at(seq, 3);
  EXPECT_EQ(ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, held).passes, 1);

  Points x = garments_at(seq, 3);
  for (Eigen::Index v = 0; v < x.rows(); v += 3) x.row(v).head<2>() *= 0.6f;  // a third pulled towards the body's axis
  Points one_at_a_time = x;
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, x);
  EXPECT_GT(moves.body, 0);
  EXPECT_GT(moves.layer, 0);
  EXPECT_GE(moves.passes, 2);
  EXPECT_LT(moves.passes, s.constraint_iterations);
  EvalConfig single = s;
  single.constraint_iterations = 1;
  const ClothConstraints one_pass(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), single);
  int passes = 1;
  for (ConstraintMoves m = one_pass.apply(body, one_at_a_time); m.body + m.layer > 0; m = one_pass.apply(body, one_at_a_time))
    ASSERT_LT(++passes, s.constraint_iterations);
  EXPECT_EQ(passes, moves.passes);
  EXPECT_EQ(x, one_at_a_time);
}

// Contact friction: an inner-tube vertex (0.3 units off the body) that slides along the body
// loses mu of its tangential motion relative to its nearest body vertex and keeps the normal
// part; the outer tube (0.55 units off) and frames without the frame before are not touched.
TEST(ClothConstraints, ContactFrictionCarriesNearBodyClothWithTheBody) {
  const dataset::Sequence seq = tubes();
  const Points body_before = seq.body_at(2), body = seq.body_at(3);
  const Points x_before = garments_at(seq, 2);
  const Points normals = dataset::vertex_normals(body, seq.info.body_faces);
  const Eigen::Index v = 5, outer = x_before.rows() - 3;  // inner / outer garment vertices
  Points slid = garments_at(seq, 3);
  slid(v, 2) += 0.3f;      // slides up the cylinder: tangential to its side
  slid(outer, 2) += 0.3f;
  const dataset::NearestBody nb = dataset::nearest_body(slid.row(v), body);
  const Eigen::RowVector3f n = normals.row(nb.index[0]);
  const auto relative = [&](const Points& x) -> Eigen::RowVector3f {
    return (x.row(v) - x_before.row(v)) - (body.row(nb.index[0]) - body_before.row(nb.index[0]));
  };
  const Eigen::RowVector3f r = relative(slid);
  const Eigen::RowVector3f tangential = r - r.dot(n) * n;
  ASSERT_GT(tangential.norm(), 0.2f);
  for (const double mu : {1.0, 0.5}) {
    EvalConfig s;
    s.strain_limit = 0;
    s.collision_shell = 0;  // friction alone
    s.body_friction = mu;
    s.friction_distance = 0.4;
    Points x = slid;
    const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, x, body_before, x_before);
    EXPECT_GT(moves.friction, 0);
    const Eigen::RowVector3f after = relative(x);
    EXPECT_NEAR((after - after.dot(n) * n - (1.f - static_cast<float>(mu)) * tangential).norm(), 0.f, 1e-5f) << mu;
    EXPECT_NEAR(after.dot(n), r.dot(n), 1e-5f) << mu;
    EXPECT_EQ(x.row(outer), slid.row(outer)) << "beyond friction_distance";
    Points unchanged = slid;
    ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, unchanged);  // no frame before: no friction
    EXPECT_EQ(unchanged, slid);
  }
}

// The tubes with the top ring (highest rest vertices) of every garment pinned, as the generator
// pins waistbands and top edges.
dataset::Sequence pinned_tubes() {
  dataset::Sequence seq = tubes();
  const Points rest = rest_garments(seq);
  Eigen::Index offset = 0;
  for (dataset::GarmentMesh& g : seq.info.garments) {
    const float top = rest.middleRows(offset, g.num_vertices).col(2).maxCoeff();
    g.pin.assign(static_cast<size_t>(g.num_vertices), 0.f);
    for (int v = 0; v < g.num_vertices; ++v)
      if (rest(offset + v, 2) > top - 1e-4f) g.pin[static_cast<size_t>(v)] = 1.f;
    offset += g.num_vertices;
  }
  return seq;
}

// The body's motion in the pin tests: around the pinned rings (z >= 2, rings at z = 3.2) it
// turns and shifts rigidly, while the body below swings sideways like a leg.
const Eigen::Matrix3f kTorsoTurn = Eigen::AngleAxisf(0.3f, Eigen::Vector3f(1.f, 0.5f, 2.f).normalized()).toRotationMatrix();
const Eigen::RowVector3f kTorsoShift(0.2f, -0.1f, 0.4f);
Points turned_torso_swung_legs(const Points& body_before) {
  Points body = (body_before * kTorsoTurn.transpose()).rowwise() + kTorsoShift;
  for (Eigen::Index b = 0; b < body.rows(); ++b)
    if (body_before(b, 2) < 2.f) body(b, 0) += 0.7f;
  return body;
}

// The pinned vertices follow the torso's rigid motion exactly, whatever the legs do, and
// neither the edge, collision nor friction steps move them afterwards.
TEST(ClothConstraints, PinnedVerticesMoveRigidlyWithTheBodyUnderThem) {
  const dataset::Sequence seq = pinned_tubes();
  const Points body_before = seq.body_at(2), x_before = garments_at(seq, 2);
  const Points body = turned_torso_swung_legs(body_before);
  ASSERT_GT(((body - body_before).rowwise().norm().array() > 0.7f).count(), 16) << "the legs swing";
  EvalConfig s;
  s.body_friction = 1.0;
  Points x = crumpled(seq);
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, x, body_before, x_before);
  EXPECT_EQ(moves.pinned, 2 * 16);
  EXPECT_GT(moves.edges, 0);
  Eigen::Index offset = 0;
  for (const dataset::GarmentMesh& g : seq.info.garments) {
    for (int v = 0; v < g.num_vertices; ++v) {
      const Eigen::Index r = offset + v;
      if (!g.pinned(v)) continue;
      const Eigen::RowVector3f carried = x_before.row(r) * kTorsoTurn.transpose() + kTorsoShift;
      EXPECT_LT((x.row(r) - carried).norm(), 1e-4f) << "row " << r;
    }
    offset += g.num_vertices;
  }
  s.pins = false;
  Points free = crumpled(seq);
  EXPECT_EQ(ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s).apply(body, free, body_before, x_before).pinned, 0);
  EXPECT_GT((free - x).norm(), 0.1f);
}

// Rigged pins (what simulate gives a scene, eval --rig-pins measures on data): from the reference
// frame on, every frame's pinned rows are the reference's moved with the torso, the legs' swing
// ignored; the frames before it and every free row stay as they were.
TEST(ClothConstraints, RiggedPinsFollowTheTorsoFromTheReferenceFrame) {
  const dataset::Sequence original = [] {
    dataset::Sequence seq = pinned_tubes();
    seq.info.pins_recorded = false;
    const int B = seq.info.num_body_vertices;
    const Points moved = turned_torso_swung_legs(seq.body_at(3));
    for (int t = 4; t < seq.info.num_frames; ++t) seq.frames.body.middleRows(static_cast<Eigen::Index>(t) * B, B) = moved;
    return seq;
  }();
  dataset::Sequence seq = original;
  dataset::rig_pins(seq, 3);
  EXPECT_TRUE(seq.info.pins_recorded);
  const Points reference = garments_at(original, 3);
  int pinned = 0;
  for (int t = 0; t < seq.info.num_frames; ++t) {
    const Points x = garments_at(seq, t), before = garments_at(original, t);
    Eigen::Index offset = 0;
    for (const dataset::GarmentMesh& g : seq.info.garments) {
      for (int v = 0; v < g.num_vertices; ++v) {
        const Eigen::Index r = offset + v;
        if (!g.pinned(v) || t <= 3) {
          EXPECT_EQ(x.row(r), before.row(r)) << "row " << r << ", frame " << t;
          continue;
        }
        const Eigen::RowVector3f carried = reference.row(r) * kTorsoTurn.transpose() + kTorsoShift;
        EXPECT_LT((x.row(r) - carried).norm(), 1e-4f) << "row " << r << ", frame " << t;
        ++pinned;
      }
      offset += g.num_vertices;
    }
  }
  EXPECT_EQ(pinned, 4 * 2 * 16);
  EXPECT_THROW(dataset::rig_pins(seq, seq.info.num_frames), std::exception);
}

// A hand that reaches into the loop at the reference frame and then leaves is not torso: the
// rig chooses the body under the pins at the first frame, where the hand is down by the legs.
TEST(ClothConstraints, RiggedPinsIgnoreAHandInTheirLoopAtTheReferenceFrame) {
  dataset::Sequence seq = pinned_tubes();
  seq.info.pins_recorded = false;
  const int B = seq.info.num_body_vertices;
  const Points first = seq.body_at(0);
  const float lowest = first.col(2).minCoeff();
  std::vector<Eigen::Index> hand;
  for (Eigen::Index b = 0; b < B; ++b)
    if (first(b, 2) < lowest + 0.5f) hand.push_back(b);
  ASSERT_GE(hand.size(), 8u);
  const Points pinned_rows_at_3 = garments_at(seq, 3);
  Eigen::RowVector3f loop_centre = Eigen::RowVector3f::Zero();
  const std::vector<Eigen::Index> pinned = seq.info.pinned_rows();
  for (Eigen::Index r : pinned) loop_centre += pinned_rows_at_3.row(r);
  loop_centre /= static_cast<float>(pinned.size());
  const Points at_3 = seq.body_at(3);
  for (int t = 3; t < seq.info.num_frames; ++t) {
    Points body = t == 3 ? at_3 : Points((at_3 * kTorsoTurn.transpose()).rowwise() + kTorsoShift);
    for (size_t k = 0; k < hand.size(); ++k) {
      const float angle = 6.2831853f * static_cast<float>(k) / static_cast<float>(hand.size());
      body.row(hand[k]) = loop_centre + Eigen::RowVector3f(0.3f * std::cos(angle), 0.3f * std::sin(angle), 0.f);
      if (t > 3) body(hand[k], 0) += 3.f;  // the hand leaves the loop sideways
    }
    seq.frames.body.middleRows(static_cast<Eigen::Index>(t) * B, B) = body;
  }
  const Points reference = garments_at(seq, 3);
  dataset::rig_pins(seq, 3);
  for (int t = 4; t < seq.info.num_frames; ++t) {
    const Points x = garments_at(seq, t);
    for (Eigen::Index r : pinned) {
      const Eigen::RowVector3f carried = reference.row(r) * kTorsoTurn.transpose() + kTorsoShift;
      EXPECT_LT((x.row(r) - carried).norm(), 1e-4f) << "row " << r << ", frame " << t;
    }
  }
}

// Recorded pins replace the rigid carry: the pinned rows end where the caller says, and the
// edge, collision and friction steps leave them there.
TEST(ClothConstraints, RecordedPinsAreHeldWhereTheyAreGiven) {
  const dataset::Sequence seq = pinned_tubes();
  const Points body_before = seq.body_at(2), x_before = garments_at(seq, 2);
  const Points body = turned_torso_swung_legs(body_before);
  EvalConfig s;
  s.body_friction = 1.0;
  Points recorded = x_before;
  recorded.rowwise() += Eigen::RowVector3f(0.05f, 0.3f, -0.2f);  // not where the torso carries them
  Points x = crumpled(seq);
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), s)
                                    .apply(body, x, body_before, x_before, &recorded);
  EXPECT_EQ(moves.pinned, 2 * 16);
  EXPECT_GT(moves.edges, 0);
  Eigen::Index offset = 0;
  for (const dataset::GarmentMesh& g : seq.info.garments) {
    for (int v = 0; v < g.num_vertices; ++v) {
      if (!g.pinned(v)) continue;
      EXPECT_EQ(x.row(offset + v), recorded.row(offset + v)) << "row " << offset + v;
    }
    offset += g.num_vertices;
  }
}

// The body under the pins is chosen in the frame given, not against the rest shape: the same
// scene laid on its side and moved away (a stress sequence starts in a pose), with the rest
// shape still upright, carries the pinned rows just as the upright scene does.
TEST(ClothConstraints, ThePinnedLoopIsFoundInTheGivenFrameNotInTheRestShape) {
  const dataset::Sequence seq = pinned_tubes();
  const Eigen::Matrix3f lay = Eigen::AngleAxisf(1.5707963f, Eigen::Vector3f::UnitX()).toRotationMatrix();
  const Eigen::RowVector3f away(3.f, 1.f, -2.f);
  const auto posed = [&](const Points& p) -> Points { return (p * lay.transpose()).rowwise() + away; };
  const Points x_before = garments_at(seq, 2);
  EvalConfig s;
  s.strain_limit = 0;
  s.collision_shell = 0;
  Points x = posed(crumpled(seq));
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), posed(seq.body_at(0)), posed(garments_at(seq, 0)), s)
                                    .apply(posed(turned_torso_swung_legs(seq.body_at(2))), x, posed(seq.body_at(2)), posed(x_before));
  EXPECT_EQ(moves.pinned, 2 * 16);
  Eigen::Index offset = 0;
  for (const dataset::GarmentMesh& g : seq.info.garments) {
    for (int v = 0; v < g.num_vertices; ++v)
      if (g.pinned(v)) {
        const Points carried = posed((x_before.row(offset + v) * kTorsoTurn.transpose() + kTorsoShift).eval());
        EXPECT_LT((x.row(offset + v) - carried.row(0)).norm(), 1e-4f) << "row " << offset + v;
      }
    offset += g.num_vertices;
  }
}

TEST(ClothConstraints, ANonFiniteFrameIsLeftForTheRolloutToReport) {
  const dataset::Sequence seq = tubes();
  Points x = garments_at(seq, 3);
  x(4, 1) = std::numeric_limits<float>::quiet_NaN();
  const ConstraintMoves moves = ClothConstraints(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), EvalConfig{}).apply(seq.body_at(3), x);
  EXPECT_EQ(moves.edges + moves.body + moves.layer, 0);
  EXPECT_TRUE(std::isnan(x(4, 1)));
}

// A randomly initialised model crumples the cloth at once; with eval.constraints every frame
// of its rollout stays near the strain limit and outside the body.
TEST(ClothConstraints, AModelRolloutWithThemKeepsTheCloth) {
  const dataset::Sequence seq = tubes();
  Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
  dataset::NormalisationStats st;
  auto model = [&](bool constrained) {
    ad::ParamStore<float> ps;
    model::register_params(ps, c.model);
    model::init_params(ps, c.model, 3);
    auto m = std::make_unique<ModelPredictor>("tiny", c, std::move(ps), st);
    m->set_constraints(constrained);
    return m;
  };
  const Rollout free_run = rollout(*model(false), seq, 2, 5);
  const Rollout held = rollout(*model(true), seq, 2, 5);
  ASSERT_EQ(held.frames.size(), 5u);
  auto mean_strain = [&](const Points& x) {
    const std::vector<double> strain = edge_strains(garment_edges(seq), x);
    return std::accumulate(strain.begin(), strain.end(), 0.0) / static_cast<double>(strain.size());
  };
  const double free_strain = mean_strain(free_run.frames.back());
  EXPECT_GT(free_strain, 0.5);
  const Config defaults;
  for (size_t k = 0; k < held.frames.size(); ++k) {
    // Eight passes do not fully undo a random network's mess (the collision steps come last),
    // but they keep the mean near the limit, against ~1 without them.
    EXPECT_LE(mean_strain(held.frames[k]), 2 * defaults.eval.strain_limit) << k;
    EXPECT_LT(mean_strain(held.frames[k]), free_strain / 5) << k;
    EXPECT_EQ(count_body_collisions(held.frames[k], seq.body_at(held.first_frame + static_cast<int>(k)),
                                    seq.info.body_faces, 0.5),
              0)
        << k;
  }
  // A trained model's settings override per rollout; other keys are fixed by the weights.
  auto m = model(true);
  EXPECT_NO_THROW(m->apply_eval_settings({"eval.strain_limit=0.2"}));
  EXPECT_THROW(m->apply_eval_settings({"model.width=8"}), ConfigError);
}

TEST(ClothConstraints, OffInThePapersConfigOnInTheProjectsModels) {
  const std::string configs = std::string(LAYERSNET_SOURCE_DIR) + "/configs/";
  EXPECT_FALSE(Config{}.eval.constraints);
  EXPECT_FALSE(load_config({configs + "paper.toml"}).eval.constraints);
  EXPECT_TRUE(load_config({configs + "default.toml"}).eval.constraints);
  EXPECT_TRUE(load_config({configs + "medium.toml"}).eval.constraints);
  // Contact friction likewise: off unless a project config asks for it.
  EXPECT_EQ(Config{}.eval.body_friction, 0.0);
  EXPECT_EQ(load_config({configs + "paper.toml"}).eval.body_friction, 0.0);
  EXPECT_EQ(load_config({configs + "default.toml"}).eval.body_friction, 1.0);
  EXPECT_EQ(load_config({configs + "medium.toml"}).eval.body_friction, 1.0);
  // The large recipe, whose pins are recorded, keeps the collision steps alone.
  const Config large = load_config({configs + "large.toml"});
  EXPECT_TRUE(large.eval.constraints);
  EXPECT_GT(large.eval.collision_shell, 0.0);
  EXPECT_EQ(large.eval.strain_limit, 0.0);
  EXPECT_EQ(large.eval.body_friction, 0.0);
  EXPECT_EQ(large.eval.layer_friction, 0.0);
}

}  // namespace
}  // namespace layersnet::eval
