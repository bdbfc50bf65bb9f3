// Chiaverini's singularity-robust task priority, compiled (closed_form.hpp).
#include <algorithm>
#include <cmath>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

ChiaveriniSolver::ChiaveriniSolver(std::vector<Index> starts, Index n, ChiaveriniOptions options)
    : ProjectionSolver(std::move(starts), n, options.rcond, options.damping),
      options_(options) {
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.task_solutions.assign(k_ * n_, 0.0);
}

double ChiaveriniSolver::solve_level(Index lev, bool last) {
  ProjectionWorkspace& ws = work_;
  ChiaveriniResult& res = result_;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_;
  const double tol = options_.rcond * ws.scales[lev];
  if (!(tol > 0.0)) return 0.0;                        // a zero level: x_own = 0, N kept
  MatrixRef J{ws.J.data(), m, n, n};
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  Reflectors H{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0};
  // the level's own solution A_i^# b_i
  std::copy(B.data, B.data + m * n, J.data);
  std::copy(ws.c.begin() + s0, ws.c.begin() + s0 + m, ws.e.begin());
  Index r = 0;
  double min_pivot = 0.0, margin = kInf;
  double* own = res.task_solutions.data() + lev * n;
  double flops = projection::lq_step(J, ws.e.data(), tol, options_.damping, H, &r, &min_pivot,
                                     &margin, own, ws);
  // x += N^A_{i-1} A_i^# b_i
  flops += projection::add_step(ws, own, true, res.x.data());
  if (last) return flops;
  // N^A_i from the kept row space of A_i N^A_{i-1} (the nested null spaces' rank r_i)
  flops += projection::project_rows(B, ws, J);
  Index rank = 0;
  flops += projection::pivoted_lq(J, ws.e.data(), tol, ws.norms.data(), H, &rank, &min_pivot,
                                  &margin);
  if (rank > 0) flops += projection::update_projector(ws, H, rank);
  return flops;
}

const ChiaveriniResult& ChiaveriniSolver::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  ProjectionWorkspace& ws = work_;
  ChiaveriniResult& res = result_;
  const bool stack_ok = projection::weigh_stack(data, starts_, n_, ws);
  res.flops = 0.0;
  std::fill(res.x.begin(), res.x.end(), 0.0);
  std::fill(res.task_solutions.begin(), res.task_solutions.end(), 0.0);
  res.solved = stack_ok;
  if (!res.solved) {
    check_stack_entries(data, M_, n_);     // a NaN, inf or √w ≤ 0 is an input error
    res.finite = false;
    return res;
  }
  projection::reset(ws);
  double flops = 0.0;
  for (Index lev = 0; lev < k_; ++lev) flops += solve_level(lev, lev == k_ - 1);
  res.flops = flops;
  res.finite =
      projection::stack_residuals(data, starts_, n_, res.x.data(), res.residuals.data());
  return res;
}

}  // namespace prioik
