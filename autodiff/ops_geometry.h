#pragma once
// Geometry ops on the tape: per-row norms, 3-vector cross products (face normals), batched
// 3x3 rotations and the rotation map phi(R) = W R W^T of paper eq. 8-9.
//
// Dimension letters: N rows, C columns, d hidden width of a rotation map.
// A rotation is stored as one row of 9 numbers, the 3x3 matrix in row-major order:
// R: (N, 9) with R[n] = [r00 r01 r02 r10 r11 r12 r20 r21 r22].
#include "autodiff/tape.h"

#include <cstdint>
#include <span>

namespace layersnet::ad {

// out[n] = ||x[n, :]||_2.                                   x: (N, C) -> (N, 1)
// At a zero row the norm is not differentiable; the gradient there is 0 (the minimum-norm
// subgradient, as in PyTorch), so it stays finite.
template <class T>
Var<T> row_norm(Tape<T>& tape, const Var<T>& x);

// out[n, :] = x[n, :] / max(||x[n, :]||, eps).              x: (N, C) -> (N, C)
// The PyTorch F.normalize convention: rows shorter than eps are divided by eps instead,
// so a zero row maps to zero (the continuous extension), and the gradient there is g / eps
// (finite; rows that are exactly zero, like the normal of a zero-area triangle, get it).
template <class T>
Var<T> row_normalize(Tape<T>& tape, const Var<T>& x, T eps = T(1e-12));

// out[n] = a[n] x b[n].                                     a, b: (N, 3) -> (N, 3)
// Face normal (not normalised, length = twice the area) of triangle (v0, v1, v2) in the
// official convention: cross3(v2 - v1, v0 - v1).
template <class T>
Var<T> cross3(Tape<T>& tape, const Var<T>& a, const Var<T>& b);

// out[n] = R[n] v[n], or R[n]^T v[n] when `transpose`.   R: (N, 9), v: (N, 3) -> (N, 3)
// (world -> local with R from rotation_from_normals, local -> world with the transpose).
template <class T>
Var<T> rotate3(Tape<T>& tape, const Var<T>& R, const Var<T>& v, bool transpose = false);

// out[n] = W R[n] W^T v[n]   (or W R[n]^T W^T v[n] when `transpose`).
// W: (d, 3), R: (N, 9), v: (N, d) -> (N, d).
// The hidden-space rotation phi(R) = W R W^T of paper eq. 8 applied without forming the
// d x d matrix: t = W^T v (3), u = R t (3), out = W u. phi(R)^T = W R^T W^T, which is the
// `transpose` form (eq. 11 rotates back with phi(R)^T). Gradients to W, R and v.
template <class T>
Var<T> rot_map_apply(Tape<T>& tape, const Var<T>& W, const Var<T>& R, const Var<T>& v, bool transpose = false);

// Local frames from normals, the official utils/mesh3d.py rotation_from_normals:
//   x0 = (1, 0, 0), then x0_c = 1 for every component with |n_c| < 1e-7;
//   x = normalize(x0 - (n . x0) n);  y = n x x;  R = rows [x; y; n]  (world -> local, R n = e_z
//   for a unit n).
// n: (N, 3) as N*3 numbers; R: (N, 9) output as N*9 numbers. Not differentiable (data only).
// n is NOT normalised here (the official gravity frame uses a non-unit vector; quirk 2), so
// R is orthonormal only for unit n. Robustness: computed in double, so normals within 1e-7
// of an axis still give orthonormal rows in float; a zero normal (||n|| < 1e-12), where the
// official code returns a degenerate matrix, gives the identity.
template <class T>
void rotation_from_normals(std::span<const T> normals, std::span<T> rotations);

}  // namespace layersnet::ad
