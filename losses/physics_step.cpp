#include "losses/physics_step.h"

#include "autodiff/conjugate_gradients.h"
#include "dataset/kept.h"
#include "dataset/neighbours.h"
#include "autodiff/check.h"

#include <Eigen/Dense>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

namespace layersnet::losses {
namespace {

using Vec = std::vector<double>;
using Block = Eigen::Matrix3d;

double dot(const Vec& a, const Vec& b) {
  double s = 0;
  for (std::size_t k = 0; k < a.size(); ++k) s += a[k] * b[k];
  return s;
}

// What the energy's contact terms found at a point, for the Hessian at the same point.
struct ContactsAt {
  std::vector<int32_t> body_nearest;   // (N) each row's nearest body vertex; empty without the body term
  std::vector<int32_t> layer_nearest;  // (N_outer) each outer vertex's nearest inner vertex; empty without the layer term
  std::vector<double> layer_normal;    // (N_outer · 3) that inner vertex's unit normal
};

// N · physics_energy (the energy itself, not per vertex) at one point, on this thread's tape: the
// value, the contacts (what the Hessian at that point needs), and the gradient
// on demand after a differentiable evaluation, so the line search's accepted point is evaluated
// once for both.
class EnergyAt {
 public:
  // differentiable: record what gradient() needs (a trial that may become the next iterate).
  double evaluate(const PhysicsInput<double>& in, const Vec& x, const PhysicsSettings& s, bool differentiable) {
    N_ = static_cast<int64_t>(x.size() / 3);
    tape().reset();
    X_ = differentiable ? tape().leaf(x.data(), N_, 3) : tape().constant(x.data(), N_, 3);
    differentiable_ = differentiable;
    PhysicsTerms<double> terms = physics_energy(tape(), X_, in, s);
    total_ = terms.total;
    contacts_ = {std::move(terms.body_nearest), std::move(terms.layer_nearest), std::move(terms.layer_normal)};
    return total_.scalar() * scale();
  }
  // The gradient of N · E at the point last evaluated (differentiable).
  void gradient(Vec& g) {
    LAYERSNET_CHECK(differentiable_, "physics step: the gradient of an energy evaluated without one");
    tape().backward(total_);
    g.assign(X_.grad, X_.grad + 3 * N_);
    for (double& v : g) v *= scale();
  }
  // Hands over the contacts found at the point last evaluated.
  ContactsAt take_contacts() { return std::move(contacts_); }

 private:
  // One tape per thread, reset for each evaluation: its arena keeps its pages from one evaluation
  // and one frame to the next instead of the kernel zeroing fresh ones.
  static ad::Tape<double>& tape() {
    thread_local ad::Tape<double> t;
    return t;
  }
  double scale() const { return static_cast<double>(std::max<int64_t>(N_, 1)); }
  int64_t N_ = 0;
  bool differentiable_ = false;
  ad::Var<double> X_, total_;
  ContactsAt contacts_;
};

// Where the approximate Hessian's blocks sit in a block-CSR matrix over the N vertices: the
// sparsity of the springs and hinges, found once per structure (pattern_for) and filled at each
// Newton iteration.
struct HessianPattern {
  std::shared_ptr<const dataset::SequenceStructure> structure;  // where it was found; null: not kept
  std::vector<int32_t> offsets;                 // (N + 1) CSR over block rows
  std::vector<int32_t> columns;                 // (nnz) ascending within a row
  std::vector<int32_t> diagonal;                // (N) each row's diagonal block
  std::vector<std::array<int32_t, 2>> spring;   // (E) blocks (i, j) and (j, i)
  std::vector<std::array<int32_t, 12>> hinge;   // (H) blocks (p, q), p ≠ q, over the corners (i, j, a, b), p-major
};

std::array<int32_t, 4> hinge_corners(const PhysicsInput<double>& in, std::size_t k) {
  return {in.hinge_i[k], in.hinge_j[k], in.hinge_a[k], in.hinge_b[k]};
}

HessianPattern hessian_pattern(const PhysicsInput<double>& in, int64_t N) {
  std::vector<std::vector<int32_t>> row(static_cast<std::size_t>(N));
  for (int64_t v = 0; v < N; ++v) row[v].push_back(static_cast<int32_t>(v));
  for (std::size_t e = 0; e < in.edge_i.size(); ++e) {
    row[in.edge_i[e]].push_back(in.edge_j[e]);
    row[in.edge_j[e]].push_back(in.edge_i[e]);
  }
  for (std::size_t k = 0; k < in.hinge_i.size(); ++k) {
    const std::array<int32_t, 4> c = hinge_corners(in, k);
    for (int p = 0; p < 4; ++p)
      for (int q = 0; q < 4; ++q)
        if (p != q) row[c[p]].push_back(c[q]);
  }
  HessianPattern pattern;
  pattern.structure = in.structure;
  pattern.offsets.reserve(static_cast<std::size_t>(N) + 1);
  pattern.offsets.push_back(0);
  for (auto& r : row) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
    pattern.columns.insert(pattern.columns.end(), r.begin(), r.end());
    pattern.offsets.push_back(static_cast<int32_t>(pattern.columns.size()));
  }
  auto at = [&](int32_t r, int32_t c) {
    const auto first = pattern.columns.begin() + pattern.offsets[r], last = pattern.columns.begin() + pattern.offsets[r + 1];
    return static_cast<int32_t>(std::lower_bound(first, last, c) - pattern.columns.begin());
  };
  pattern.diagonal.resize(static_cast<std::size_t>(N));
  for (int64_t v = 0; v < N; ++v) pattern.diagonal[v] = at(static_cast<int32_t>(v), static_cast<int32_t>(v));
  pattern.spring.resize(in.edge_i.size());
  for (std::size_t e = 0; e < in.edge_i.size(); ++e)
    pattern.spring[e] = {at(in.edge_i[e], in.edge_j[e]), at(in.edge_j[e], in.edge_i[e])};
  pattern.hinge.resize(in.hinge_i.size());
  for (std::size_t k = 0; k < in.hinge_i.size(); ++k) {
    const std::array<int32_t, 4> c = hinge_corners(in, k);
    int n = 0;
    for (int p = 0; p < 4; ++p)
      for (int q = 0; q < 4; ++q)
        if (p != q) pattern.hinge[k][n++] = at(c[p], c[q]);
  }
  return pattern;
}

// The pattern of `in`'s springs and hinges: made once per sequence structure and kept for the
// thread's last few structures (a rollout steps through one, a training thread through a few);
// made afresh where the input names no structure.
std::shared_ptr<const HessianPattern> pattern_for(const PhysicsInput<double>& in, int64_t N) {
  auto make = [&] { return std::make_shared<const HessianPattern>(hessian_pattern(in, N)); };
  if (!in.structure) return make();
  thread_local std::vector<std::shared_ptr<const HessianPattern>> recent;
  const std::shared_ptr<const HessianPattern> p =
      dataset::kept_or_made(recent, 8, [&](const HessianPattern& kept) { return kept.structure == in.structure; }, make);
  LAYERSNET_CHECK(static_cast<int64_t>(p->diagonal.size()) == N && p->spring.size() == in.edge_i.size() &&
                      p->hinge.size() == in.hinge_i.size(),
                  "physics step: the input's " << N << " vertices, " << in.edge_i.size() << " springs and "
                                               << in.hinge_i.size() << " hinges are not its structure's");
  return p;
}

// The approximate Hessian of N · E at x (see the header) as block-CSR on its pattern: mass and
// drag, the springs, bending, the body and layer contacts and the friction's tangential part.
struct Hessian {
  const HessianPattern* pattern = nullptr;
  std::vector<double> blocks;         // (nnz · 9) row-major 3×3
  // (nnz · 9 + 1) the same blocks by columns, then one 0, for the product: it reads a column as four
  // doubles, the fourth being the next column's (or the next block's, or that 0) and ignored.
  // Unpadded, a product streams 72 bytes a block instead of 96.
  std::vector<double> by_columns;
  std::vector<Block> preconditioner;  // (N) inverse of each vertex's diagonal block; 0 on fixed rows
  std::vector<Block> diagonal_sums;   // (N) the diagonal blocks while they are summed

  int64_t rows() const { return static_cast<int64_t>(preconditioner.size()); }
  // The by-columns copy of the blocks of rows [r0, r1) (by_columns sized already).
  void copy_by_columns(int64_t r0, int64_t r1) {
    const auto k0 = static_cast<std::size_t>(pattern->offsets[r0]), k1 = static_cast<std::size_t>(pattern->offsets[r1]);
    for (std::size_t k = k0; k < k1; ++k)
      for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) by_columns[9 * k + 3 * c + r] = blocks[9 * k + 3 * r + c];
  }
  // Rows [r0, r1) of y = H p, one row at a time: a gather, so no row is written twice; each block
  // adds its three columns times p's entries as 4-wide vectors.
  void multiply(const Vec& p, Vec& y, int64_t r0, int64_t r1) const {
    using V4 = Eigen::Vector4d;
    for (int64_t v = r0; v < r1; ++v) {
      V4 acc = V4::Zero();
      for (int32_t k = pattern->offsets[v]; k < pattern->offsets[v + 1]; ++k) {
        const double* b = &by_columns[9 * static_cast<std::size_t>(k)];
        const double* q = &p[3 * static_cast<std::size_t>(pattern->columns[k])];
        acc += Eigen::Map<const V4>(b) * q[0] + Eigen::Map<const V4>(b + 3) * q[1] + Eigen::Map<const V4>(b + 6) * q[2];
      }
      y[3 * v] = acc[0], y[3 * v + 1] = acc[1], y[3 * v + 2] = acc[2];
    }
  }
};

using RowBlock = Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>;

// The layer contacts' blocks k n nᵀ on the outer garment's vertices of rows [r0, r1) inside the layer
// margin, with the nearest inner vertex and its normal held still (as the body contacts hold the
// body still): without them the Newton step meets the layer term through its gradient alone.
void add_layer_contacts(const PhysicsInput<double>& in, const Vec& x, const PhysicsSettings& s, const ContactsAt& at_x,
                        int32_t r0, int32_t r1, std::vector<Block>& block) {
  const int64_t G = static_cast<int64_t>(in.garment_offsets.size()) - 1;
  if (G < 2 || s.collision_layer == 0) return;
  const int32_t o0 = in.garment_offsets[G - 1], o1 = in.garment_offsets[G];
  LAYERSNET_CHECK(static_cast<int64_t>(at_x.layer_nearest.size()) == o1 - o0 &&
                      at_x.layer_normal.size() == 3 * at_x.layer_nearest.size(),
                  "physics step: " << at_x.layer_nearest.size() << " layer contacts for " << o1 - o0 << " outer vertices");
  auto at = [&](int32_t v) { return Eigen::Vector3d(x[3 * v], x[3 * v + 1], x[3 * v + 2]); };
  const double root_k = std::sqrt(s.collision_stiffness * s.collision_layer);
  for (int32_t v = std::max(o0, r0); v < std::min(o1, r1); ++v) {
    const Eigen::Vector3d n(&at_x.layer_normal[3 * static_cast<std::size_t>(v - o0)]);
    if ((at(v) - at(at_x.layer_nearest[v - o0])).dot(n) >= s.layer_margin) continue;
    const Eigen::Vector3d u = root_k * n;
    block[v] += u * u.transpose();
  }
}

// Rows a thread of the step's threaded loops (the Hessian's fill, the conjugate gradients) takes at
// least, so that the solver's three meetings an iteration stay small beside its share of the
// product (about 80 µs for 3,120 rows). A choice timed only on that outfit and only for the solver,
// where two threads took 0.63× the time of one.
constexpr int64_t kRowsPerThread = 1024;

// Threads for a loop over N rows: those OpenMP offers outside a parallel region (one inside it,
// as in training's samples), at least kRowsPerThread rows each.
int step_threads(int64_t N) {
  return omp_in_parallel() ? 1 : static_cast<int>(std::clamp<int64_t>(N / kRowsPerThread, 1, omp_get_max_threads()));
}

// Fills h at x on `pattern`, in h's own buffers: a Hessian kept from one step to the next is neither
// allocated nor cleared again (every entry is written below). `at_x`: the contacts the energy
// found at x (EnergyAt's). Each thread fills the block rows of one contiguous range of vertices,
// walking every term in the same order and adding only to its own rows: every block sums its terms
// in the single pass's order, so the Hessian is the same bits on any thread count.
void fill_hessian(Hessian& h, const PhysicsInput<double>& in, const HessianPattern& pattern, const Vec& x,
                  const PhysicsSettings& s, const std::vector<uint8_t>& fixed, const ContactsAt& at_x) {
  const int64_t N = static_cast<int64_t>(x.size() / 3);
  h.pattern = &pattern;
  h.blocks.resize(9 * pattern.columns.size());
  h.by_columns.resize(9 * pattern.columns.size() + 1);
  h.by_columns.back() = 0.0;
  h.preconditioner.resize(N);
  h.diagonal_sums.resize(N);
  // Off-diagonal blocks go to their place at once; the diagonal ones are summed in `block` first,
  // for their inverses (the preconditioner).
  auto matrix_block = [&](int32_t position) { return RowBlock(&h.blocks[9 * static_cast<std::size_t>(position)]); };
  std::vector<Block>& block = h.diagonal_sums;
  const int64_t B = static_cast<int64_t>(in.body_pos.size() / 3);
  const bool body_contacts = B > 0 && s.collision_body != 0;
  LAYERSNET_CHECK(!body_contacts || static_cast<int64_t>(at_x.body_nearest.size()) == N,
                  "physics step: " << at_x.body_nearest.size() << " nearest body vertices for " << N << " rows");
  const int threads = step_threads(N);
#pragma omp parallel num_threads(threads) if (threads > 1)
  {
    const int64_t team = omp_get_num_threads(), me = omp_get_thread_num();
    const auto r0 = static_cast<int32_t>(N * me / team), r1 = static_cast<int32_t>(N * (me + 1) / team);
    auto mine = [&](int32_t v) { return v >= r0 && v < r1; };
    std::fill(h.blocks.begin() + 9 * static_cast<std::ptrdiff_t>(pattern.offsets[r0]),
              h.blocks.begin() + 9 * static_cast<std::ptrdiff_t>(pattern.offsets[r1]), 0.0);
    for (int32_t v = r0; v < r1; ++v) {
      block[v].setZero();
      block[v].diagonal().setConstant(2 * s.inertia * in.inertia_weight[v] +
                                      (in.drag_weight.empty() ? 0.0 : 2 * s.drag * in.drag_weight[v]));
    }
    for (std::size_t e = 0; e < in.edge_i.size(); ++e) {
      const int32_t i = in.edge_i[e], j = in.edge_j[e];
      if (!mine(i) && !mine(j)) continue;
      const Eigen::Vector3d d(x[3 * i] - x[3 * j], x[3 * i + 1] - x[3 * j + 1], x[3 * i + 2] - x[3 * j + 2]);
      const double l = d.norm(), k = 2 * s.stretch * in.edge_half_k[e];
      Block K = Block::Zero();
      if (l > 0) {
        const Eigen::Vector3d u = d / l;
        const Block along = u * u.transpose();
        K = k * (along + std::max(0.0, 1 - in.edge_rest[e] / l) * (Block::Identity() - along));
      }
      if (mine(i)) matrix_block(pattern.spring[e][0]) -= K, block[i] += K;
      if (mine(j)) matrix_block(pattern.spring[e][1]) -= K, block[j] += K;
    }
    // The dihedral angle's gradient: each far corner moves along its face normal over its height
    // above the hinge, and the hinge's ends take the opposite share by where the corner projects.
    auto at = [&](int32_t v) { return Eigen::Vector3d(x[3 * v], x[3 * v + 1], x[3 * v + 2]); };
    for (std::size_t k = 0; k < in.hinge_i.size() && s.bending != 0; ++k) {
      const int32_t i = in.hinge_i[k], j = in.hinge_j[k], a = in.hinge_a[k], b = in.hinge_b[k];
      if (!mine(i) && !mine(j) && !mine(a) && !mine(b)) continue;
      const Eigen::Vector3d xi = at(i), e = at(j) - xi;
      const double e2 = e.squaredNorm();
      const double stiffness = s.bending * std::hypot(in.hinge_k_cos0[k], in.hinge_k_sin0[k]);
      if (!(e2 > 0) || !(stiffness > 0)) continue;
      std::array<Eigen::Vector3d, 4> u{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                       Eigen::Vector3d::Zero()};
      bool degenerate = false;
      // The corners lie on opposite sides of the hinge, so e × r points to opposite sides for them:
      // rising together along (e × r_a, −e × r_b) folds the hinge, whatever the faces' winding.
      const int32_t corner[2] = {a, b};
      for (int f = 0; f < 2; ++f) {
        const Eigen::Vector3d r = at(corner[f]) - xi;
        const double t = r.dot(e) / e2;
        const Eigen::Vector3d height = r - t * e;
        const Eigen::Vector3d n = e.cross(r) * (f == 0 ? 1.0 : -1.0);
        const double h2 = height.squaredNorm(), nn = n.norm();
        if (!(h2 > 0) || !(nn > 0)) {
          degenerate = true;
          break;
        }
        const Eigen::Vector3d g = n / (nn * std::sqrt(h2));
        u[2 + f] += g, u[0] -= (1 - t) * g, u[1] -= t * g;
      }
      if (degenerate) continue;
      const double root_k = std::sqrt(stiffness);
      for (auto& v : u) v *= root_k;
      const int32_t rows[4] = {i, j, a, b};
      int n = 0;
      for (int p = 0; p < 4; ++p)
        for (int q = 0; q < 4; ++q) {
          if (p == q) {
            if (mine(rows[p])) block[rows[p]] += u[p] * u[p].transpose();
          } else {
            if (mine(rows[p])) matrix_block(pattern.hinge[k][n]) += u[p] * u[q].transpose();
            ++n;
          }
        }
    }
    if (body_contacts) {
      const double root_k = std::sqrt(s.collision_stiffness * s.collision_body);
      for (int32_t v = r0; v < r1; ++v) {
        const Eigen::Vector3d xv(x[3 * v], x[3 * v + 1], x[3 * v + 2]);
        const auto [n, r] = offset_from_body(in, at_x.body_nearest[v], xv);
        if (r.dot(n) >= s.body_margin) continue;
        const Eigen::Vector3d u = root_k * n;
        block[v] += u * u.transpose();
      }
    }
    add_layer_contacts(in, x, s, at_x, r0, r1, block);
    for (std::size_t k = 0; k < in.friction_rows.size(); ++k) {
      if (!mine(in.friction_rows[k])) continue;
      const Eigen::Vector3d n(&in.friction_normal[3 * k]);
      const double weight = 2 * s.friction * in.friction_half_weight[k];
      block[in.friction_rows[k]] += weight * (Block::Identity() - n * n.transpose());
    }
    for (int32_t v = r0; v < r1; ++v) {
      const bool usable = !fixed[v] && std::fabs(block[v].determinant()) > 1e-300;
      h.preconditioner[v] = usable ? Block(block[v].inverse()) : Block::Zero();
      matrix_block(pattern.diagonal[v]) = block[v];
    }
    h.copy_by_columns(r0, r1);
  }
}

// The Hessian as a block CSR matrix over the free vertices (what Hessian::multiply applies),
// with each vertex's inertia weight as its scale: A⁻¹ (s ⊙ a) is where the step's last Newton
// system moves the cloth when its inertia target moves by a. Fixed rows: identity, scale 0.
dataset::BlockSystem<float> assemble_system(const PhysicsInput<double>& in, const Hessian& h, const PhysicsSettings& s,
                                            const std::vector<uint8_t>& fixed) {
  const int64_t N = h.rows();
  const HessianPattern& pattern = *h.pattern;
  dataset::BlockSystem<float> out;
  out.offsets.reserve(static_cast<std::size_t>(N) + 1);
  out.offsets.push_back(0);
  out.scale.resize(static_cast<std::size_t>(N));
  for (int64_t v = 0; v < N; ++v) {
    for (int32_t k = pattern.offsets[v]; k < pattern.offsets[v + 1]; ++k) {
      const int32_t c = pattern.columns[k];
      if (fixed[v] ? c != v : fixed[c]) continue;
      out.columns.push_back(c);
      for (int e = 0; e < 9; ++e)
        out.blocks.push_back(fixed[v] ? (e % 4 == 0 ? 1.0f : 0.0f) : static_cast<float>(h.blocks[9 * static_cast<std::size_t>(k) + e]));
    }
    out.offsets.push_back(static_cast<int32_t>(out.columns.size()));
    out.scale[v] = fixed[v] ? 0.0f : static_cast<float>(2 * s.inertia * in.inertia_weight[v]);
  }
  return out;
}

// Conjugate gradients on H p = −g over the free rows (fixed rows stay 0), on the threads OpenMP
// offers outside a parallel region.
Vec solve(const Hessian& h, const Vec& g, const std::vector<uint8_t>& fixed, int iterations) {
  const int64_t N = h.rows();
  Vec r(3 * static_cast<std::size_t>(N));
  for (std::size_t k = 0; k < r.size(); ++k) r[k] = fixed[k / 3] ? 0.0 : -g[k];
  auto multiply = [&](const Vec& p, Vec& y, int64_t r0, int64_t r1) {
    h.multiply(p, y, r0, r1);
    for (int64_t v = r0; v < r1; ++v)
      if (fixed[v]) y[3 * v] = y[3 * v + 1] = y[3 * v + 2] = 0;
  };
  auto precondition = [&](const Vec& from, Vec& to, int64_t r0, int64_t r1) {
    for (int64_t v = r0; v < r1; ++v) {
      const Eigen::Vector3d y = h.preconditioner[v] * Eigen::Vector3d(from[3 * v], from[3 * v + 1], from[3 * v + 2]);
      for (int c = 0; c < 3; ++c) to[3 * v + c] = y[c];
    }
  };
  const double stop_ratio = 1e-8;  // a relative residual of 1e-4
  return ad::conjugate_gradients(std::move(r), multiply, precondition, iterations, stop_ratio, step_threads(N));
}

}  // namespace

dataset::Points minimise_step_energy(PhysicsInput<double> in, dataset::Points x0, const std::vector<uint8_t>& fixed,
                                     const PhysicsStepSettings& settings, PhysicsStepReport* report,
                                     dataset::BlockSystem<float>* system) {
  // Every energy evaluation and Hessian of the solve queries the same body; the friction holds
  // the contacts of the step's start.
  if (!in.body_index && !in.body_pos.empty()) index_body(in);
  const int64_t N = x0.rows();
  LAYERSNET_CHECK(static_cast<int64_t>(in.x_t.size()) == 3 * N && static_cast<int64_t>(fixed.size()) == N,
                  "minimise_step_energy: the guess has " << N << " rows, the input " << in.x_t.size() / 3
                                                         << " vertices and the fixed mask " << fixed.size());
  Vec x(3 * N);
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) x[3 * v + c] = x0(v, c);
  const PhysicsSettings& s = settings.energy;
  add_contact_friction(in, x0, settings.friction, settings.friction_distance);
  EnergyAt at;
  Vec g;
  double e = at.evaluate(in, x, s, settings.newton_iterations > 0);
  if (settings.newton_iterations > 0) at.gradient(g);
  ContactsAt contacts = at.take_contacts();  // at x, for its Hessian
  if (report) report->energy_start = e / std::max<int64_t>(N, 1), report->line_search_halvings = 0;
  const std::shared_ptr<const HessianPattern> pattern =
      settings.newton_iterations > 0 || system ? pattern_for(in, N) : nullptr;
  thread_local Hessian h;  // its buffers serve every Newton iteration of every step on this thread
  for (int it = 0; it < settings.newton_iterations; ++it) {
    fill_hessian(h, in, *pattern, x, s, fixed, contacts);
    const Vec p = solve(h, g, fixed, settings.cg_iterations);
    const double slope = dot(g, p);
    if (!(slope < 0)) break;  // at a minimum, or no descent direction
    // Backtracking (Armijo): the energy is piecewise (nearest contacts), so a full step may overshoot.
    // A trial is recorded for its gradient unless it is the last iteration's (which needs none).
    const bool next_needs_gradient = it + 1 < settings.newton_iterations;
    double alpha = 1;
    Vec trial(3 * N);
    double e_trial = 0;
    bool accepted = false;
    for (int halving = 0; halving < 12; ++halving, alpha *= 0.5) {
      for (int64_t k = 0; k < 3 * N; ++k) trial[k] = x[k] + alpha * p[k];
      e_trial = at.evaluate(in, trial, s, next_needs_gradient);
      if (e_trial <= e + 1e-4 * alpha * slope) {
        accepted = true;
        break;
      }
      if (report) ++report->line_search_halvings;
    }
    if (!accepted) break;
    x.swap(trial);
    e = e_trial;
    if (next_needs_gradient) at.gradient(g);
    contacts = at.take_contacts();
  }
  if (report) report->energy_end = e / std::max<int64_t>(N, 1);
  if (system) {
    fill_hessian(h, in, *pattern, x, s, fixed, contacts);
    *system = assemble_system(in, h, s, fixed);
  }
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) x0(v, c) = static_cast<float>(x[3 * v + c]);
  return x0;
}

dataset::Points physics_step_displacement(const dataset::TrainingSample& s, const dataset::SequenceInfo& info,
                                          const PhysicsStepSettings& settings, PhysicsStepReport* report,
                                          dataset::BlockSystem<float>* system) {
  const int64_t N = s.num_vertices();
  const bool body_inertia = settings.inertia == "body";
  LAYERSNET_CHECK(settings.inertia == "body" || settings.inertia == "world",
                  "physics step: inertia \"" << settings.inertia << "\" is neither \"body\" nor \"world\"");
  LAYERSNET_CHECK(s.body_carry.rows() == N && (!body_inertia || s.body_carry_prev.rows() == N),
                  "physics step of sample '" << s.sequence_id << "' frame " << s.frame
                                             << ": needs the body carry" << (body_inertia ? " from t-1 and from t" : "")
                                             << "; build the sample with model::sample_options_for(the model's config)");
  LAYERSNET_CHECK(settings.pins == "carried" || settings.pins == "recorded",
                  "physics step: pins \"" << settings.pins << "\" are neither \"carried\" nor \"recorded\"");
  const bool recorded_pins = settings.pins == "recorded" && info.pins_recorded;
  LAYERSNET_CHECK(!recorded_pins || s.target.rows() == N,
                  "physics step of sample '" << s.sequence_id << "' frame " << s.frame
                                             << ": recorded pins need the sample's frame t+1 (its target)");
  LAYERSNET_CHECK(settings.substeps >= 1, "physics step: " << settings.substeps << " substeps; give 1 or more");
  LAYERSNET_CHECK(!system || settings.substeps == 1,
                  "physics step: its linear system is made for one step per frame, not " << settings.substeps << " substeps");
  PhysicsInput<double> in = cast_physics_input<double>(physics_input_from_sample(s, info, settings.energy));
  if (!in.body_pos.empty()) index_body(in);
  // The input's frame is t+1's root, where the carried guess is x̃_t + c (x̃_t = state, root-relative).
  dataset::Points guess(N, 3);
  std::vector<uint8_t> fixed(N);
  for (int64_t v = 0; v < N; ++v) {
    fixed[v] = in.inertia_weight[v] == 0;  // pinned
    for (int c = 0; c < 3; ++c) {
      guess(v, c) = fixed[v] && recorded_pins ? s.target(v, c) : s.state(v, c) + s.body_carry(v, c);
      if (body_inertia)  // 2 x_t − x_{t−1} = x̃_t + c + (v_t − c_t)
        in.x_tm1[3 * v + c] = 2 * in.x_t[3 * v + c] - (guess(v, c) + s.state(v, 3 + c) - s.body_carry_prev(v, c));
    }
  }
  dataset::Points x;
  if (settings.substeps == 1) {
    x = minimise_step_energy(std::move(in), guess, fixed, settings, report, system);
  } else {
    // S implicit steps of h = 1/S frame. Each substep's energy times h² keeps the inertia term
    // (target x + h v) and scales every force's potential by h² and the drag's (c/2h)‖y − x‖² to
    // c h/2 ‖y − x‖². Each starts from its share of the body carry; pinned rows take that share.
    const double h = 1.0 / settings.substeps;
    PhysicsStepSettings sub = settings;
    sub.substeps = 1;
    PhysicsSettings& w = sub.energy;
    w.drag *= h;
    for (double* force : {&w.stretch, &w.bending, &w.gravity, &w.wind, &w.collision_body, &w.collision_layer}) *force *= h * h;
    std::vector<double> velocity(3 * N);  // units per frame
    for (int64_t k = 0; k < 3 * N; ++k) velocity[k] = in.x_t[k] - in.x_tm1[k];
    const std::vector<double> start = in.x_t;
    dataset::Points carried(N, 3);
    PhysicsStepReport part;
    if (report) *report = PhysicsStepReport{};
    for (int step = 0; step < settings.substeps; ++step) {
      for (int64_t v = 0; v < N; ++v)
        for (int c = 0; c < 3; ++c) {
          const int64_t k = 3 * v + c;
          in.x_tm1[k] = in.x_t[k] - h * velocity[k];
          carried(v, c) = static_cast<float>(in.x_t[k] + h * (guess(v, c) - start[k]));
        }
      x = minimise_step_energy(in, carried, fixed, sub, report ? &part : nullptr);
      if (report) {
        if (step == 0) report->energy_start = part.energy_start;
        report->energy_end = part.energy_end, report->line_search_halvings += part.line_search_halvings;
      }
      for (int64_t v = 0; v < N; ++v)
        for (int c = 0; c < 3; ++c) {
          const int64_t k = 3 * v + c;
          velocity[k] = (x(v, c) - in.x_t[k]) / h;
          in.x_t[k] = x(v, c);
        }
    }
  }
  dataset::Points displacement(N, 3);
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) displacement(v, c) = x(v, c) - s.state(v, c);
  return displacement;
}

PhysicsStepSettings physics_step_settings(const ModelConfig& model) {
  PhysicsStepSettings settings;
  settings.newton_iterations = model.physics_step_iterations;
  settings.cg_iterations = model.physics_step_cg_iterations;
  settings.substeps = model.physics_step_substeps;
  settings.inertia = model.physics_step_inertia;
  settings.pins = model.physics_step_pins;
  settings.energy.collision_stiffness = model.physics_step_collision_stiffness;
  settings.energy.collision_layer = model.physics_step_layer_collision ? model.physics_step_layer_stiffness : 0.0;
  settings.energy.layer_margin = model.physics_step_layer_margin;
  settings.friction = model.physics_step_friction;
  settings.friction_distance = model.physics_step_friction_distance;
  settings.energy.face_wind = model.physics_step_face_wind;
  settings.energy.bending = model.physics_step_bending;
  settings.energy.stretch = model.physics_step_stretch;
  settings.energy.bending_by_height = model.physics_step_bending_by_height;
  return settings;
}

void add_physics_step(dataset::TrainingSample& sample, const dataset::SequenceInfo& info, const ModelConfig& model) {
  if (model.velocity_base != "physics") return;
  const bool solved = model.physics_step_correction == "solved";
  sample.physics_step = physics_step_displacement(sample, info, physics_step_settings(model), nullptr,
                                                  solved ? &sample.physics_system : nullptr);
}

}  // namespace layersnet::losses
