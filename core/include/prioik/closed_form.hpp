// The closed-form formulations beside the extended Jacobian, compiled alike: each a
// prepared solver over one workspace allocated at construction (nothing allocated per
// solve), on householder.hpp's primitives, with the core's rank rule (a pivot of the
// row-pivoted LQ counts when its norm exceeds rcond times the level's scale — ‖A_i‖_F,
// or ‖A_i M⁻¹‖_F and ‖A_i L⁻ᵀ‖_F where the readable paths use those — the RRQR estimate
// of the singular value they test; ReferenceSolver, the nested-SVD reference, tests the
// singular values themselves) and its rounding rule (core/CMakeLists.txt).
// Each solve counts its floating-point operations (a multiply, an add, a divide or a
// square root is one; comparisons and copies are none) in its result's `flops`.
//
// Recursive null-space projection (Nakamura 1987; Siciliano & Slotine 1991), for each
// level i with x_0 = 0 and N_0 = I:
//     Ĵ_i = A_i N_{i-1},   x_i = x_{i-1} + N_{i-1} Ĵ_i^# (b_i − A_i x_{i-1}),
//     N_i = N_{i-1} − V_i V_iᵀ   (V_i: an orthonormal basis of Ĵ_i's kept row space,
//                                 re-orthonormalised inside range(N_{i-1}))
// Ĵ_i^# is the truncated pseudo-inverse (damping 0) or Ĵᵀ(ĴĴᵀ + λI)⁻¹ on the kept
// directions (damping λ). Ĵ_i comes from a row-pivoted LQ (Householder reflectors from
// the right): Ĵ_i = Pᵀ [L 0] Q, Ĵ^# e = Q_rᵀ argmin ‖L z − P e‖² + λ ‖z‖², V_i = Q_rᵀ.
//
// One thread at a time per solver (a second concurrent call throws ConcurrentUse).
#pragma once

#include <atomic>
#include <vector>

#include "prioik/extended_jacobian.hpp"
#include "prioik/flops.hpp"

namespace prioik {

struct NullspaceOptions {
  double rcond = 1e-9;
  double damping = 0.0;     // λ of the damped inverse (0: pseudo-inverse)
  bool reproject = true;    // multiply each step by N_{i-1} once more (exact no-op)
};

// What every compiled closed form's answer holds, read by name (each result adds its own).
struct ProjectionResult {
  std::vector<double> x;            // n
  std::vector<double> residuals;    // k: ‖√w ∘ (A_i x − b_i)‖
  double flops = 0.0;               // floating-point operations of the solve
  bool solved = false;       // false: a level's scale is outside [1e-100, 1e100] (the
                             // caller equilibrates), or as the result says; nothing solved
  bool finite = false;       // the residuals (and so x) are finite
};

// The answer of one null-space projection solve.
struct NullspaceResult : ProjectionResult {
  std::vector<double> min_pivots;   // k: the smallest kept pivot norm of Ĵ_i (0: none)
  std::vector<double> margins;      // k: the rank decisions' margins (inf: none decided)
  std::vector<Index> ranks;         // k: the kept rank of Ĵ_i
  bool ambiguous = false;    // some level's margin ≤ kAmbiguity
};

// What one solve of a projector recursion (nullspace, chiaverini) works in, allocated at
// prepare: the weighted rows, the projector N, one level's LQ and the step's scratch.
struct ProjectionWorkspace {
  ProjectionWorkspace() = default;
  ProjectionWorkspace(Index M, Index n, Index k, Index m_max);

  std::vector<double> B;        // M × n: diag(√w) A
  std::vector<double> c;        // M: √w ∘ b
  std::vector<double> scales;   // k: ‖A_i‖_F of the weighted rows
  std::vector<double> N;        // n × n: the projector N_{i-1} (symmetric, held whole)
  std::vector<double> J;        // m_max × n: Ĵ_i (or A_i), then its LQ's [L 0]
  std::vector<double> e;        // m_max: the level's right-hand side, permuted as J's rows
  std::vector<double> norms;    // m_max: J's rows' squared norms on the trailing columns
  std::vector<double> V;        // n × n: reflector t in V(t, t:)
  std::vector<double> beta;     // n
  std::vector<Index> pos;       // n
  std::vector<double> basis;    // n × n: row l = V_i's column l (orthonormalised)
  std::vector<double> step;     // n
  std::vector<double> aux;      // n
  std::vector<double> L;        // m_max × n: the least squares' matrix
  std::vector<double> spare;    // small_least_squares' scratch
  std::vector<double> chol;     // n × n: the mass matrix's Cholesky factor (unifying)
  std::vector<double> left;     // n × n: M⁻¹ V (unifying)
  std::vector<double> right;    // n × n: M V (unifying)
  bool projected = false;       // some level has updated N (else N = I)
};

// What every compiled closed form holds: the layout (the k + 1 row offsets `starts` of
// the levels, n columns), its ProjectionWorkspace allocated at construction, and the
// one-thread-at-a-time flag; and the frame of a solve, around the formulation's level
// step. The constructor throws InputError on a malformed layout, rcond outside (0, 1) or
// a damping not finite and ≥ 0.
class ProjectionSolver {
 public:
  virtual ~ProjectionSolver() = default;

  Index rows() const { return M_; }
  Index cols() const { return n_; }
  Index levels() const { return k_; }

 protected:
  ProjectionSolver(std::vector<Index> starts, Index n, double rcond, double damping);

  // The opening of a solve: x = 0, flops = 0, solved and finite false; the stack weighed
  // into the workspace (ws.B = diag(√w) A, ws.c = √w ∘ b, the levels' scales) and N = I.
  // Throws InputError naming a NaN, inf or √w ≤ 0 (check_stack_entries); returns whether
  // every level's scale is in [1e-100, 1e100] (else there is nothing to solve).
  bool open_solve(const StackArrays& data, ProjectionResult& res);
  // The formulation's levels first, …, k − 1 in turn; returns their flops
  double run_levels(Index first);
  // Level lev's rows s0, …, s0 + m − 1 on the workspace: their weighted rows B (ws.B),
  // the matrix the level factors J (ws.J, m × n) and the LQ's reflectors H (none yet)
  struct Level {
    Index s0, m;
    MatrixRef B, J;
    Reflectors H;
  };
  Level level(Index lev);
  // Null-space projection's step of a level at x: J = A_i N, e = b_i − A_i x and, when
  // tol > 0, x += N J^# e (x += J^# e when !reproject) by projection::lq_step, which
  // writes the rank, the smallest kept pivot and the margin; returns the flops
  double projected_step(Level& lv, double tol, double damping, bool reproject, double* x,
                        Index* rank, double* min_pivot, double* margin);
  // level lev's step (and, unless last, its projector update) on the workspace; returns
  // the level's flops
  virtual double solve_level(Index lev, bool last) = 0;
  // The close of a solve: res.flops = flops, and the levels' residuals at x and whether
  // they are finite
  void close_solve(const StackArrays& data, double flops, ProjectionResult& res) const;

  std::vector<Index> starts_;
  Index M_, n_, k_;
  ProjectionWorkspace work_;
  std::atomic<bool> busy_{false};
};

class NullspaceSolver final : public ProjectionSolver {
 public:
  // starts: the k + 1 row offsets of the levels; n: the columns. Throws InputError on a
  // malformed layout or options.
  NullspaceSolver(std::vector<Index> starts, Index n, NullspaceOptions options);

  // Solve one stack of the layout; the result is this solver's, overwritten by the next
  // solve. Throws InputError naming the array of a non-finite entry or a √w ≤ 0.
  const NullspaceResult& solve(const StackArrays& data);

  const NullspaceResult& result() const { return result_; }
  const NullspaceOptions& options() const { return options_; }

 private:
  double solve_level(Index lev, bool last) override;

  NullspaceOptions options_;
  NullspaceResult result_;
};

// Chiaverini's singularity-robust task priority in its k-level form (Chiaverini 1997):
//     x = Σ_i N^A_{i-1} A_i^# b_i,   N^A_{i-1} the projector onto null(J_{i-1}^A)
// A_i^# (the level's own pseudo-inverse, or A_iᵀ(A_i A_iᵀ + λI)⁻¹ on the kept directions)
// from a row-pivoted LQ of A_i; N^A_i updated as NullspaceSolver's N_i (the same
// projector: a basis of A_i N^A_{i-1}'s kept row space, re-orthonormalised).
struct ChiaveriniOptions {
  double rcond = 1e-9;
  double damping = 0.0;     // λ of the damped inverse (0: pseudo-inverse)
};

struct ChiaveriniResult : ProjectionResult {
  std::vector<double> task_solutions;  // k × n: row i = A_i^# b_i, the level's own solution
};

class ChiaveriniSolver final : public ProjectionSolver {
 public:
  ChiaveriniSolver(std::vector<Index> starts, Index n, ChiaveriniOptions options);

  // Solve one stack of the layout (as NullspaceSolver::solve).
  const ChiaveriniResult& solve(const StackArrays& data);

  const ChiaveriniResult& result() const { return result_; }

 private:
  double solve_level(Index lev, bool last) override;

  ChiaveriniOptions options_;
  ChiaveriniResult result_;
};

// The unifying framework of Peters et al. (2008) in the reading of Jeong & Chang (2009),
// eq. 40, with the joint-space inertia M = L Lᵀ given per solve:
//     x = Σ_i N_i J_i^{M²+} b_i,   J^{M²+} = M⁻¹ (A M⁻¹)⁺,
//     N_1 = I,   N_{i+1} = N_i (I − J_i^{M²+} A_i) = N_i − (N_i M⁻¹ V)(M V)ᵀ
// (B = A M⁻¹ = Pᵀ [L_B 0] Q by a row-pivoted LQ, rank rule rcond ‖B‖_F; B⁺ y =
// Q_rᵀ argmin ‖L_B z − P y‖ and J^{M²+} A = M⁻¹ B⁺ B M = M⁻¹ V Vᵀ M with V = Q_rᵀ).
// The answer of a solve with a mass matrix (unifying, operational_space), read by name.
// solved is also false when M is not positive definite (mass_positive_definite).
struct UnifyingResult : ProjectionResult {
  std::vector<Index> ranks;         // k: the kept rank of each level's factored matrix
  bool mass_positive_definite = false;   // the Cholesky factorization of M succeeded
};

// A solver with the joint-space inertia M = L Lᵀ given per solve (unifying,
// operational_space): one solve factors M, then runs over the levels the mass-matrix
// weighted level step, for each level i (x_0 = 0, N_0 = I):
//     J_i = the level's rows in M's weighting (level_rows), its rank rule rcond ‖·‖_F,
//     J_i = Pᵀ [L_J 0] Q (row-pivoted LQ),   z = Q_rᵀ argmin ‖L_J z − P e‖,
//     x_i = x_{i-1} + N_{i-1} (map_step z),   N_i = N_{i-1} − Σ_{l<r} p_l q_lᵀ
// with (p_l, q_l) = projector_factors(Q e_l); the derived solver gives the three parts.
class MassMatrixSolver : public ProjectionSolver {
 public:
  // Solve one stack of the layout with the joint-space inertia M (n × n, row-major; its
  // lower triangle is read). Throws InputError naming a non-finite entry, a √w ≤ 0 or a
  // non-finite entry of M.
  const UnifyingResult& solve(const StackArrays& data, const double* mass_matrix);

  const UnifyingResult& result() const { return result_; }

 protected:
  // reproject: x_i = x_{i-1} + N_{i-1} (map_step z) (else + map_step z, when J_i holds N_{i-1})
  MassMatrixSolver(std::vector<Index> starts, Index n, double rcond, bool reproject);

  // M's lower Cholesky factor L (ws.chol) and the projector N (ws.N)
  MatrixRef mass_factor() { return MatrixRef{work_.chol.data(), n_, n_, n_}; }
  MatrixRef projector() { return MatrixRef{work_.N.data(), n_, n_, n_}; }

  // The level's matrix lv.J from its rows lv.B, and its right-hand side (ws.e); adds the
  // squared scale of the rank rule to *scale2; returns the flops
  virtual double level_rows(const Level& lv, double* scale2) = 0;
  // the step in x from the step z of J's LQ, in place; returns the flops
  virtual double map_step(double* z) = 0;
  // the pair (p, q) of the projector update N ← N − p qᵀ for v = Q e_l; returns the flops
  virtual double projector_factors(const double* v, double* p, double* q) = 0;

  UnifyingResult result_;     // x, residuals, ranks of the factored matrices, flops, flags

 private:
  double solve_level(Index lev, bool last) final;

  double rcond_;
  bool reproject_;
};

class UnifyingSolver final : public MassMatrixSolver {
 public:
  UnifyingSolver(std::vector<Index> starts, Index n, double rcond);

 private:
  // J = A_i M⁻¹ (row j: M⁻¹ a_j, M symmetric), e = b_i
  double level_rows(const Level& lv, double* scale2) override;
  // z ← M⁻¹ z
  double map_step(double* z) override;
  // p = N_i M⁻¹ v, q = M v
  double projector_factors(const double* v, double* p, double* q) override;
};

// Prioritized operational-space control (Khatib 1987; Sentis & Khatib 2005) with the
// joint-space inertia M = L Lᵀ given per solve, for each level (x_0 = 0, N_0 = I):
//     J_{i|prev} = A_i N_{i-1},  B = J_{i|prev} L⁻ᵀ = Pᵀ [L_B 0] Q (row-pivoted LQ, rank
//     rule rcond ‖A_i L⁻ᵀ‖_F),  J̄ = L⁻ᵀ B⁺,
//     x_i = x_{i-1} + N_{i-1} J̄ (b_i − A_i x_{i-1}),  N_i = N_{i-1} − (L⁻ᵀ V)(L V)ᵀ
// (J̄ J_{i|prev} = L⁻ᵀ B⁺ B Lᵀ = L⁻ᵀ V Vᵀ Lᵀ with V = Q_rᵀ).
struct OperationalSpaceOptions {
  double rcond = 1e-9;
  bool reproject = true;    // multiply each step by N_{i-1} once more (exact no-op)
};

class OperationalSpaceSolver final : public MassMatrixSolver {
 public:
  OperationalSpaceSolver(std::vector<Index> starts, Index n, OperationalSpaceOptions options);

 private:
  // J = A_i N_{i-1} L⁻ᵀ (scale ‖A_i L⁻ᵀ‖_F), e = b_i − A_i x_{i-1}
  double level_rows(const Level& lv, double* scale2) override;
  // z ← L⁻ᵀ z
  double map_step(double* z) override;
  // p = L⁻ᵀ v, q = L v
  double projector_factors(const double* v, double* p, double* q) override;
};

// The exact lexicographic minimum-norm least squares by nested SVD null spaces (the
// `reference` formulation), for each level i with x = 0 and Z_1 = I (n × n):
//     M_i = A_i Z_i,   y_i = V_r diag(σ/(σ² + μ_i²)) U_rᵀ (b_i − A_i x),   x ← x + Z_i y_i,
//     Z_{i+1} = Z_i · null(M_i)
// rank r = #{σ > rcond ‖A_i‖_F} (the readable path's rule, on singular values), a σ within
// kAmbiguity of the threshold marking the level ambiguous; undamped steps get two steps of
// iterative refinement from the level's residual formed row by row. The SVD of M_i is a
// Householder LQ, M_i = [L 0] Q, then a one-sided (Hestenes) Jacobi SVD of L's columns,
// L W = U Σ (rotations until every pair of columns is orthogonal to m ε): σ are the
// singular values of M_i to its relative accuracy, V = Qᵀ [W; 0] and null(M_i) = Qᵀ's
// columns past L's and W's columns with σ ≤ the threshold. With a metric W_x (n × n,
// SPD on the last null space) the tie-break solves (ZᵀW_xZ) z = −ZᵀW_x x by Cholesky.
struct ReferenceOptions {
  double rcond = 1e-9;
  std::vector<double> level_damping;   // k values μ_i² ≥ 0 (empty: none)
  std::vector<double> metric;          // n × n, row-major (empty: minimum norm)
};

struct ReferenceResult : ProjectionResult {
  std::vector<Index> ranks;         // k: the kept rank of M_i
  std::vector<Index> ambiguous;     // k: 1 where a σ of M_i lies within kAmbiguity of the
                                    // threshold
  Index null_space_dim = 0;         // the columns of the last Z
  Index sweeps = 0;                 // the Jacobi sweeps of the solve, over every level
  Index rotations = 0;              // the Jacobi rotations of the solve, over every level
  bool metric_positive_definite = true;   // ZᵀW_xZ factored (false: x without tie-break)
};

// What a reference solve works in beside its ProjectionWorkspace, allocated at prepare.
struct ReferenceWorkspace {
  ReferenceWorkspace() = default;
  ReferenceWorkspace(Index n, Index m_max);

  Index d = 0;                  // the current null space's dimension (Z's columns)
  std::vector<double> Z;        // n × n: the null-space basis Z_i (columns < d)
  std::vector<double> Gt;       // n × m_max: L's columns as rows (Jacobi's matrix)
  std::vector<double> Wt;       // n × n: the Jacobi rotations' product, transposed
  std::vector<double> sigma;    // n: the singular values of M_i
  std::vector<Index> order;     // n: the kept columns first, then the null ones
  std::vector<double> gain;     // n: the step's coordinates on the kept columns
  std::vector<double> res0;     // m_max: b_i − A_i x, the level's rows in order
  std::vector<double> row;      // n: scratch
  std::vector<double> G;        // n × n: ZᵀW_xZ and its Cholesky factor
  std::vector<double> WZ;       // n × n: W_x Z
};

class ReferenceSolver final : public ProjectionSolver {
 public:
  // Throws InputError on a malformed layout, rcond outside (0, 1), level_damping not k
  // finite values ≥ 0, or a metric not n × n finite values.
  ReferenceSolver(std::vector<Index> starts, Index n, ReferenceOptions options);

  // Solve one stack of the layout (as NullspaceSolver::solve).
  const ReferenceResult& solve(const StackArrays& data);

  const ReferenceResult& result() const { return result_; }

 private:
  // level lev on the workspace (Z: n × d, d the null space's dimension; N unused)
  double solve_level(Index lev, bool last) override;
  // the level's step from the kept singular directions (Zq's columns), refined; its flops
  double level_step(Index lev, Index s0, Index m, Index r);
  // the metric's tie-break on the last null space; its flops
  double metric_step();

  ReferenceOptions options_;
  ReferenceResult result_;
  ReferenceWorkspace nested_;   // beside work_ (the weighted rows, M_i's LQ)
};

// Saturation in the Null Space (SNS; Flacco, De Luca & Khatib, T-RO 2015, Algorithm 2):
// box bounds on x from the first level's single-column rows (lower ≤ a·x_j ≤ upper), hard,
// and strict priorities over the equality levels below. Per level, NullspaceSolver's step
// (x_free, and N_i after the level); when x_free leaves the box, the most critical joint
// is saturated at its bound and the level solved again in the null space left,
//     x_s = c + s a,  a = M⁺ b_i,  c = x − M⁺ A_i x + (I − M⁺ A_i) B⁺ (x_N − x)_sat,
//     M = A_i P̄,  P̄ = P − B⁺ B,  B = the rows `sat` of P = N_{i-1},
// keeping the best feasible scaling s ∈ [0, 1]; a level whose rank would drop stops, and
// one with no feasible scaling is dropped (s = 0). Every pseudo-inverse is a row-pivoted
// LQ (M: rank rule rcond ‖A_i‖_F; B: 1e-12 max(1, ‖B‖_F)), applied to vectors.
struct SnsOptions {
  double rcond = 1e-9;
  double bound_tolerance = 1e-9;   // a bound is met within tol · max(1, |bound|)
  Index max_saturations = -1;      // saturated joints per level (-1: the bounded columns)
  bool bounds_level = false;       // the first level holds the bounds (else: none)
};

// what a solve found wrong with the bounds rows (the caller names the task)
enum class SnsBounds : int { ok = 0, not_single_column = 1, empty_box = 2 };

// residuals: the bounds level's is ‖√w ∘ the distance of A_0 x to [lower, upper]‖;
// solved is also false when the bounds are malformed (`bounds`).
struct SnsResult : ProjectionResult {
  std::vector<double> task_scaling;   // k: each equality level's s (the bounds level: 1)
  std::vector<double> margins;        // k: the unbounded step's rank decision margins
  std::vector<Index> ranks;           // k: the unbounded step's kept rank
  std::vector<Index> iterations;      // k: the saturation rounds of each level
  std::vector<Index> saturated;       // k × n: row i holds level i's saturated columns ...
  std::vector<Index> saturated_count; // k: ... this many of them, in order
  std::vector<double> lower, upper;   // n: the box the bounds rows give
  SnsBounds bounds = SnsBounds::ok;   // not ok: nothing solved (`bad_entry` says where)
  Index bad_entry = -1;               // the row (not_single_column) or column (empty_box)
  bool exact = false;        // every level reached its unbounded residual
};

// What an SNS solve works in beside its ProjectionWorkspace, allocated at prepare: the
// box, the rounds' vectors (n each) and the two factorizations they apply.
struct SnsWorkspace {
  SnsWorkspace() = default;
  SnsWorkspace(Index n, Index m_max);

  Index bounded = 0;            // the bounded columns
  std::vector<double> tol;      // the bounds' tolerances
  std::vector<double> x_free, x_new, best, xs, cvec, a, corr, u, x_sat;
  std::vector<double> col_hi;   // each column's upper end of s
  std::vector<char> free;       // the columns not saturated
  std::vector<double> Pbar;     // n × n: P − B⁺B
  std::vector<double> Jm, perm_m, Vm, beta_m;   // M = A_i P̄'s LQ (Jm: m_max × n)
  std::vector<Index> pos_m;
  std::vector<double> Jb, perm_b, Vb, beta_b;   // B's LQ (Jb: n × n)
  std::vector<Index> pos_b;
  std::vector<double> y;        // max(m_max, n): scratch of apply_pinv's callers
  std::vector<double> v;        // n
};

class SnsSolver final : public ProjectionSolver {
 public:
  SnsSolver(std::vector<Index> starts, Index n, SnsOptions options);

  // Solve one stack of the layout: A, b, sqrt_weight as NullspaceSolver::solve; lower and
  // upper (M) the bounds of the first level's rows (read when options.bounds_level).
  // Throws InputError naming a non-finite entry, a √w ≤ 0 or a NaN bound.
  const SnsResult& solve(const StackArrays& data, const double* lower, const double* upper);

  const SnsResult& result() const { return result_; }

 private:
  // the box from the bounds rows; false when they are malformed (result_.bounds says why).
  // Throws InputError naming a bound that is NaN, lower = +inf, upper = −inf or lower > upper.
  bool read_bounds(const StackArrays& data, const double* lower, const double* upper);
  // the scaling interval [s_min, s_max] of c + s a within the box, col_hi_ each column's
  // upper end (formulations.sns._scale_interval); returns the flops
  double scale_interval(double* s_min, double* s_max);
  bool feasible(const double* v) const;
  double solve_level(Index lev, bool last) override;
  // the saturation rounds of level lev from x (x_new: the answer, *scale its s; false:
  // none feasible); returns the flops
  double saturate(Index lev, Index rank, double* x_new, double* scale, bool* found);
  // z = M⁺ y for the factored M (J, perm, H, rank); returns the flops
  double apply_pinv(MatrixRef J, const double* perm, const Reflectors& H, Index rank,
                    const double* y, double* z);
  // factor M = A_i P̄ with P̄ = P − B⁺B for the saturated rows; returns the flops
  double factor_saturated(Index lev, Index count, Index* rank_m, Index* rank_b);

  SnsOptions options_;
  SnsResult result_;
  SnsWorkspace rounds_;         // beside work_ (the weighted rows, the projector, its LQ)
};

}  // namespace prioik
