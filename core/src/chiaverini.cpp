// Chiaverini's singularity-robust task priority, compiled (closed_form.hpp).
#include <algorithm>
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
  const double tol = options_.rcond * ws.scales[lev];
  if (!(tol > 0.0)) return 0.0;                        // a zero level: x_own = 0, N kept
  auto [s0, m, B, J, H] = level(lev);
  // the level's own solution A_i^# b_i
  std::copy(B.data, B.data + m * n_, J.data);
  std::copy(ws.c.begin() + s0, ws.c.begin() + s0 + m, ws.e.begin());
  Index r = 0;
  double min_pivot = 0.0, margin = kInf;
  double* own = res.task_solutions.data() + lev * n_;
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
  ChiaveriniResult& res = result_;
  std::fill(res.task_solutions.begin(), res.task_solutions.end(), 0.0);
  res.solved = open_solve(data, res);
  if (!res.solved) return res;
  close_solve(data, run_levels(0), res);
  return res;
}

}  // namespace prioik
