// Recursive null-space projection, compiled (closed_form.hpp).
#include <algorithm>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

NullspaceSolver::NullspaceSolver(std::vector<Index> starts, Index n, NullspaceOptions options)
    : ProjectionSolver(std::move(starts), n, options.rcond, options.damping),
      options_(options) {
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.min_pivots.assign(k_, 0.0);
  result_.margins.assign(k_, kInf);
  result_.ranks.assign(k_, 0);
}

// Ĵ_i = A_i N_{i-1}, x_i = x_{i-1} + N_{i-1} Ĵ_i^# (b_i − A_i x_{i-1}), then N_i
double NullspaceSolver::solve_level(Index lev, bool last) {
  NullspaceResult& res = result_;
  Level lv = level(lev);
  Index r = 0;
  double flops = projected_step(lv, options_.rcond * work_.scales[lev], options_.damping,
                                options_.reproject, res.x.data(), &r, &res.min_pivots[lev],
                                &res.margins[lev]);
  res.ranks[lev] = r;
  if (r > 0 && !last) flops += projection::update_projector(work_, lv.H, r);
  return flops;
}

const NullspaceResult& NullspaceSolver::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  NullspaceResult& res = result_;
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  std::fill(res.min_pivots.begin(), res.min_pivots.end(), 0.0);
  std::fill(res.margins.begin(), res.margins.end(), kInf);
  res.ambiguous = false;
  res.solved = open_solve(data, res);
  if (!res.solved) return res;
  close_solve(data, run_levels(0), res);
  for (Index lev = 0; lev < k_; ++lev)
    if (res.margins[lev] <= kAmbiguity) res.ambiguous = true;
  return res;
}

}  // namespace prioik
