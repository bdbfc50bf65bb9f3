// The unifying framework (eq. 40 of Jeong & Chang 2009), compiled (closed_form.hpp), and
// the solve with a mass matrix it shares with operational_space.cpp (MassMatrixSolver).
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

namespace {

// v = M⁻¹ v in place for M = L Lᵀ (L in the lower triangle of chol); returns the flops
double mass_solve(MatrixRef chol, double* v) {
  cholesky_solve(chol, v, chol.rows);
  return 2.0 * static_cast<double>(chol.rows * chol.rows);
}

}  // namespace

MassMatrixSolver::MassMatrixSolver(std::vector<Index> starts, Index n, double rcond)
    : ProjectionSolver(std::move(starts), n, rcond, 0.0) {
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.ranks.assign(k_, 0);
}

const UnifyingResult& MassMatrixSolver::solve(const StackArrays& data, const double* mass_matrix) {
  BusyGuard guard(busy_);
  ProjectionWorkspace& ws = work_;
  UnifyingResult& res = result_;
  const bool stack_ok = projection::weigh_stack(data, starts_, n_, ws);
  res.flops = 0.0;
  std::fill(res.x.begin(), res.x.end(), 0.0);
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  res.finite = false;
  res.mass_positive_definite = projection::factor_mass_matrix(data, mass_matrix, stack_ok, n_,
                                                              ws);
  res.solved = stack_ok && res.mass_positive_definite;
  if (!res.solved) return res;
  projection::reset(ws);
  double flops = projection::cholesky_flops(n_);
  for (Index lev = 0; lev < k_; ++lev) flops += solve_level(lev, lev == k_ - 1);
  res.flops = flops;
  res.finite =
      projection::stack_residuals(data, starts_, n_, res.x.data(), res.residuals.data());
  return res;
}

UnifyingSolver::UnifyingSolver(std::vector<Index> starts, Index n, double rcond)
    : MassMatrixSolver(std::move(starts), n, rcond), rcond_(rcond) {}

double UnifyingSolver::solve_level(Index lev, bool last) {
  ProjectionWorkspace& ws = work_;
  UnifyingResult& res = result_;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_;
  const MatrixRef chol{ws.chol.data(), n, n, n};
  MatrixRef N{ws.N.data(), n, n, n};
  MatrixRef J{ws.J.data(), m, n, n};
  // B = A_i M⁻¹ (row j: M⁻¹ a_j, M symmetric), its scale and the targets
  double flops = 0.0, scale2 = 0.0;
  for (Index i = 0; i < m; ++i) {
    std::copy(ws.B.data() + (s0 + i) * n, ws.B.data() + (s0 + i + 1) * n, J.row(i));
    flops += mass_solve(chol, J.row(i));
    scale2 += dot(J.row(i), J.row(i), n);
    ws.e[i] = ws.c[s0 + i];
  }
  flops += 2.0 * static_cast<double>(m * n) + 1.0;
  const double tol = rcond_ * std::sqrt(scale2);
  if (!(tol > 0.0)) return flops;
  Reflectors H{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0};
  // θ̈_i = N_i M⁻¹ B⁺ b_i
  double* step = ws.step.data();
  Index r = 0;
  double min_pivot = 0.0, margin = kInf;
  flops += projection::lq_step(J, ws.e.data(), tol, 0.0, H, &r, &min_pivot, &margin, step, ws);
  res.ranks[lev] = r;
  if (r == 0) return flops;
  flops += mass_solve(chol, step);
  flops += projection::add_step(ws, step, true, res.x.data());
  if (last) return flops;
  // N_{i+1} = N_i − (N_i M⁻¹ V)(M V)ᵀ, V = Q_rᵀ
  MatrixRef left{ws.left.data(), r, n, n}, right{ws.right.data(), r, n, n};
  for (Index l = 0; l < r; ++l) {
    double* vl = ws.basis.data() + l * n;
    flops += projection::reflector_column(H, l, vl, n);
    // M V from the factor: M v = L (Lᵀ v)
    double* rl = right.row(l);
    for (Index a = 0; a < n; ++a) {
      double acc = 0.0;
      for (Index c = a; c < n; ++c) acc += chol(c, a) * vl[c];
      ws.aux[a] = acc;
    }
    for (Index a = 0; a < n; ++a) rl[a] = dot(chol.row(a), ws.aux.data(), a + 1);
    flops += 2.0 * static_cast<double>(n * (n + 1));
    std::copy(vl, vl + n, left.row(l));
    flops += mass_solve(chol, left.row(l));
    if (ws.projected) {
      flops += projection::multiply_rows(N, left.row(l), ws.aux.data());
      std::copy(ws.aux.begin(), ws.aux.end(), left.row(l));
    }
  }
  flops += projection::subtract_products(N, left, right, r);
  ws.projected = true;
  return flops;
}

}  // namespace prioik
