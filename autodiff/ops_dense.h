#pragma once
// Dense ops on the tape. Shapes: N rows, C columns. Each op has plain kernels
// (`*_forward` / `*_backward`, no tape, no allocation) and a wrapper that records a node.
#include "autodiff/tape.h"

namespace layersnet::ad {

// out = a + b. a: (N, C); b: (N, C), (1, C) [row broadcast], (N, 1) or (1, 1).
template <class T>
Var<T> add(Tape<T>& tape, const Var<T>& a, const Var<T>& b);

}  // namespace layersnet::ad
