// The graph ops composed the way LayersNet's RotAttention uses them (official encoder layer): the
// fused attention for self messages, its edge weights on the inter edges, the hidden-space
// rotation phi(R) = W R W^T, an MLP in the local frame and phi(R)^T back, summed per patch.
// Checked end to end with a directional derivative (JAX check_grads style), then in float
// against double, and for arena reuse across steps.
#include "autodiff/ops_dense.h"
#include "autodiff/ops_graph.h"
#include "edge_kinds.h"
#include "gradcheck_registry.h"

#include <Eigen/Geometry>

#include <random>
#include <vector>

namespace layersnet::ad::testing {

namespace {

constexpr int kHeads = 2, kDim = 4, kP = 4, kM = 5, kK = 3;  // one group: head 0 world, head 1 mesh

// Receiver i: a few world and mesh patch senders, then kK inter senders (rows kM + i*kK + k).
struct LayerGraph {
  std::vector<int32_t> offsets{0}, senders, kinds, inter_edges, inter_receivers, inter_senders, inter_offsets{0};
  std::vector<uint32_t> head_kinds = alternating_head_kinds(kHeads);
  LayerGraph() {
    std::mt19937 rng(7);
    for (int i = 0; i < kP; ++i) {
      const int n_self = i == 2 ? 0 : 1 + static_cast<int>(rng() % 4);  // receiver 2: inter edges only
      for (int k = 0; k < n_self; ++k) {
        senders.push_back(static_cast<int32_t>(rng() % kM));
        kinds.push_back(k % 2 == 0 ? kWorldEdge : kMeshEdge);
      }
      for (int k = 0; k < kK; ++k) {
        inter_edges.push_back(static_cast<int32_t>(senders.size()));
        inter_receivers.push_back(i);
        inter_senders.push_back(kM + i * kK + k);
        senders.push_back(kM + i * kK + k);
        kinds.push_back(kInterEdge);
      }
      offsets.push_back(static_cast<int32_t>(senders.size()));
      inter_offsets.push_back(static_cast<int32_t>(inter_edges.size()));
    }
  }
  RiaGraph view() const { return {offsets, senders, kinds, head_kinds, kSelfMessageKinds}; }
};

// Inputs: q, r (P, H*D); s = [patch senders; inter senders] (M + P*K, H*D); W (D, 3);
// Rot (P*K, 9); A (D, D); c (1, D). Returns the (P, H*D) attention output of RotAttention.
template <class T>
Var<T> rot_attention(Tape<T>& t, const std::vector<Var<T>>& v, const LayerGraph& g) {
  const auto& [q, r, s, W, rot, A, c] = std::array<Var<T>, 7>{v[0], v[1], v[2], v[3], v[4], v[5], v[6]};
  const RiaResult<T> att = rot_inv_attention(t, q, r, s, g.view(), T(1 / std::sqrt(double(kDim))));
  // Inter messages of the world head (columns 0..D-1), weighted by its b' = b / ||r - hs||.
  Var<T> b = slice_cols(t, gather_rows(t, att.weights, g.inter_edges), 0, 1);              // (P*K, 1)
  Var<T> rv = slice_cols(t, gather_rows(t, r, g.inter_receivers), 0, kDim);               // (P*K, D)
  Var<T> hs = slice_cols(t, gather_rows(t, s, g.inter_senders), 0, kDim);                 // (P*K, D)
  Var<T> local = rot_map_apply(t, W, rot, add(t, rv, hs));                                 // H (r + hs)
  Var<T> u = rot_map_apply(t, W, rot, relu(t, linear(t, local, A, c)), /*transpose=*/true);  // H^T ReLU(.)
  Var<T> msg = segment_sum(t, mul(t, u, b), g.inter_offsets);                              // (P, D)
  Var<T> zeros = t.zeros(kP, kHeads * kDim - kDim);
  return add(t, att.out, concat_cols(t, {msg, zeros}));  // messages land in channels 0..D-1
}

std::vector<GradcheckInput> layer_inputs() {
  const int rows_s = kM + kP * kK, C = kHeads * kDim;
  RowMat<double> rot(kP * kK, 9);
  RowMat<double> normals = random_matrix(kP * kK, 3, 207);
  normals.row(0) << 0, 0, 1;  // axis-parallel body normals too
  normals.row(1) << -1, 0, 0;
  for (int k = 0; k < normals.rows(); ++k) normals.row(k).normalize();
  for (int k = 0; k < normals.rows(); ++k) {  // R n = e_z
    const Eigen::Matrix3d m =
        Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d(normals.row(k).transpose()), Eigen::Vector3d::UnitZ())
            .toRotationMatrix();
    for (int c = 0; c < 9; ++c) rot(k, c) = m(c / 3, c % 3);
  }
  return {{random_matrix(kP, C, 201)}, {random_matrix(kP, C, 202)}, {random_matrix(rows_s, C, 203)},
          {random_matrix(kDim, 3, 204)}, {rot, false}, {random_matrix(kDim, kDim, 205)}, {random_matrix(1, kDim, 206)}};
}

}  // namespace

TEST(RiaComposition, OfficialRotAttentionLayerDirectionalCheck) {
  const LayerGraph g;
  const auto loss = [&g](Tape<double>& t, const std::vector<Var<double>>& v) {
    Var<double> out = rot_attention(t, v, g);
    return mean_all(t, squared_error(t, out, t.zeros(out.rows, out.cols)));
  };
  const auto inputs = layer_inputs();
  for (unsigned seed : {1u, 2u, 3u}) {
    GradcheckOptions opt;
    opt.seed = seed;
    const DirectionalReport rep = directional_gradcheck(loss, inputs, opt);
    EXPECT_TRUE(rep.ok) << "analytic " << rep.analytic << " numeric " << rep.numeric;
    EXPECT_NE(rep.analytic, 0.0);
  }
  // Per-op: the whole layer output against central differences on every coordinate.
  const auto f = [&g](Tape<double>& t, const std::vector<Var<double>>& v) { return rot_attention(t, v, g); };
  const GradcheckReport rep = expect_gradcheck(OpKind::RotInvAttention, f, inputs);
  EXPECT_TRUE(rep.ops_seen.count(OpKind::RotMapApply));
  EXPECT_TRUE(rep.ops_seen.count(OpKind::GatherRows));
  EXPECT_TRUE(rep.ops_seen.count(OpKind::SegmentSum));
  // Receiver 2 has only inter edges: its self message is zero but the inter message is not.
  EXPECT_FALSE(rep.output.row(2).head(kDim).isZero());
  EXPECT_TRUE(rep.output.row(2).tail(kDim).isZero());
}

TEST(RiaComposition, FloatAgreesWithDoubleAndArenaIsReused) {
  const LayerGraph g;
  const auto inputs = layer_inputs();
  Tape<double> td;
  std::vector<Var<double>> vd;
  for (const auto& in : inputs) vd.push_back(td.leaf(in.value.data(), in.value.rows(), in.value.cols()));
  Var<double> yd = rot_attention(td, vd, g);
  std::fill_n(yd.grad, yd.size(), 1.0);
  td.backward_seeded();

  Tape<float> tf(/*first_block_bytes=*/512);
  std::size_t heap_after_second = 0, bytes_first = 0;
  for (int step = 0; step < 4; ++step) {
    tf.reset();
    std::vector<RowMat<float>> values;
    std::vector<Var<float>> vf;
    for (const auto& in : inputs) {
      values.push_back(in.value.cast<float>());
      vf.push_back(tf.leaf(values.back().data(), in.value.rows(), in.value.cols()));
    }
    Var<float> yf = rot_attention(tf, vf, g);
    std::fill_n(yf.grad, yf.size(), 1.0f);
    tf.backward_seeded();
    const double scale = yd.val().cwiseAbs().maxCoeff();
    EXPECT_LT((yf.val().cast<double>() - yd.val()).cwiseAbs().maxCoeff(), 1e-4 * scale);
    for (std::size_t k = 0; k < vf.size(); ++k) {
      const double gs = vd[k].grd().cwiseAbs().maxCoeff() + 1e-12;
      EXPECT_LT((vf[k].grd().cast<double>() - vd[k].grd()).cwiseAbs().maxCoeff(), 1e-3 * gs) << "input " << k;
    }
    if (step == 0) bytes_first = tf.arena().bytes_in_use();
    if (step == 1) heap_after_second = tf.arena().heap_allocations();
    if (step >= 2) {
      EXPECT_EQ(tf.arena().heap_allocations(), heap_after_second) << "a steady-state step allocated";
      EXPECT_EQ(tf.arena().bytes_in_use(), bytes_first);
    }
  }
}

}  // namespace layersnet::ad::testing
