// Gradient checks of the fused Rotation Invariant Attention (autodiff/ops_attention.h):
// against a plain reference of the official formula, rotation invariance, head masks,
// empty neighbour lists, near-coincident receivers/senders and saturated logits.
#include "autodiff/ops_dense.h"
#include "autodiff/ops_graph.h"
#include "edge_kinds.h"
#include "gradcheck_registry.h"

#include <omp.h>

#include <Eigen/Dense>

#include <cmath>
#include <random>
#include <vector>

namespace layersnet::ad::testing {

namespace {

// A neighbour graph with its own storage.
struct Graph {
  std::vector<int32_t> offsets{0}, senders, kinds;
  std::vector<uint32_t> head_kinds;
  uint32_t message_kinds = kSelfMessageKinds;
  RiaGraph view() const { return {offsets, senders, kinds, head_kinds, message_kinds}; }
  int64_t edges() const { return static_cast<int64_t>(senders.size()); }
};

// Receiver i gets counts[i] random edges with random kinds (world / mesh / inter).
Graph random_graph(const std::vector<int>& counts, int n_send, int heads, unsigned seed) {
  std::mt19937 rng(seed);
  Graph g;
  for (int c : counts) {
    for (int k = 0; k < c; ++k) {
      g.senders.push_back(static_cast<int32_t>(rng() % static_cast<unsigned>(n_send)));
      g.kinds.push_back(static_cast<int32_t>(rng() % 3));
    }
    g.offsets.push_back(static_cast<int32_t>(g.senders.size()));
  }
  g.head_kinds = alternating_head_kinds(heads);
  return g;
}

// The official formula, plainly: logit = scale (q.s + q.r) / (||r - s||/2 + 1e-7),
// w = a / ||r - s||. Returns out (P, H*D) and w (E, H).
std::pair<RowMat<double>, RowMat<double>> reference(const RowMat<double>& q, const RowMat<double>& r,
                                                    const RowMat<double>& s, const Graph& g, int heads, double scale) {
  const int64_t D = q.cols() / heads;
  RowMat<double> out = RowMat<double>::Zero(q.rows(), q.cols()), w = RowMat<double>::Zero(g.edges(), heads);
  for (int64_t i = 0; i < q.rows(); ++i) {
    for (int h = 0; h < heads; ++h) {
      const auto qi = q.row(i).segment(h * D, D), ri = r.row(i).segment(h * D, D);
      std::vector<double> z;
      std::vector<int64_t> es;
      for (int64_t e = g.offsets[static_cast<std::size_t>(i)]; e < g.offsets[static_cast<std::size_t>(i) + 1]; ++e) {
        if (!((g.head_kinds[static_cast<std::size_t>(h)] >> g.kinds[static_cast<std::size_t>(e)]) & 1u)) continue;
        const auto sj = s.row(g.senders[static_cast<std::size_t>(e)]).segment(h * D, D);
        z.push_back(scale * (qi.dot(sj) + qi.dot(ri)) / ((ri - sj).norm() / 2 + 1e-7));
        es.push_back(e);
      }
      if (es.empty()) continue;
      const double zmax = *std::max_element(z.begin(), z.end());
      double sum = 0;
      for (double& v : z) sum += (v = std::exp(v - zmax));
      for (std::size_t k = 0; k < es.size(); ++k) {
        const int64_t e = es[k];
        const auto sj = s.row(g.senders[static_cast<std::size_t>(e)]).segment(h * D, D);
        w(e, h) = z[k] / sum / (ri - sj).norm();
        if ((g.message_kinds >> g.kinds[static_cast<std::size_t>(e)]) & 1u)
          out.row(i).segment(h * D, D) += w(e, h) * (sj + ri);
      }
    }
  }
  return {out, w};
}

GradcheckFn ria_out(const Graph& g, double scale, double eps = 1e-7) {
  return [&g, scale, eps](Tape<double>& t, const std::vector<Var<double>>& v) {
    return rot_inv_attention(t, v[0], v[1], v[2], g.view(), scale, eps).out;
  };
}
GradcheckFn ria_weights(const Graph& g, double scale, double eps = 1e-7) {
  return [&g, scale, eps](Tape<double>& t, const std::vector<Var<double>>& v) {
    return rot_inv_attention(t, v[0], v[1], v[2], g.view(), scale, eps).weights;
  };
}

}  // namespace

GRADCHECK_TEST(RotInvAttention, MatchesOfficialFormulaWithHeadMasks) {
  const int heads = 4, D = 3, P = 5, M = 7;
  const Graph g = random_graph({4, 0, 6, 1, 5}, M, heads, 1);
  const RowMat<double> q = random_matrix(P, heads * D, 101), r = random_matrix(P, heads * D, 102),
                       s = random_matrix(M, heads * D, 103);
  const double scale = 1 / std::sqrt(double(D));
  const GradcheckReport rep = expect_gradcheck(OpKind::RotInvAttention, ria_out(g, scale), {{q}, {r}, {s}});
  const auto [ref_out, ref_w] = reference(q, r, s, g, heads, scale);
  EXPECT_TRUE(rep.output.isApprox(ref_out, 1e-5)) << rep.output << "\n\n" << ref_out;
  EXPECT_TRUE(rep.output.row(1).isZero());  // receiver without neighbours
  EXPECT_TRUE(rep.gradients[0].row(1).isZero());
  EXPECT_TRUE(rep.gradients[1].row(1).isZero());

  const GradcheckReport wrep = expect_gradcheck(OpKind::RotInvAttention, ria_weights(g, scale), {{q}, {r}, {s}});
  EXPECT_TRUE(wrep.output.isApprox(ref_w, 1e-5));
  for (int64_t e = 0; e < g.edges(); ++e)
    for (int h = 0; h < heads; ++h)
      if (!((g.head_kinds[static_cast<std::size_t>(h)] >> g.kinds[static_cast<std::size_t>(e)]) & 1u)) {
        EXPECT_EQ(wrep.output(e, h), 0.0) << "edge " << e << " head " << h;
      }
}

GRADCHECK_TEST(RotInvAttention, BothOutputsTogetherAndConstantSenders) {
  // D = 1 so out (P, H) and segment_sum(w) (P, H) can be added: both gradients in one check.
  const int heads = 2, P = 4, M = 5;
  const Graph g = random_graph({3, 2, 0, 4}, M, heads, 2);
  const auto f = [&g](Tape<double>& t, const std::vector<Var<double>>& v) {
    const RiaResult<double> res = rot_inv_attention(t, v[0], v[1], v[2], g.view(), 0.7);
    return add(t, res.out, segment_sum(t, res.weights, g.offsets));
  };
  expect_gradcheck(OpKind::RotInvAttention, f,
                   {{random_matrix(P, heads, 111)}, {random_matrix(P, heads, 112)}, {random_matrix(M, heads, 113)}});
  expect_gradcheck(OpKind::RotInvAttention, f,
                   {{random_matrix(P, heads, 114)}, {random_matrix(P, heads, 115)}, {random_matrix(M, heads, 116), false}});
}

GRADCHECK_TEST(RotInvAttention, OneReceiverOneSenderOneEdge) {
  Graph g;
  g.offsets = {0, 1};
  g.senders = {0};
  g.kinds = {kMeshEdge};
  g.head_kinds = {1u << kMeshEdge};
  const RowMat<double> q = random_matrix(1, 2, 121), r = random_matrix(1, 2, 122), s = random_matrix(1, 2, 123);
  const GradcheckReport rep = expect_gradcheck(OpKind::RotInvAttention, ria_out(g, 0.5), {{q}, {r}, {s}});
  // One edge: a = 1, out = (s + r) / ||r - s||.
  const double dist = std::sqrt((r - s).squaredNorm() + 1e-14);
  EXPECT_TRUE(rep.output.isApprox((s + r) / dist, 1e-14));
  expect_gradcheck(OpKind::RotInvAttention, ria_weights(g, 0.5), {{q}, {r}, {s}});
}

GRADCHECK_TEST(RotInvAttention, EmptyListsAndHeadsWithNothingToAttend) {
  // Receiver 0 has only inter edges: mesh heads (odd) see nothing. Receiver 1 has none.
  // Receiver 2 has only mesh edges: world heads see nothing.
  Graph g;
  g.offsets = {0, 2, 2, 4};
  g.senders = {0, 1, 2, 0};
  g.kinds = {kInterEdge, kInterEdge, kMeshEdge, kMeshEdge};
  g.head_kinds = alternating_head_kinds(2);
  const RowMat<double> q = random_matrix(3, 4, 131), r = random_matrix(3, 4, 132), s = random_matrix(3, 4, 133);
  const GradcheckReport rep = expect_gradcheck(OpKind::RotInvAttention, ria_out(g, 0.5), {{q}, {r}, {s}});
  // Inter edges carry no (s + r) message: receiver 0 output is zero, as is receiver 1's.
  EXPECT_TRUE(rep.output.topRows(2).isZero());
  EXPECT_TRUE(rep.output.row(2).head(2).isZero());   // world head of receiver 2
  EXPECT_FALSE(rep.output.row(2).tail(2).isZero());  // mesh head of receiver 2
  EXPECT_TRUE(rep.gradients[0].row(1).isZero());
  EXPECT_TRUE(rep.gradients[1].row(1).isZero());
  const GradcheckReport w = expect_gradcheck(OpKind::RotInvAttention, ria_weights(g, 0.5), {{q}, {r}, {s}});
  EXPECT_GT(w.output(0, 0), 0.0);  // the world head weighs the inter edges
  EXPECT_EQ(w.output(0, 1), 0.0);
  // No edges at all.
  Graph none;
  none.offsets = {0, 0};
  none.head_kinds = alternating_head_kinds(2);
  const GradcheckReport z = expect_gradcheck(OpKind::RotInvAttention, ria_out(none, 0.5),
                                             {{random_matrix(1, 4, 134)}, {random_matrix(1, 4, 135)}, {random_matrix(2, 4, 136)}});
  EXPECT_TRUE(z.output.isZero());
  for (const auto& grad : z.gradients) EXPECT_TRUE(grad.isZero());
}

GRADCHECK_TEST(RotInvAttention, NearCoincidentReceiverAndSender) {
  // ||r - s|| = 1e-6 on one edge: logits ~1e6 saturate the softmax and w ~ 1e6, but outputs
  // and gradients stay finite and correct (finite differences with a step 1e-4 of the
  // distance); at r = s exactly the eps smoothing keeps everything finite.
  Graph g;
  g.offsets = {0, 3};
  g.senders = {0, 1, 2};
  g.kinds = {kWorldEdge, kWorldEdge, kInterEdge};
  g.head_kinds = {(1u << kWorldEdge) | (1u << kInterEdge)};
  const RowMat<double> r = random_matrix(1, 3, 142);
  const RowMat<double> q = r + 0.3 * random_matrix(1, 3, 141);  // q.(s + r) > 0: the near edge wins
  RowMat<double> s = random_matrix(3, 3, 143);
  for (double dist : {1e-2, 1e-4, 1e-6}) {
    s.row(1) = r.row(0) + dist * (RowMat<double>(1, 3) << 0.6, 0, -0.8).finished();
    GradcheckOptions opt;
    opt.eps = dist * 1e-4;
    opt.rtol = 1e-4;
    opt.atol = 1e-11 / (dist * dist);  // rounding of an output ~1/dist over a step ~dist
    expect_gradcheck(OpKind::RotInvAttention, ria_out(g, 0.25), {{q}, {r}, {s}}, opt);
    const GradcheckReport w = expect_gradcheck(OpKind::RotInvAttention, ria_weights(g, 0.25), {{q}, {r}, {s}}, opt);
    EXPECT_NEAR(w.output(1, 0) * dist, 1.0, 0.05) << "the near edge takes (almost) all the weight";
    EXPECT_GT(w.gradients[1].cwiseAbs().maxCoeff(), 0.1 / (dist * dist)) << "and its 1/rho^2 gradient";
  }
  s.row(1) = r.row(0);
  GradcheckOptions opt;
  opt.max_coords = 0;
  const GradcheckReport rep = gradcheck(ria_out(g, 0.25), {{q}, {r}, {s}}, opt);
  EXPECT_TRUE(rep.finite) << rep.failures;
  EXPECT_LE(rep.output.cwiseAbs().maxCoeff(), 4 / 1e-7);  // |w| <= 1/eps, |s + r| small
}

GRADCHECK_TEST(RotInvAttention, SaturatedLogitsOfPlusMinus80) {
  // Scale chosen so the logits reach about +-80: the softmax subtracts its maximum.
  Graph g;
  g.offsets = {0, 3};
  g.senders = {0, 1, 2};
  g.kinds = {kWorldEdge, kWorldEdge, kWorldEdge};
  g.head_kinds = {1u << kWorldEdge};
  RowMat<double> q(1, 2), r(1, 2), s(3, 2);
  q << 1, 0;
  r << 0, 0;
  s << 1, 0, -1, 0, 0, 1;  // logits: 2 scale * (+1, -1, 0) / 1
  const double scale = 40;
  const GradcheckReport rep = expect_gradcheck(OpKind::RotInvAttention, ria_weights(g, scale), {{q}, {r}, {s}});
  EXPECT_NEAR(rep.output(0, 0), 1.0, 1e-12);
  EXPECT_GT(rep.output(1, 0), 0.0);
  EXPECT_LT(rep.output(1, 0), 1e-60);  // exp(-160)
  expect_gradcheck(OpKind::RotInvAttention, ria_out(g, scale), {{q}, {r}, {s}});
}

TEST(RotInvAttention, RotatingEveryHeadByAnOrthogonalMatrixRotatesTheOutput) {
  // Rotation invariance (eq. 5-7): q.(s + r) and ||r - s|| do not change when q, r, s of a
  // head are rotated together, so the weights are unchanged and the message rotates.
  const int heads = 2, D = 4, P = 3, M = 4;
  const Graph g = random_graph({3, 2, 4}, M, heads, 3);
  const RowMat<double> q = random_matrix(P, heads * D, 151), r = random_matrix(P, heads * D, 152),
                       s = random_matrix(M, heads * D, 153);
  RowMat<double> big = RowMat<double>::Zero(heads * D, heads * D);
  for (int h = 0; h < heads; ++h)
    big.block(h * D, h * D, D, D) = Eigen::HouseholderQR<Eigen::MatrixXd>(random_matrix(D, D, 154 + h)).householderQ();
  GradcheckOptions opt;
  opt.max_coords = 1;
  const GradcheckReport a = gradcheck(ria_weights(g, 0.5), {{q}, {r}, {s}}, opt);
  const GradcheckReport b = gradcheck(ria_weights(g, 0.5), {{q * big}, {r * big}, {s * big}}, opt);
  EXPECT_TRUE(a.output.isApprox(b.output, 1e-12));
  const GradcheckReport c = gradcheck(ria_out(g, 0.5), {{q}, {r}, {s}}, opt);
  const GradcheckReport d = gradcheck(ria_out(g, 0.5), {{q * big}, {r * big}, {s * big}}, opt);
  EXPECT_TRUE((c.output * big).isApprox(d.output, 1e-12));
}

GRADCHECK_TEST(RotInvAttention, LayersNetSizedSliceIsThreadCountInvariant) {
  // 8 heads of 16 (d = 128), 120 receivers with up to 30 neighbours: the parallel paths.
  const int heads = 8, D = 16, P = 120, M = 150;
  std::vector<int> counts(P);
  for (int i = 0; i < P; ++i) counts[static_cast<std::size_t>(i)] = (i * 7) % 31;
  const Graph g = random_graph(counts, M, heads, 4);
  const std::vector<GradcheckInput> in = {
      {random_matrix(P, heads * D, 161)}, {random_matrix(P, heads * D, 162)}, {random_matrix(M, heads * D, 163)}};
  GradcheckOptions opt;
  opt.max_coords = 12;
  expect_gradcheck(OpKind::RotInvAttention, ria_out(g, 0.25), in, opt);
  const int saved = omp_get_max_threads();
  opt.max_coords = 1;
  omp_set_num_threads(1);
  const GradcheckReport one = gradcheck(ria_out(g, 0.25), in, opt);
  omp_set_num_threads(2);
  const GradcheckReport two = gradcheck(ria_out(g, 0.25), in, opt);
  omp_set_num_threads(saved);
  EXPECT_TRUE((one.output.array() == two.output.array()).all());
  for (std::size_t k = 0; k < 3; ++k) EXPECT_TRUE((one.gradients[k].array() == two.gradients[k].array()).all()) << k;
}

TEST(RotInvAttention, RejectsBadShapesAndIndices) {
  Tape<double> tape;
  const RowMat<double> x = random_matrix(2, 4, 171);
  Var<double> v = tape.leaf(x.data(), 2, 4);
  Graph g;
  g.offsets = {0, 1, 1};
  g.senders = {5};  // out of range
  g.kinds = {0};
  g.head_kinds = alternating_head_kinds(2);
  EXPECT_THROW(rot_inv_attention(tape, v, v, v, g.view(), 1.0), CheckError);
  g.senders = {1};
  g.head_kinds = alternating_head_kinds(3);  // 4 columns do not split into 3 heads
  EXPECT_THROW(rot_inv_attention(tape, v, v, v, g.view(), 1.0), CheckError);
}

}  // namespace layersnet::ad::testing
