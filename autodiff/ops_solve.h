#pragma once
// A linear solve on the tape: out = A⁻¹ (s ⊙ b), with A a symmetric positive-definite matrix of
// 3×3 blocks over N block rows (block CSR) and s a scale per block row. Conjugate gradients
// preconditioned by the inverse diagonal blocks, in double precision whatever T is, sequential
// (the result does not depend on the thread count). Backward solves with A again:
// db += s ⊙ A⁻¹ dout, since A is symmetric. A and s are constants (no gradient).
//
// A row that should not move (a pinned vertex) has an identity diagonal block, no other block
// in its row or column, and scale 0: its output row is 0.
#include "autodiff/tape.h"

#include <cstdint>
#include <span>

namespace layersnet::ad {

// A: BlockSpd (autodiff/op_params.h). b: (N, 3) -> (N, 3).
template <class T>
Var<T> block_spd_solve(Tape<T>& tape, const BlockSpd<T>& A, const Var<T>& b);

}  // namespace layersnet::ad
