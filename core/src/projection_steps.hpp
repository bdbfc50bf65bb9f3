// The steps shared by the compiled closed forms (nullspace, chiaverini, unifying, sns,
// operational_space): each works on a ProjectionWorkspace (closed_form.hpp), allocates
// nothing and returns the floating-point operations it performed (counted as its loops
// execute).
#pragma once

#include <string>
#include <vector>

#include "busy_guard.hpp"
#include "prioik/closed_form.hpp"

namespace prioik::projection {

std::string fmt(double v);

// out[i] = X row i · y for the rows of X
double multiply_rows(MatrixRef X, const double* y, double* out);

// v = H_0 H_1 … H_from v (the reflectors t = from, …, 0 of H applied in turn; pos_t = t)
double apply_leading_reflectors(const Reflectors& H, Index from, double* v, Index n);

// The row-pivoted LQ of J (m × n) in place, J = Pᵀ [L 0] Q: one reflector per row whose
// pivot norm exceeds tol (H.V row r, pos r, H.count = the rank), applied to the rows after
// it; e permuted with the rows. Writes the rank, the smallest kept pivot norm (0: none) and
// the decision's margin (the smaller of kept / tol and tol / the largest rejected).
double pivoted_lq(MatrixRef J, double* e, double tol, double* norms, Reflectors& H, Index* rank,
                  double* min_pivot, double* margin);

// z[:r] = argmin ‖L z − e‖² + λ ‖z‖², L = J[:m, :r] lower trapezoidal (after pivoted_lq):
// forward substitution when r = m and λ = 0, else small_least_squares (ws.L, ws.spare)
double level_unknowns(MatrixRef J, const double* e, Index r, double damping, double* z,
                      ProjectionWorkspace& ws);

// The level's step z = J^# e with J's rank decided by tol: pivoted_lq of J (the rank, the
// smallest kept pivot and the margin written as it says), then Q_rᵀ level_unknowns
// (damping λ); z = 0 when the rank is 0
double lq_step(MatrixRef J, double* e, double tol, double damping, Reflectors& H, Index* rank,
               double* min_pivot, double* margin, double* z, ProjectionWorkspace& ws);

// x += N z (N = ws.N), or x += z when !reproject or ws.N = I
double add_step(ProjectionWorkspace& ws, const double* z, bool reproject, double* x);

// J = B N (N = ws.N, symmetric; a copy of B while ws.N = I)
double project_rows(MatrixRef B, const ProjectionWorkspace& ws, MatrixRef J);

// N ← N − V Vᵀ for V = Q e_l (l < r; Q = H_0 … H_{r-1}) mapped by N and re-orthonormalised
// inside range(N) (classical Gram-Schmidt, twice); N kept exactly symmetric
double update_projector(ProjectionWorkspace& ws, const Reflectors& H, Index r);

// N = I
void reset(ProjectionWorkspace& ws);

// v = Q e_l, Q = H_0 … H_{l} (the column l of the reflectors' product)
double reflector_column(const Reflectors& H, Index l, double* v, Index n);

// N ← N − Σ_{l<r} p_l q_lᵀ (p_l, q_l the rows l of left and right; N general)
double subtract_products(MatrixRef N, MatrixRef left, MatrixRef right, Index r);

// ws.B, ws.c = √w ∘ A, √w ∘ b and ws.scales = the levels' scales; whether every row and
// level is usable (√w finite and > 0, entries finite, scales in [1e-100, 1e100]). Both
// checks always run.
bool weigh_stack(const StackArrays& data, const std::vector<Index>& starts, Index n,
                 ProjectionWorkspace& ws);

// ws.chol = the lower Cholesky factor of the mass matrix (n × n, row-major). Throws
// InputError naming a non-finite entry of the mass matrix; returns whether the
// factorization succeeded (M positive definite).
bool factor_mass_matrix(const double* mass, Index n, ProjectionWorkspace& ws);

// residuals[i] = ‖√w ∘ (A_i x − b_i)‖ for the k = starts.size() − 1 levels; whether their
// sum (and so x) is finite
bool stack_residuals(const StackArrays& data, const std::vector<Index>& starts, Index n,
                     const double* x, double* residuals);

// Throws InputError on a malformed layout or options; returns the largest level's rows.
Index check_layout(const std::vector<Index>& starts, Index n, double rcond, double damping);

// The flops of cholesky_lower on n × n, as its loops are written
double cholesky_flops(Index n);

// Throws InputError naming the first entry of M (n × n) that is not finite
void check_mass_matrix(const double* mass, Index n);

}  // namespace prioik::projection
