// The nested pivoted QR of Jeong & Chang's extended Jacobian (eq. 15-18, the QR reading
// of eq. 18), with prioik's selective damping and per-level step bound (trust region).
//
// Level by level, an LQ factorization with row pivoting of the level's rows restricted to
// the still-free coordinates (A_i Z_i in rotated coordinates) finds the level's rank r_i
// (pivot norm > rcond ‖A_i‖_F) and a Householder reflector per feasible direction. Each
// reflector is applied, from the right, to the rows of the levels below only, so the free
// coordinates of the next level are the trailing columns (Z_{i+1} implicitly). The
// level's feasible rows are then lower-trapezoidal L (eq. 26) and its unknowns follow by
// forward substitution, or by a small least squares when the level conflicts (r_i < m_i),
// optionally damped: selectively (μ² = λ_max (1 - (σ/ε)²) when the RRQR estimate σ of the
// level's smallest singular value is below ε = singular_threshold ‖A_i‖_F) and by the
// trust region ‖z_i‖ ≤ Δ_i (bounded_step). A level with m_i ≥ d free coordinates
// (undamped, unbounded) is first tried with one column-pivoted QR: with full column rank
// it is solved by it and leaves no null space. A last level of unit rows (a posture of
// uniform weight) is solved by the unit-rows step (householder.hpp) when it can be.
// Finally x = H_1 H_2 … H_R y.
#pragma once

#include <vector>

#include "prioik/householder.hpp"

namespace prioik {

// A rank decision whose margin (the smallest of kept pivot / threshold and threshold /
// largest rejected pivot) is at most this is ambiguous (hierarchy.linalg.AMBIGUITY).
constexpr double kAmbiguity = 1e3;
// ... and a clear one within this factor of kAmbiguity is near-ambiguous
// (hierarchy.linalg.NEAR_AMBIGUITY).
constexpr double kNearAmbiguity = 10.0;
// ‖x‖ beyond which float64 may limit a level's accuracy at the certificate's tolerance
// (hierarchy.linalg.PRECISION_LIMIT_NORM = 1e-8 / (16 ε)).
constexpr double kPrecisionLimitNorm = 1e-8 / (16.0 * 2.220446049250313e-16);

struct NestedQRParameters {
  double rcond = 1e-10;
  double level_damping = 0.0;        // λ_max of the selective damping (0: off)
  double singular_threshold = 0.0;   // ε of the selective damping (0: off)
  const double* step_bound = nullptr;  // k bounds Δ_i (0: unbounded); null: none
  // optional, M entries: row i's entries are zero but at column row_columns[i] when that
  // is ≥ 0 (the caller checked it; -1: not known); spares the unit-rows test its scan
  const Index* row_columns = nullptr;

  bool selective() const { return level_damping > 0.0 && singular_threshold > 0.0; }
};

// The scratch of nested_qr for M rows and n columns, allocated once (a prepared solver
// owns one); its contents between calls do not matter.
struct NestedQRWorkspace {
  NestedQRWorkspace() = default;
  NestedQRWorkspace(Index rows, Index cols);

  Index M = 0;
  Index n = 0;
  std::vector<double> V;        // n × n: reflector t in V(t, pos_t:)
  std::vector<double> beta;     // n
  std::vector<Index> pos;       // n
  std::vector<Index> end;       // n: one past each reflector's last non-zero entry
  std::vector<double> y;        // n: the rotated unknowns
  std::vector<double> norms;    // max(M, n): the level's row norms on the free columns
  std::vector<double> rhs;      // M: the level's right-hand side
  std::vector<double> L;        // M × n: a level's trapezoid; the unit-rows step's Zu and G
  std::vector<double> spare;    // the full-rank and least-squares steps' scratch
  std::vector<double> svd;      // bounded_step's scratch
  std::vector<Index> iscratch;  // n: the full-rank step's column permutation
  std::vector<Index> cover;     // n: the unit rows' columns
  std::vector<Index> ucols;     // n: the columns no unit row covers

  Reflectors reflectors(Index count) {
    return Reflectors{MatrixRef{V.data(), n, n, n}, beta.data(), pos.data(), count, end.data()};
  }
};

// Where nested_qr writes its answer: x (n), and per level (k) the rank r_i, the damping
// μ_i² (0 where the level is exact) and the rank decision's margin (inf when the level
// decided nothing). rowperm (optional, M entries) is permuted as the rows of B are.
struct NestedQROutput {
  double* x = nullptr;
  Index* ranks = nullptr;
  double* level_mu2 = nullptr;
  double* margins = nullptr;
  Index* rowperm = nullptr;
  double* flops = nullptr;    // the solve's floating-point operations (flops.hpp), when given
};

// Solve one stack in place: B (M × n) the weighted rows and c (M) the targets, both
// overwritten; starts (k + 1) the levels' row offsets; scales (k) ‖A_i‖_F. trust_region:
// whether the step bounds apply (else they must be zeros or null).
void nested_qr(MatrixRef B, double* c, const Index* starts, Index k, const double* scales,
               const NestedQRParameters& params, bool trust_region, NestedQRWorkspace& ws,
               const NestedQROutput& out);

// Trust-region least squares of one level: min ‖L z - rhs‖ s.t. ‖z‖ ≤ Δ for L[:m, :r] of
// full column rank: the smallest μ² ≥ mu2_min whose damped step (LᵀL + μ² I)⁻¹ Lᵀ rhs has
// ‖z‖ ≤ Δ (Newton on 1/‖z‖ - 1/Δ in the SVD basis, one-sided Jacobi SVD), z into z[:r];
// returns μ². Scratch: bounded_step_scratch(m, r) floats.
double bounded_step(MatrixRef L, const double* rhs, Index m, Index r, double mu2_min,
                    double step_bound, double* z, double* scratch);

inline Index bounded_step_scratch(Index m, Index r) { return r * m + r * r + 2 * r; }

}  // namespace prioik
