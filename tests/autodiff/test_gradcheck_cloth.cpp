// Gradient checks of the cloth ops (autodiff/ops_cloth.h), and each against the composition of
// elementary ops it stands for: the same values and the same gradients.
#include "autodiff/ops_cloth.h"
#include "autodiff/ops_dense.h"
#include "autodiff/ops_geometry.h"
#include "autodiff/ops_graph.h"
#include "gradcheck_registry.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace layersnet::ad::testing {

namespace {

// A bent 3 × 3 grid of vertices: 8 triangles, 9 vertices, 8 interior edges.
struct Grid {
  std::vector<int32_t> faces;
  RowMat<double> x{9, 3};
  Grid() {
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        const int a = 3 * i + j, b = a + 3, c = a + 4, d = a + 1;
        faces.insert(faces.end(), {a, b, c, a, c, d});
      }
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) x.row(3 * i + j) << i, j, 0.3 * std::sin(i + 2.0 * j);
  }
};

// Hinges (i, j, a, p, q, b) of the grid's faces that share an edge, found by brute force.
struct Hinges {
  std::vector<int32_t> i, j, a, p, q, b;
  std::vector<double> k_cos, k_sin;
  explicit Hinges(const std::vector<int32_t>& faces) {
    const int F = static_cast<int>(faces.size() / 3);
    for (int f = 0; f < F; ++f)
      for (int g = f + 1; g < F; ++g)
        for (int e = 0; e < 3; ++e) {
          const int32_t u = faces[3 * f + e], v = faces[3 * f + (e + 1) % 3], w = faces[3 * f + (e + 2) % 3];
          for (int h = 0; h < 3; ++h) {
            const int32_t s = faces[3 * g + h], t = faces[3 * g + (h + 1) % 3], o = faces[3 * g + (h + 2) % 3];
            if (!((s == u && t == v) || (s == v && t == u))) continue;
            i.push_back(u), j.push_back(v), a.push_back(w), p.push_back(s), q.push_back(t), b.push_back(o);
            const double theta0 = 0.1 * static_cast<double>(i.size());  // weights that differ per hinge
            k_cos.push_back(0.7 * std::cos(theta0)), k_sin.push_back(0.7 * std::sin(theta0));
          }
        }
  }
};

// The compositions the ops replace, as the physics energy and the losses recorded them.
Var<double> normals_by_composition(Tape<double>& t, const Var<double>& x, const std::vector<int32_t>& faces) {
  const int64_t F = static_cast<int64_t>(faces.size() / 3);
  std::vector<int32_t> corner[3];
  for (int k = 0; k < 3; ++k)
    for (int64_t f = 0; f < F; ++f) corner[k].push_back(faces[3 * f + k]);
  const Var<double> v0 = gather_rows(t, x, corner[0]), v1 = gather_rows(t, x, corner[1]), v2 = gather_rows(t, x, corner[2]);
  const Var<double> fn = row_normalize(t, cross3(t, sub(t, v2, v1), sub(t, v0, v1)));
  std::vector<int32_t> all(corner[0]);
  all.insert(all.end(), corner[1].begin(), corner[1].end());
  all.insert(all.end(), corner[2].begin(), corner[2].end());
  return row_normalize(t, scatter_add_rows(t, concat_rows(t, concat_rows(t, fn, fn), fn), all, x.rows));
}

Var<double> alignment_by_composition(Tape<double>& t, const Var<double>& x, const Hinges& h) {
  auto at = [&](const std::vector<int32_t>& idx) { return gather_rows(t, x, idx); };
  const Var<double> xi = at(h.i), xj = at(h.j), xa = at(h.a), xp = at(h.p), xq = at(h.q), xb = at(h.b);
  const Var<double> nA = row_normalize(t, cross3(t, sub(t, xj, xi), sub(t, xa, xi)));
  const Var<double> nB = row_normalize(t, cross3(t, sub(t, xq, xp), sub(t, xb, xp)));
  const Var<double> e = row_normalize(t, sub(t, xi, xj));
  const Var<double> cos_t = row_sum(t, mul(t, nA, nB)), sin_t = row_sum(t, mul(t, cross3(t, nA, nB), e));
  auto weighted = [&](const Var<double>& v, const std::vector<double>& w) {
    return sum_all(t, mul(t, v, t.constant(w.data(), static_cast<int64_t>(w.size()), 1)));
  };
  return add(t, weighted(cos_t, h.k_cos), weighted(sin_t, h.k_sin));
}

// Value and gradient of two functions of the same input agree to `tol` relative to their largest
// entry or 1 (the eps convention makes gradients of order 1e12 at a degenerate face).
void expect_same(const GradcheckFn& f, const GradcheckFn& g, const RowMat<double>& x, double tol) {
  GradcheckOptions opt;
  opt.max_coords = 0;
  const GradcheckReport a = gradcheck(f, {{x}}, opt), b = gradcheck(g, {{x}}, opt);
  ASSERT_EQ(a.output.rows(), b.output.rows());
  auto scale = [](const RowMat<double>& m) { return std::max(1.0, m.cwiseAbs().maxCoeff()); };
  EXPECT_LT((a.output - b.output).cwiseAbs().maxCoeff(), tol * scale(a.output));
  EXPECT_LT((a.gradients[0] - b.gradients[0]).cwiseAbs().maxCoeff(), tol * scale(a.gradients[0]));
}

}  // namespace

// ---- vertex_normals ---------------------------------------------------------------------

GRADCHECK_TEST(VertexNormals, BentGridAndItsComposition) {
  const Grid grid;
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return vertex_normals<double>(t, v[0], grid.faces); };
  const GradcheckReport rep = expect_gradcheck(OpKind::VertexNormals, f, {{grid.x}});
  for (int v = 0; v < 9; ++v) EXPECT_NEAR(rep.output.row(v).norm(), 1.0, 1e-14);
  const auto g = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return normals_by_composition(t, v[0], grid.faces); };
  expect_same(f, g, grid.x, 1e-12);
  expect_thread_count_invariant(f, {{grid.x}});
}

GRADCHECK_TEST(VertexNormals, ZeroAreaFaceAndLooseVertex) {
  // Vertex 3 is in no face; face (0, 1, 2) is flat in z = 0, face (0, 1, 4) has collinear corners.
  RowMat<double> x(5, 3);
  x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 5, 5, 5, 2, 0, 0;
  const std::vector<int32_t> faces{0, 1, 2, 0, 1, 4};
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return vertex_normals<double>(t, v[0], faces); };
  GradcheckOptions opt;
  opt.max_coords = 0;  // finite differences across the degenerate face are not meaningful
  const GradcheckReport rep = gradcheck(f, {{x}}, opt);
  EXPECT_TRUE(rep.finite) << rep.failures;
  EXPECT_TRUE(rep.output.row(3).isZero());
  EXPECT_TRUE(rep.output.row(4).isZero());
  // (x2 − x1) × (x0 − x1) = +z: the flat face alone sets vertices 0, 1 and 2.
  for (int v = 0; v < 3; ++v) EXPECT_NEAR(rep.output(v, 2), 1.0, 1e-12) << "vertex " << v;
  const auto g = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return normals_by_composition(t, v[0], faces); };
  expect_same(f, g, x, 1e-12);
}

// ---- spring_energy ----------------------------------------------------------------------

GRADCHECK_TEST(SpringEnergy, RandomSpringsAndItsFormula) {
  const RowMat<double> x = random_matrix(6, 3, 301);
  const std::vector<int32_t> i{0, 1, 2, 3, 0, 5}, j{1, 2, 3, 4, 5, 2};
  const std::vector<double> rest{0.5, 0.8, 1.0, 0.2, 1.5, 0.9}, half_k{1.0, 2.0, 0.5, 3.0, 0.25, 1.5};
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return spring_energy<double>(t, v[0], i, j, rest, half_k);
  };
  const GradcheckReport rep = expect_gradcheck(OpKind::SpringEnergy, f, {{x}});
  double expected = 0;
  for (std::size_t e = 0; e < i.size(); ++e) {
    const double stretch = (x.row(i[e]) - x.row(j[e])).norm() - rest[e];
    expected += half_k[e] * stretch * stretch;
  }
  EXPECT_NEAR(rep.output(0, 0), expected, 1e-13);
  expect_thread_count_invariant(f, {{x}});
}

GRADCHECK_TEST(SpringEnergy, ZeroLengthSpringHasAFiniteGradient) {
  RowMat<double> x = random_matrix(3, 3, 302);
  x.row(1) = x.row(0);
  const std::vector<int32_t> i{0, 1}, j{1, 2};
  const std::vector<double> rest{0.5, 0.5}, half_k{1.0, 1.0};
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return spring_energy<double>(t, v[0], i, j, rest, half_k);
  };
  GradcheckOptions opt;
  opt.max_coords = 0;
  const GradcheckReport rep = gradcheck(f, {{x}}, opt);
  EXPECT_TRUE(rep.finite);
  EXPECT_TRUE(rep.ops_seen.count(OpKind::SpringEnergy));
  // Only the second spring pulls: rows 0 and 1 get nothing from the first.
  EXPECT_TRUE(rep.gradients[0].row(0).isZero());
}

// ---- dihedral_alignment -----------------------------------------------------------------

GRADCHECK_TEST(DihedralAlignment, BentGridAndItsComposition) {
  const Grid grid;
  const Hinges h(grid.faces);
  ASSERT_EQ(h.i.size(), 8u);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return dihedral_alignment<double>(t, v[0], h.i, h.j, h.a, h.p, h.q, h.b, h.k_cos, h.k_sin);
  };
  expect_gradcheck(OpKind::DihedralAlignment, f, {{grid.x}});
  const auto g = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return alignment_by_composition(t, v[0], h); };
  expect_same(f, g, grid.x, 1e-12);
  expect_thread_count_invariant(f, {{grid.x}});
  // Random positions (folds of every sign) too.
  expect_same(f, g, random_matrix(9, 3, 303), 1e-11);
  expect_gradcheck(OpKind::DihedralAlignment, f, {{random_matrix(9, 3, 304)}});
}

GRADCHECK_TEST(DihedralAlignment, FlatAndRightAngleFolds) {
  // Face A = (i, j, a) = (0, 1, 2), face B = (p, q, b) = (1, 0, 3), hinge along x.
  RowMat<double> flat(4, 3), folded(4, 3);
  flat << 0, 0, 0, 1, 0, 0, 0.5, 1, 0, 0.5, -1, 0;
  folded << 0, 0, 0, 1, 0, 0, 0.5, 1, 0, 0.5, 0, 1;
  const std::vector<int32_t> i{0}, j{1}, a{2}, p{1}, q{0}, b{3};
  auto value = [&](const RowMat<double>& x, double k_cos, double k_sin) {
    const std::vector<double> kc{k_cos}, ks{k_sin};
    const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
      return dihedral_alignment<double>(t, v[0], i, j, a, p, q, b, kc, ks);
    };
    GradcheckOptions opt;
    opt.max_coords = 0;
    return gradcheck(f, {{x}}, opt).output(0, 0);
  };
  EXPECT_NEAR(value(flat, 1, 0), 1.0, 1e-15);   // cos 0
  EXPECT_NEAR(value(flat, 0, 1), 0.0, 1e-15);   // sin 0
  EXPECT_NEAR(value(folded, 1, 0), 0.0, 1e-15); // cos 90°
  EXPECT_NEAR(value(folded, 0, 1), 1.0, 1e-15); // sin 90°
}

}  // namespace layersnet::ad::testing
