// Floating-point operation counts of the core's linear-algebra steps (householder.hpp,
// nested_qr.hpp) as their loops are written, by formula over the sizes a solve used: a
// multiply, an add, a divide or a square root is one operation; comparisons, copies and
// swaps are none. A dot product or a reflector update is counted in full (the kernels'
// skip of a zero reflector product, and of a reflector's trailing zeros (Reflectors::end),
// is not subtracted). The nested QR's count leaves out a
// full-rank attempt that fails and the trust-region step's SVD (bounded_step).
#pragma once

#include "prioik/householder.hpp"

namespace prioik {

// small_least_squares(L, rhs, m, r, mu2, …): damped (mu2 > 0), the QR of [L; √mu2 I] and no
// refinement; undamped, the QR of L, back substitution and one step of refinement.
double small_least_squares_flops(Index m, Index r, bool damped);

// full_rank_least_squares on m rows and d free columns that passed (all d pivots kept).
double full_rank_least_squares_flops(Index m, Index d);

// The nested QR's row-pivoted LQ of one level: m rows on d = n - col free columns, rank r,
// each reflector also applied to the `below` rows after the level (the lower levels'
// rows, rotated with it); with the level's right-hand side and row norms
// (level_rhs_and_norms).
double pivoted_lq_level_flops(Index m, Index n, Index col, Index r, Index below);

// Applying `count` reflectors at positions pos[0:count] to one vector of n entries.
double reflectors_flops(const Index* pos, Index count, Index n);

// The unit-rows step of a last level of m unit rows on n - col free coordinates, after
// `count` reflectors at pos (unit_rows_solve with nu = n - m uncovered columns).
double unit_rows_flops(Index m, Index n, Index col, const Index* pos, Index count);

}  // namespace prioik
