#pragma once
// Geometry ops on the tape: per-row norms, 3-vector cross products (face normals), batched
// 3x3 rotations and the rotation map phi(R) = W R W^T of paper eq. 8-9.
//
// Dimension letters: N rows, C columns, d hidden width of a rotation map.
// A rotation is stored as one row of 9 numbers, the 3x3 matrix in row-major order:
// R: (N, 9) with R[n] = [r00 r01 r02 r10 r11 r12 r20 r21 r22].
#include "autodiff/tape.h"

#include <cstdint>

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
// (world -> local with R of rows [x; y; n], local -> world with the transpose).
template <class T>
Var<T> rotate3(Tape<T>& tape, const Var<T>& R, const Var<T>& v, bool transpose = false);

// out[n] = W R[n] W^T v[n]   (or W R[n]^T W^T v[n] when `transpose`).
// W: (d, 3), R: (N, 9), v: (N, d) -> (N, d).
// The hidden-space rotation phi(R) = W R W^T of paper eq. 8 applied without forming the
// d x d matrix: t = W^T v (3), u = R t (3), out = W u. phi(R)^T = W R^T W^T, which is the
// `transpose` form (eq. 11 rotates back with phi(R)^T). Gradients to W, R and v.
template <class T>
Var<T> rot_map_apply(Tape<T>& tape, const Var<T>& W, const Var<T>& R, const Var<T>& v, bool transpose = false);

}  // namespace layersnet::ad
