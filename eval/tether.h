#pragma once
// Patch tether: a rollout constraint that keeps every predicted vertex near its own patch.
//
// Each step moves a vertex v that ended farther than L_v from c_v, the centre (mean, world)
// of the other members of its own patch p, back onto the sphere of radius L_v around c_v:
//   L_v = factor · ρ_p,  ρ_p = the largest such distance of a member of p in the rest shape
//   (the file's /garments/<name>/rest, else frame 0), at least the median over patches,
//   scene units.
// Why: cloth barely stretches, so a vertex never leaves its patch (the generated data stay
// within data_tether_ratio = 1.06–2.41 of ρ over 24 sequences); a learned step can, because
// the decoder's vertex branch integrates each vertex's offset to its patch from the previous
// output, and an offset it never saw feeds itself (single vertices running away; eval/README.md,
// "Stability at the extremes").
// The centre leaves v out, and the worst vertices are moved first with the centres kept
// current, so a runaway does not drag its patch mates. Only positions change: the next
// step's velocities are differences of positions, so the runaway velocity goes too (as in
// position-based dynamics). factor 0 = off (the default; official: no such step).
#include "dataset/patches.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"

#include <vector>

namespace layersnet::eval {

// (N,) L_v in layer order for the sequence's garments under `structure` (its patch size).
std::vector<float> tether_limits(const dataset::Sequence& seq, const dataset::SequenceStructure& structure,
                                 double factor);

// Projects x (N, 3, world) in place, worst first, in passes until none moves (at most 8);
// returns how many moves were made.
// Vertices whose own patch has no other member are never moved; non-finite rows stay as they are.
int apply_tether(const dataset::PatchStructure& patches, const std::vector<float>& limit, dataset::Points& x);

// Largest |x_v − c_v| / L_v over the vertices with mates and a limit (<= 1 after apply_tether).
double tether_ratio(const dataset::PatchStructure& patches, const std::vector<float>& limit, const dataset::Points& x);

// The data's own largest |x_v − c_v| / ρ_p over frames first..T−1 and vertices: the factor
// must stay above it (real cloth is never moved).
double data_tether_ratio(const dataset::Sequence& seq, const dataset::SequenceStructure& structure, int first);

}  // namespace layersnet::eval
