#include "autodiff/ops_cloth.h"

#include "autodiff/ops_graph.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <vector>

namespace layersnet::ad {

namespace {

template <class T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

// The shortest length a normal is divided by (row_normalize's default).
template <class T>
constexpr T kNormalEps = T(1e-12);

template <class T>
Vec3<T> row3(const T* x, int32_t r) {
  return Vec3<T>(x[3 * r], x[3 * r + 1], x[3 * r + 2]);
}

template <class T>
void add_row3(T* x, int32_t r, const Vec3<T>& v) {
  for (int c = 0; c < 3; ++c) x[3 * r + c] += v[c];
}

// c / max(|c|, eps) and the divisor.
template <class T>
Vec3<T> unit(const Vec3<T>& c, T& divisor) {
  divisor = std::max(c.norm(), kNormalEps<T>);
  return c / divisor;
}

// The gradient of c from that of u = c / divisor (row_normalize's backward: no projection where
// the divisor is the constant eps).
template <class T>
Vec3<T> unit_backward(const Vec3<T>& u, T divisor, const Vec3<T>& g_u) {
  const T along = divisor > kNormalEps<T> ? u.dot(g_u) : T(0);
  return (g_u - along * u) / divisor;
}

template <class T>
void check_points(const char* what, const Var<T>& x) {
  LAYERSNET_CHECK(x.cols == 3, what << ": x must be (V, 3), got (" << x.rows << ", " << x.cols << ")");
}

// One hinge's unit normals and unit edge at x (dihedral_alignment's forward and backward).
template <class T>
struct Hinge {
  Vec3<T> uA, vA, uB, vB, edge, nA, nB, e;
  T mA, mB, me;
  Hinge(const T* x, int32_t i, int32_t j, int32_t a, int32_t p, int32_t q, int32_t b) {
    const Vec3<T> xi = row3(x, i), xp = row3(x, p);
    uA = row3(x, j) - xi, vA = row3(x, a) - xi;
    uB = row3(x, q) - xp, vB = row3(x, b) - xp;
    edge = xi - row3(x, j);
    nA = unit<T>(uA.cross(vA), mA);
    nB = unit<T>(uB.cross(vB), mB);
    e = unit<T>(edge, me);
  }
};

}  // namespace

// ---- vertex_normals ---------------------------------------------------------------------
// Node: in[0] = x; FaceParams::faces; saved = [unit face normals (F, 3) | their divisors (F) |
// the vertex sums' divisors (V)].
template <class T>
Var<T> vertex_normals(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> faces) {
  check_points("vertex_normals", x);
  LAYERSNET_CHECK(faces.size() % 3 == 0, "vertex_normals: " << faces.size() << " face corners is not a multiple of 3");
  check_indices("vertex_normals faces", faces, x.rows);
  const int64_t V = x.rows, F = static_cast<int64_t>(faces.size() / 3);
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(V, 3, grad);
  T* saved = tape.scratch(static_cast<std::size_t>(4 * F + V));
  T *face_unit = saved, *face_divisor = saved + 3 * F, *vertex_divisor = saved + 4 * F;
  std::fill(out.value, out.value + 3 * V, T(0));
  for (int64_t f = 0; f < F; ++f) {
    const int32_t* c = &faces[3 * f];
    const Vec3<T> x1 = row3(x.value, c[1]);
    const Vec3<T> n = unit<T>((row3(x.value, c[2]) - x1).cross(row3(x.value, c[0]) - x1), face_divisor[f]);
    for (int k = 0; k < 3; ++k) face_unit[3 * f + k] = n[k];
    for (int k = 0; k < 3; ++k) add_row3(out.value, c[k], n);
  }
  for (int64_t v = 0; v < V; ++v) {
    const Vec3<T> n = unit<T>(row3(out.value, static_cast<int32_t>(v)), vertex_divisor[v]);
    for (int k = 0; k < 3; ++k) out.value[3 * v + k] = n[k];
  }
  if (grad) tape.record(OpKind::VertexNormals, out, {x}, FaceParams{tape.copy_to_arena(faces)}).saved = saved;
  return out;
}

template <class T>
void backward_vertex_normals(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (!x.grad) return;
  const std::span<const int32_t> faces = std::get<FaceParams>(node.params).faces;
  const int64_t V = x.rows, F = static_cast<int64_t>(faces.size() / 3);
  const T *face_unit = node.saved, *face_divisor = node.saved + 3 * F, *vertex_divisor = node.saved + 4 * F;
  std::vector<T> sum_grad(static_cast<std::size_t>(3 * V));  // of each vertex's unnormalised sum
  for (int64_t v = 0; v < V; ++v) {
    const auto r = static_cast<int32_t>(v);
    const Vec3<T> g = unit_backward<T>(row3(node.out.value, r), vertex_divisor[v], row3(node.out.grad, r));
    for (int k = 0; k < 3; ++k) sum_grad[3 * v + k] = g[k];
  }
  for (int64_t f = 0; f < F; ++f) {
    const int32_t* c = &faces[3 * f];
    const Vec3<T> g_unit = row3(sum_grad.data(), c[0]) + row3(sum_grad.data(), c[1]) + row3(sum_grad.data(), c[2]);
    const Vec3<T> g_cross = unit_backward<T>(row3(face_unit, static_cast<int32_t>(f)), face_divisor[f], g_unit);
    // cross = a × b with a = x2 − x1, b = x0 − x1.
    const Vec3<T> x1 = row3(x.value, c[1]);
    const Vec3<T> a = row3(x.value, c[2]) - x1, b = row3(x.value, c[0]) - x1;
    const Vec3<T> g_a = b.cross(g_cross), g_b = g_cross.cross(a);
    add_row3(x.grad, c[2], g_a);
    add_row3(x.grad, c[0], g_b);
    add_row3<T>(x.grad, c[1], -(g_a + g_b));
  }
}

// ---- spring_energy ----------------------------------------------------------------------
// Node: in[0] = x; SpringParams. Lengths are recomputed in backward.
template <class T>
Var<T> spring_energy(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> i, std::span<const int32_t> j,
                     std::span<const T> rest, std::span<const T> half_k) {
  check_points("spring_energy", x);
  LAYERSNET_CHECK(j.size() == i.size() && rest.size() == i.size() && half_k.size() == i.size(),
                  "spring_energy: " << i.size() << " and " << j.size() << " ends, " << rest.size() << " rest lengths and "
                                    << half_k.size() << " stiffnesses");
  check_indices("spring_energy i", i, x.rows);
  check_indices("spring_energy j", j, x.rows);
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(1, 1, grad);
  double sum = 0;
  for (std::size_t e = 0; e < i.size(); ++e) {
    const double stretch = static_cast<double>((row3(x.value, i[e]) - row3(x.value, j[e])).norm() - rest[e]);
    sum += static_cast<double>(half_k[e]) * stretch * stretch;
  }
  out.value[0] = static_cast<T>(sum);
  if (grad)
    tape.record(OpKind::SpringEnergy, out, {x},
                SpringParams<T>{tape.copy_to_arena(i), tape.copy_to_arena(j), tape.copy_to_arena(rest), tape.copy_to_arena(half_k)});
  return out;
}

template <class T>
void backward_spring_energy(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (!x.grad) return;
  const auto& s = std::get<SpringParams<T>>(node.params);
  const T g = node.out.grad[0];
  for (std::size_t e = 0; e < s.i.size(); ++e) {
    const Vec3<T> d = row3(x.value, s.i[e]) - row3(x.value, s.j[e]);
    const T length = d.norm();
    if (length == T(0)) continue;
    const Vec3<T> push = (g * 2 * s.half_k[e] * (length - s.rest[e]) / length) * d;
    add_row3(x.grad, s.i[e], push);
    add_row3<T>(x.grad, s.j[e], -push);
  }
}

// ---- dihedral_alignment -----------------------------------------------------------------
// Node: in[0] = x; DihedralParams. The hinges' normals are recomputed in backward.
template <class T>
Var<T> dihedral_alignment(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> i, std::span<const int32_t> j,
                          std::span<const int32_t> a, std::span<const int32_t> p, std::span<const int32_t> q,
                          std::span<const int32_t> b, std::span<const T> k_cos, std::span<const T> k_sin) {
  check_points("dihedral_alignment", x);
  const std::size_t H = i.size();
  const std::array<std::span<const int32_t>, 6> corners{i, j, a, p, q, b};
  for (const auto& c : corners) {
    LAYERSNET_CHECK(c.size() == H, "dihedral_alignment: corner arrays of " << H << " and " << c.size() << " hinges");
    check_indices("dihedral_alignment corners", c, x.rows);
  }
  LAYERSNET_CHECK(k_cos.size() == H && k_sin.size() == H,
                  "dihedral_alignment: " << H << " hinges but " << k_cos.size() << " and " << k_sin.size() << " weights");
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(1, 1, grad);
  double sum = 0;
  for (std::size_t h = 0; h < H; ++h) {
    const Hinge<T> g(x.value, i[h], j[h], a[h], p[h], q[h], b[h]);
    sum += static_cast<double>(k_cos[h] * g.nA.dot(g.nB) + k_sin[h] * g.nA.cross(g.nB).dot(g.e));
  }
  out.value[0] = static_cast<T>(sum);
  if (grad) {
    DihedralParams<T> params;
    for (int c = 0; c < 6; ++c) params.corners[c] = tape.copy_to_arena(corners[c]);
    params.k_cos = tape.copy_to_arena(k_cos), params.k_sin = tape.copy_to_arena(k_sin);
    tape.record(OpKind::DihedralAlignment, out, {x}, params);
  }
  return out;
}

template <class T>
void backward_dihedral_alignment(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (!x.grad) return;
  const auto& s = std::get<DihedralParams<T>>(node.params);
  const auto& [i, j, a, p, q, b] = s.corners;
  const T g = node.out.grad[0];
  for (std::size_t h = 0; h < i.size(); ++h) {
    const Hinge<T> k(x.value, i[h], j[h], a[h], p[h], q[h], b[h]);
    // cos = nA·nB, sin = (nA × nB)·e = nA·(nB × e) = nB·(e × nA).
    const Vec3<T> g_nA = g * (s.k_cos[h] * k.nB + s.k_sin[h] * k.nB.cross(k.e));
    const Vec3<T> g_nB = g * (s.k_cos[h] * k.nA + s.k_sin[h] * k.e.cross(k.nA));
    const Vec3<T> g_e = (g * s.k_sin[h]) * k.nA.cross(k.nB);
    // Through the normalisations, then the cross products (d(u × v) = du × v + u × dv).
    const Vec3<T> g_cA = unit_backward<T>(k.nA, k.mA, g_nA), g_cB = unit_backward<T>(k.nB, k.mB, g_nB);
    const Vec3<T> g_edge = unit_backward<T>(k.e, k.me, g_e);
    const Vec3<T> g_uA = k.vA.cross(g_cA), g_vA = g_cA.cross(k.uA);
    const Vec3<T> g_uB = k.vB.cross(g_cB), g_vB = g_cB.cross(k.uB);
    add_row3(x.grad, j[h], g_uA);
    add_row3(x.grad, a[h], g_vA);
    add_row3<T>(x.grad, i[h], g_edge - g_uA - g_vA);
    add_row3(x.grad, q[h], g_uB);
    add_row3(x.grad, b[h], g_vB);
    add_row3<T>(x.grad, p[h], -(g_uB + g_vB));
    add_row3<T>(x.grad, j[h], -g_edge);
  }
}

#define LAYERSNET_INSTANTIATE(T)                                                                                          \
  template Var<T> vertex_normals<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>);                                  \
  template Var<T> spring_energy<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>, std::span<const int32_t>,           \
                                   std::span<const T>, std::span<const T>);                                              \
  template Var<T> dihedral_alignment<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>, std::span<const int32_t>,      \
                                        std::span<const int32_t>, std::span<const int32_t>, std::span<const int32_t>,     \
                                        std::span<const int32_t>, std::span<const T>, std::span<const T>);               \
  template void backward_vertex_normals<T>(const Node<T>&);                                                              \
  template void backward_spring_energy<T>(const Node<T>&);                                                               \
  template void backward_dihedral_alignment<T>(const Node<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

}  // namespace layersnet::ad
