#pragma once
// Cloth geometry ops on the tape: the mesh quantities the losses and the physics energy take of
// every predicted frame, each one op with a hand-written backward instead of a chain of gathers,
// cross products and normalisations (the physics step evaluates them three to five times a
// frame; docs/decisions.md, "The cloth energy's terms as single ops").
//
// x: (V, 3) positions. Index arrays hold rows of x. Energies are (1, 1), summed in double in a
// fixed order, so the result does not depend on the thread count.
#include "autodiff/tape.h"

#include <cstdint>
#include <span>

namespace layersnet::ad {

// Unit vertex normals: each face (v0, v1, v2) adds its unit normal (v2 − v1) × (v0 − v1) /
// |…| to its three corners, and each sum is normalised. Lengths below 1e-12 are divided by
// 1e-12 instead (row_normalize's convention): a zero-area face adds nothing, and a vertex in no
// face gets a zero normal.                                  x: (V, 3), faces: (F · 3) -> (V, 3)
template <class T>
Var<T> vertex_normals(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> faces);

// Σ_e half_k[e] (|x[i[e]] − x[j[e]]| − rest[e])²: springs of rest length `rest`. At a zero
// length the gradient of the length is 0 (row_norm's convention).
//                                                x: (V, 3), i, j, rest, half_k: (E) -> (1, 1)
template <class T>
Var<T> spring_energy(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> i, std::span<const int32_t> j,
                     std::span<const T> rest, std::span<const T> half_k);

// Σ_h k_cos[h] cos θ_h + k_sin[h] sin θ_h over hinges between face A = (i, j, a) and face B =
// (p, q, b) as wound, {p, q} = {i, j}: cos θ = n_A · n_B and sin θ = (n_A × n_B) · ê with the
// unit normals n_A ∝ (x_j − x_i) × (x_a − x_i), n_B ∝ (x_q − x_p) × (x_b − x_p) and ê ∝ x_i − x_j
// (normalised as vertex_normals' faces are). With k_cos = k cos θ0 and k_sin = k sin θ0 it is
// Σ k cos(θ − θ0): bending's energy is Σ k minus it.   x: (V, 3), indices and k: (H) -> (1, 1)
template <class T>
Var<T> dihedral_alignment(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> i, std::span<const int32_t> j,
                          std::span<const int32_t> a, std::span<const int32_t> p, std::span<const int32_t> q,
                          std::span<const int32_t> b, std::span<const T> k_cos, std::span<const T> k_sin);

}  // namespace layersnet::ad
