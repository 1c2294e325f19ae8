#include "losses/physics.h"

#include "autodiff/ops_cloth.h"
#include "autodiff/ops_dense.h"
#include "autodiff/ops_geometry.h"
#include "autodiff/ops_graph.h"
#include "dataset/neighbours.h"
#include "dataset/wind.h"
#include "model/tape_helpers.h"


#include <algorithm>
#include <cmath>

namespace layersnet::losses {
namespace {

using ad::Var;

// Blender's vertex-group scaled setting: base + w·|max − base| (the absolute value is Blender's).
double group_scaled(double base, double max, double weight) { return base + weight * std::fabs(max - base); }

template <class T>
Var<T> column(ad::Tape<T>& tape, const std::vector<T>& v, int64_t cols) {
  return model::constant(tape, v, static_cast<int64_t>(v.size()) / cols, cols);
}

// Σ_rows weight_r · value_r for (R, 1) tensors.
template <class T>
Var<T> weighted_sum(ad::Tape<T>& tape, const Var<T>& value, const std::vector<T>& weight) {
  return ad::sum_all(tape, ad::mul(tape, value, column(tape, weight, 1)));
}

template <class T>
Var<T> collision(ad::Tape<T>& tape, const Var<T>& x, const Var<T>& anchor, const Var<T>& normal, double margin,
                 double stiffness, int64_t* contacts) {
  const Var<T> d = ad::row_sum(tape, ad::mul(tape, ad::sub(tape, x, anchor), normal));  // (Q, 1)
  const Var<T> pen = ad::hinge_sq(tape, d, static_cast<T>(margin));
  if (contacts) {
    *contacts = 0;
    for (int64_t i = 0; i < pen.rows; ++i) *contacts += pen.value[i] > T(0);
  }
  return ad::scale(tape, ad::sum_all(tape, pen), static_cast<T>(stiffness / 2));
}

// Nearest anchor rows (indices) of the query rows, on current values.
template <class T>
std::vector<int32_t> nearest(const T* query, int64_t q0, int64_t q1, const T* anchors, int64_t a0, int64_t a1) {
  return dataset::nearest_body(rows_as_points(query, q0, q1), rows_as_points(anchors, a0, a1)).index;
}

}  // namespace

double ramped(double start, double end, int64_t step, int64_t ramp_start, int64_t ramp_steps) {
  if (step < ramp_start) return start;
  if (ramp_steps <= 0) return end;
  const double f = std::min(1.0, static_cast<double>(step - ramp_start) / static_cast<double>(ramp_steps));
  return start + f * (end - start);
}

PhysicsInput<float> physics_input_from_sample(const dataset::TrainingSample& s, const dataset::SequenceInfo& info,
                                              const PhysicsSettings& settings) {
  LAYERSNET_CHECK(s.structure != nullptr && static_cast<int>(s.structure->vertex_offsets.size()) == info.num_garments() + 1,
                  "physics_input_from_sample: sample '" << s.sequence_id << "' does not match the SequenceInfo's garments");
  const auto& offsets = s.structure->vertex_offsets;
  const int G = info.num_garments();
  const int64_t N = s.num_vertices(), B = s.body_state.rows();
  const int t = s.frame;
  PhysicsInput<float> in;
  in.garment_offsets = offsets;
  in.structure = s.structure;
  // x_t and x_{t−1} in frame t+1's root coordinates: x̃_f + r_f − r_{t+1}.
  const Eigen::Vector3f shift_t = (info.translation.row(t) - info.translation.row(t + 1)).transpose();
  const Eigen::Vector3f shift_tm1 = (info.translation.row(t - 1) - info.translation.row(t + 1)).transpose();
  in.x_t.resize(N * 3), in.x_tm1.resize(N * 3);
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) {
      const float xt = s.state(v, c), vt = s.state(v, 3 + c);  // x̃_t, v_t = x̃_t − x̃_{t−1}
      in.x_t[3 * v + c] = xt + shift_t[c];
      in.x_tm1[3 * v + c] = xt - vt + shift_tm1[c];
    }
  // Per-vertex mass, drag and gravity; pinned vertices follow the body instead.
  const Eigen::Vector3d g = 1e-3 * info.gravity.cast<double>();
  const double drag = settings.air_damping * 0.01;
  in.inertia_weight.assign(N, 0.f), in.drag_weight.assign(N, 0.f), in.external_force.assign(N * 3, 0.f);
  for (int k = 0; k < G; ++k) {
    const auto& mesh = info.garments[k];
    for (int v = 0; v < mesh.num_vertices; ++v) {
      if (mesh.pinned(v)) continue;
      const int64_t gv = offsets[k] + v;
      in.inertia_weight[gv] = static_cast<float>(mesh.attributes.mass / 2.0);
      in.drag_weight[gv] = static_cast<float>(drag / 2);
      for (int c = 0; c < 3; ++c) in.external_force[3 * gv + c] = static_cast<float>(mesh.attributes.mass * g[c]);
    }
  }
  // The stiffness Blender simulated each layer with (SequenceInfo::stiffness_per_layer).
  std::vector<double> layer_tension(G), layer_bending(G);
  for (int k = 0; k < G; ++k) {
    const auto& inner = info.garments.front().attributes;
    const auto& own = info.garments[k].attributes;
    const double outer_group = (G >= 2 && k == G - 1) ? 1.0 : 0.0;
    layer_tension[k] = info.stiffness_per_layer
                           ? own.tension_stiffness
                           : group_scaled(inner.tension_stiffness, info.garments.back().attributes.tension_stiffness, outer_group);
    layer_bending[k] = info.stiffness_per_layer
                           ? own.bending_stiffness
                           : group_scaled(inner.bending_stiffness, info.garments.back().attributes.bending_stiffness, outer_group);
  }
  // Structural springs: every mesh edge; the average rest length over the whole cloth object (all
  // layers: the generator makes one) sets Blender's stiffness scale.
  const auto& edges = s.structure->edges;
  double avg = 0;
  for (const auto& e : edges) avg += e.rest_length;
  avg = edges.empty() ? 1.0 : avg / static_cast<double>(edges.size());
  constexpr double kFltEpsilon = 1.1920929e-7;  // Blender adds FLT_EPSILON to the average
  const std::size_t E = edges.size(), H = s.structure->hinges.size();
  in.edge_i.reserve(E), in.edge_j.reserve(E), in.edge_rest.reserve(E), in.edge_half_k.reserve(E);
  for (const auto& e : edges) {
    in.edge_i.push_back(e.i), in.edge_j.push_back(e.j);
    in.edge_rest.push_back(static_cast<float>(e.rest_length));
    in.edge_half_k.push_back(static_cast<float>(layer_tension[e.garment] / (avg + kFltEpsilon) / 2));
  }
  for (auto* v : {&in.hinge_i, &in.hinge_j, &in.hinge_a, &in.hinge_p, &in.hinge_q, &in.hinge_b}) v->reserve(H);
  in.hinge_k_cos0.reserve(H), in.hinge_k_sin0.reserve(H);
  for (const auto& h : s.structure->hinges) {
    const double k = layer_bending[h.garment] * h.rest_length * 0.1 * (settings.bending_by_height ? h.rest_height : 1.0);
    in.hinge_i.push_back(h.i), in.hinge_j.push_back(h.j), in.hinge_a.push_back(h.a);
    in.hinge_p.push_back(h.p), in.hinge_q.push_back(h.q), in.hinge_b.push_back(h.b);
    in.hinge_k_cos0.push_back(static_cast<float>(k * h.cos0));
    in.hinge_k_sin0.push_back(static_cast<float>(k * h.sin0));
    in.hinge_k_sum += k;
  }
  in.faces = s.structure->faces;
  // Face wind at x_t: the effector gives each vertex w = field strength (stored strength × the
  // file's wind_field_factor) × the field's z axis / fps, and each face face_wind × area / 3 times
  // (w·n) n to each corner.
  in.wind_force.assign(N * 3, 0.f);
  if (info.has_wind && info.wind_strength[t + 1] != 0.f) {
    const Eigen::Vector3d w =
        settings.face_wind / static_cast<double>(info.fps) * static_cast<double>(info.wind_strength[t + 1]) *
        static_cast<double>(info.wind_field_factor) *
        dataset::wind_direction(info.wind_rotation.row(t + 1).transpose()).cast<double>();
    const dataset::Points force = dataset::face_wind_force(s.state.leftCols<3>(), in.faces, w);
    for (int k = 0; k < G; ++k)
      for (int v = 0; v < info.garments[k].num_vertices; ++v) {
        if (info.garments[k].pinned(v)) continue;
        const int64_t gv = offsets[k] + v;
        for (int d = 0; d < 3; ++d) in.wind_force[3 * gv + d] = force(gv, d);
      }
  }
  in.body_pos.resize(B * 3), in.body_normals.resize(B * 3);
  for (int64_t b = 0; b < B; ++b)
    for (int c = 0; c < 3; ++c) in.body_pos[3 * b + c] = s.body_state(b, c), in.body_normals[3 * b + c] = s.body_normals_next(b, c);
  return in;
}

template <class T>
Var<T> inertia_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in) {
  std::vector<T> target(in.x_t.size());
  for (std::size_t k = 0; k < target.size(); ++k) target[k] = 2 * in.x_t[k] - in.x_tm1[k];
  return weighted_sum(tape, ad::squared_error(tape, x, column(tape, target, 3)), in.inertia_weight);
}

template <class T>
Var<T> drag_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in) {
  return weighted_sum(tape, ad::squared_error(tape, x, column(tape, in.x_t, 3)), in.drag_weight);
}

template <class T>
Var<T> stretch_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in) {
  return ad::spring_energy<T>(tape, x, in.edge_i, in.edge_j, in.edge_rest, in.edge_half_k);
}

template <class T>
Var<T> bending_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in) {
  // Σ k (1 − cos(θ − θ0)) = Σ k − Σ k cos(θ − θ0).
  const Var<T> aligned = ad::dihedral_alignment<T>(tape, x, in.hinge_i, in.hinge_j, in.hinge_a, in.hinge_p, in.hinge_q,
                                                   in.hinge_b, in.hinge_k_cos0, in.hinge_k_sin0);
  const T k_sum = static_cast<T>(in.hinge_k_sum);
  return ad::sub(tape, tape.constant(&k_sum, 1, 1), aligned);
}

template <class T>
Var<T> work_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in, const std::vector<T>& force) {
  const Var<T> dx = ad::sub(tape, x, column(tape, in.x_t, 3));
  return ad::scale(tape, ad::sum_all(tape, ad::mul(tape, dx, column(tape, force, 3))), T(-1));
}

template <class T>
Var<T> body_collision_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in, double margin,
                             double stiffness, int64_t* contacts, std::vector<int32_t>* nearest_out) {
  const int64_t B = static_cast<int64_t>(in.body_pos.size() / 3);
  const auto idx = in.body_index ? in.body_index->query(rows_as_points(x.value, 0, x.rows)).index
                                 : nearest(x.value, 0, x.rows, in.body_pos.data(), 0, B);
  const Var<T> h = ad::gather_rows(tape, column(tape, in.body_pos, 3), idx);
  const Var<T> n = ad::gather_rows(tape, column(tape, in.body_normals, 3), idx);
  if (nearest_out) *nearest_out = idx;
  return collision(tape, x, h, n, margin, stiffness, contacts);
}

template <class T>
Var<T> layer_collision_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in, double margin,
                              double stiffness, int64_t* contacts, std::vector<int32_t>* nearest_out,
                              std::vector<T>* normal_out) {
  const int64_t G = static_cast<int64_t>(in.garment_offsets.size()) - 1;
  LAYERSNET_CHECK(G >= 2, "layer_collision_energy needs two garments or more (has " << G << ")");
  const int64_t o0 = in.garment_offsets[G - 1], o1 = in.garment_offsets[G];
  // Indices into the inner vertices [0, o0) are global vertex ids.
  const auto idx = nearest(x.value, o0, o1, x.value, 0, o0);
  // Inner normals from the inner garments' faces only (the outer's faces are not their neighbours).
  std::vector<int32_t> inner_faces;
  for (std::size_t f = 0; f < in.faces.size() / 3; ++f)
    if (in.faces[3 * f] < o0) inner_faces.insert(inner_faces.end(), in.faces.begin() + 3 * f, in.faces.begin() + 3 * f + 3);
  const Var<T> inner = model::rows_of(x, 0, o0);
  const Var<T> normals = ad::vertex_normals<T>(tape, inner, inner_faces);
  const Var<T> normal = ad::gather_rows(tape, normals, idx);
  if (nearest_out) *nearest_out = idx;
  if (normal_out) normal_out->assign(normal.value, normal.value + 3 * normal.rows);
  return collision(tape, model::rows_of(x, o0, o1), ad::gather_rows(tape, inner, idx), normal, margin, stiffness, contacts);
}

template <class T>
void add_contact_friction(PhysicsInput<T>& in, const dataset::Points& start, double mu, double distance) {
  in.friction_rows.clear(), in.friction_anchor.clear(), in.friction_normal.clear(), in.friction_half_weight.clear();
  const int64_t N = start.rows();
  LAYERSNET_CHECK(static_cast<int64_t>(in.inertia_weight.size()) == N,
                  "add_contact_friction: the start has " << N << " rows, the input " << in.inertia_weight.size() << " vertices");
  if (!(mu > 0) || in.body_pos.empty()) return;
  const auto nearest_body = in.body_index ? in.body_index->query(start).index
                                          : dataset::nearest_body(start, rows_as_points(in.body_pos.data(), 0,
                                                                  static_cast<int64_t>(in.body_pos.size() / 3))).index;
  for (int64_t v = 0; v < N; ++v) {
    if (!(in.inertia_weight[v] > 0)) continue;  // pinned: moves with the body anyway
    const Eigen::Vector3d x0 = start.row(v).transpose().cast<double>();
    const auto [n, r] = offset_from_body(in, nearest_body[v], x0);
    const Eigen::Vector3d unit = n.normalized();
    if (r.dot(unit) >= distance || r.norm() > 2 * distance) continue;
    in.friction_rows.push_back(static_cast<int32_t>(v));
    for (int c = 0; c < 3; ++c)
      in.friction_anchor.push_back(static_cast<T>(x0[c])), in.friction_normal.push_back(static_cast<T>(unit[c]));
    in.friction_half_weight.push_back(static_cast<T>(mu * in.inertia_weight[v]));
  }
}

template <class T>
Var<T> friction_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in) {
  // ‖P d‖² = ‖d‖² − (n·d)² for a unit n.
  const Var<T> d = ad::sub(tape, ad::gather_rows(tape, x, in.friction_rows), column(tape, in.friction_anchor, 3));
  const Var<T> along = ad::row_sum(tape, ad::mul(tape, d, column(tape, in.friction_normal, 3)));
  const Var<T> slip2 = ad::sub(tape, ad::row_sum(tape, ad::mul(tape, d, d)), ad::mul(tape, along, along));
  return weighted_sum(tape, slip2, in.friction_half_weight);
}

template <class T>
PhysicsTerms<T> physics_energy(ad::Tape<T>& tape, const Var<T>& x, const PhysicsInput<T>& in, const PhysicsSettings& ps) {
  const int64_t N = x.rows;
  LAYERSNET_CHECK(x.cols == 3 && static_cast<int64_t>(in.x_t.size()) == 3 * N,
                  "physics_energy: x (" << x.rows << ", " << x.cols << ") does not match the input's " << in.x_t.size() / 3
                                        << " vertices");
  PhysicsTerms<T> out;
  std::vector<Var<T>> weighted;
  const T per_vertex = T(1) / static_cast<T>(std::max<int64_t>(N, 1));
  auto add = [&](double weight, double& value, auto make) {
    if (weight == 0) return;
    const Var<T> term = ad::scale(tape, make(), per_vertex);
    value = static_cast<double>(term.scalar());
    weighted.push_back(ad::scale(tape, term, static_cast<T>(weight)));
  };
  add(ps.inertia, out.inertia, [&] { return inertia_energy(tape, x, in); });
  add(ps.drag, out.drag, [&] { return drag_energy(tape, x, in); });
  if (!in.edge_i.empty()) add(ps.stretch, out.stretch, [&] { return stretch_energy(tape, x, in); });
  if (!in.hinge_i.empty()) add(ps.bending, out.bending, [&] { return bending_energy(tape, x, in); });
  add(ps.gravity, out.gravity, [&] { return work_energy(tape, x, in, in.external_force); });
  add(ps.wind, out.wind, [&] { return work_energy(tape, x, in, in.wind_force); });
  if (!in.body_pos.empty())
    add(ps.collision_body, out.collision_body,
        [&] {
          return body_collision_energy(tape, x, in, ps.body_margin, ps.collision_stiffness, &out.body_contacts,
                                       &out.body_nearest);
        });
  if (in.garment_offsets.size() >= 3)
    add(ps.collision_layer, out.collision_layer,
        [&] {
          return layer_collision_energy(tape, x, in, ps.layer_margin, ps.collision_stiffness, &out.layer_contacts,
                                        &out.layer_nearest, &out.layer_normal);
        });
  if (!in.friction_rows.empty()) add(ps.friction, out.friction, [&] { return friction_energy(tape, x, in); });
  LAYERSNET_CHECK(!weighted.empty(), "physics_energy: every term's weight is 0");
  out.total = weighted[0];
  for (std::size_t k = 1; k < weighted.size(); ++k) out.total = ad::add(tape, out.total, weighted[k]);
  return out;
}

#define LAYERSNET_PHYSICS_INSTANTIATE(T)                                                                              \
  template Var<T> inertia_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&);                                \
  template Var<T> drag_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&);                                   \
  template Var<T> stretch_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&);                                \
  template Var<T> bending_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&);                                \
  template Var<T> work_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&, const std::vector<T>&);            \
  template Var<T> body_collision_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&, double, double, int64_t*,    \
                                        std::vector<int32_t>*);                                                      \
  template Var<T> layer_collision_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&, double, double, int64_t*,   \
                                         std::vector<int32_t>*, std::vector<T>*);                                    \
  template Var<T> friction_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&);                               \
  template void add_contact_friction(PhysicsInput<T>&, const dataset::Points&, double, double);                      \
  template PhysicsTerms<T> physics_energy(ad::Tape<T>&, const Var<T>&, const PhysicsInput<T>&, const PhysicsSettings&);
LAYERSNET_PHYSICS_INSTANTIATE(float)
LAYERSNET_PHYSICS_INSTANTIATE(double)
#undef LAYERSNET_PHYSICS_INSTANTIATE

}  // namespace layersnet::losses
