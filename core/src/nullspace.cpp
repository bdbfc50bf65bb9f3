// Recursive null-space projection, compiled (closed_form.hpp).
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

using projection::fmt;

void check_stack_entries(const StackArrays& data, Index M, Index n) {
  for (Index i = 0; i < M; ++i)
    for (Index j = 0; j < n; ++j)
      if (!std::isfinite(data.A[i * n + j]))
        throw InputError("A[" + std::to_string(i) + ", " + std::to_string(j) +
                         "] is not finite (" + fmt(data.A[i * n + j]) + ")");
  for (Index i = 0; i < M; ++i)
    if (!std::isfinite(data.b[i]))
      throw InputError("b[" + std::to_string(i) + "] is not finite (" + fmt(data.b[i]) + ")");
  for (Index i = 0; i < M; ++i) {
    const double w = data.sqrt_weight[i];
    if (!(w > 0.0 && w < kInf))
      throw InputError("sqrt_weight[" + std::to_string(i) + "] must be finite and > 0, got " +
                       fmt(w));
  }
}

ProjectionWorkspace::ProjectionWorkspace(Index M, Index n, Index k, Index m_max)
    : B(M * n, 0.0),
      c(M, 0.0),
      scales(k, 0.0),
      N(n * n, 0.0),
      J(m_max * n, 0.0),
      e(m_max, 0.0),
      norms(m_max, 0.0),
      V(n * n, 0.0),
      beta(n, 0.0),
      pos(n, 0),
      basis(n * n, 0.0),
      step(n, 0.0),
      aux(n, 0.0),
      L(m_max * n, 0.0),
      spare(small_least_squares_scratch(m_max, std::min(m_max, n)), 0.0),
      chol(n * n, 0.0),
      left(n * n, 0.0),
      right(n * n, 0.0) {}

ProjectionSolver::ProjectionSolver(std::vector<Index> starts, Index n, double rcond,
                                   double damping)
    : starts_(std::move(starts)), n_(n) {
  const Index m_max = projection::check_layout(starts_, n_, rcond, damping);
  k_ = static_cast<Index>(starts_.size()) - 1;
  M_ = starts_.back();
  work_ = ProjectionWorkspace(M_, n_, k_, m_max);
}

NullspaceSolver::NullspaceSolver(std::vector<Index> starts, Index n, NullspaceOptions options)
    : ProjectionSolver(std::move(starts), n, options.rcond, options.damping),
      options_(options) {
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.min_pivots.assign(k_, 0.0);
  result_.margins.assign(k_, kInf);
  result_.ranks.assign(k_, 0);
}

double NullspaceSolver::solve_level(Index lev, bool last) {
  ProjectionWorkspace& ws = work_;
  NullspaceResult& res = result_;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_;
  const double tol = options_.rcond * ws.scales[lev];
  MatrixRef J{ws.J.data(), m, n, n};
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  // Ĵ_i = A_i N_{i-1} and e = b_i − A_i x_{i-1}
  double flops = projection::project_rows(B, ws, J);
  flops += projection::multiply_rows(B, res.x.data(), ws.e.data());
  for (Index i = 0; i < m; ++i) ws.e[i] = ws.c[s0 + i] - ws.e[i];
  flops += static_cast<double>(m);
  if (!(tol > 0.0)) return flops;                      // a zero level keeps nothing
  Reflectors H{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0};
  // the step Q_rᵀ z, reprojected by N_{i-1}
  double* step = ws.step.data();
  Index r = 0;
  flops += projection::lq_step(J, ws.e.data(), tol, options_.damping, H, &r,
                               &res.min_pivots[lev], &res.margins[lev], step, ws);
  res.ranks[lev] = r;
  if (r == 0) return flops;
  flops += projection::add_step(ws, step, options_.reproject, res.x.data());
  if (!last) flops += projection::update_projector(ws, H, r);
  return flops;
}

const NullspaceResult& NullspaceSolver::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  ProjectionWorkspace& ws = work_;
  NullspaceResult& res = result_;
  const bool stack_ok = projection::weigh_stack(data, starts_, n_, ws);
  res.flops = 0.0;
  std::fill(res.x.begin(), res.x.end(), 0.0);
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  std::fill(res.min_pivots.begin(), res.min_pivots.end(), 0.0);
  std::fill(res.margins.begin(), res.margins.end(), kInf);
  res.solved = stack_ok;
  if (!res.solved) {
    check_stack_entries(data, M_, n_);     // a NaN, inf or √w ≤ 0 is an input error
    res.finite = res.ambiguous = false;
    return res;
  }
  projection::reset(ws);
  double flops = 0.0;
  for (Index lev = 0; lev < k_; ++lev) flops += solve_level(lev, lev == k_ - 1);
  res.flops = flops;
  res.finite =
      projection::stack_residuals(data, starts_, n_, res.x.data(), res.residuals.data());
  res.ambiguous = false;
  for (Index lev = 0; lev < k_; ++lev)
    if (res.margins[lev] <= kAmbiguity) res.ambiguous = true;
  return res;
}

}  // namespace prioik
