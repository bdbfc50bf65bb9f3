// The frame every compiled closed form shares (closed_form.hpp): the workspace, the
// layout's checks, a solve's opening and close around the formulation's levels, and the
// mass-matrix weighted level step of unifying and operational_space (MassMatrixSolver).
#include <algorithm>
#include <cmath>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

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

bool ProjectionSolver::open_solve(const StackArrays& data, ProjectionResult& res) {
  const bool stack_ok = projection::weigh_stack(data, starts_, n_, work_);
  std::fill(res.x.begin(), res.x.end(), 0.0);
  res.flops = 0.0;
  res.solved = res.finite = false;
  if (!stack_ok) {
    check_stack_entries(data, M_, n_);     // a NaN, inf or √w ≤ 0 is an input error
    return false;
  }
  projection::reset(work_);
  return true;
}

double ProjectionSolver::run_levels(Index first) {
  double flops = 0.0;
  for (Index lev = first; lev < k_; ++lev) flops += solve_level(lev, lev == k_ - 1);
  return flops;
}

ProjectionSolver::Level ProjectionSolver::level(Index lev) {
  ProjectionWorkspace& ws = work_;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_;
  return Level{s0, m, MatrixRef{ws.B.data() + s0 * n, m, n, n}, MatrixRef{ws.J.data(), m, n, n},
               Reflectors{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0}};
}

double ProjectionSolver::projected_step(Level& lv, double tol, double damping, bool reproject,
                                        double* x, Index* rank, double* min_pivot,
                                        double* margin) {
  ProjectionWorkspace& ws = work_;
  double flops = projection::project_rows(lv.B, ws, lv.J);
  flops += projection::multiply_rows(lv.B, x, ws.e.data());
  for (Index i = 0; i < lv.m; ++i) ws.e[i] = ws.c[lv.s0 + i] - ws.e[i];
  flops += static_cast<double>(lv.m);
  if (!(tol > 0.0)) return flops;                      // a zero level keeps nothing
  flops += projection::lq_step(lv.J, ws.e.data(), tol, damping, lv.H, rank, min_pivot, margin,
                               ws.step.data(), ws);
  if (*rank > 0) flops += projection::add_step(ws, ws.step.data(), reproject, x);
  return flops;
}

void ProjectionSolver::close_solve(const StackArrays& data, double flops,
                                   ProjectionResult& res) const {
  res.flops = flops;
  res.finite =
      projection::stack_residuals(data, starts_, n_, res.x.data(), res.residuals.data());
}

MassMatrixSolver::MassMatrixSolver(std::vector<Index> starts, Index n, double rcond,
                                   bool reproject)
    : ProjectionSolver(std::move(starts), n, rcond, 0.0), rcond_(rcond), reproject_(reproject) {
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.ranks.assign(k_, 0);
}

const UnifyingResult& MassMatrixSolver::solve(const StackArrays& data, const double* mass_matrix) {
  BusyGuard guard(busy_);
  UnifyingResult& res = result_;
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  const bool stack_ok = open_solve(data, res);
  res.mass_positive_definite = projection::factor_mass_matrix(mass_matrix, n_, work_);
  res.solved = stack_ok && res.mass_positive_definite;
  if (!res.solved) return res;
  close_solve(data, projection::cholesky_flops(n_) + run_levels(0), res);
  return res;
}

double MassMatrixSolver::solve_level(Index lev, bool last) {
  ProjectionWorkspace& ws = work_;
  Level lv = level(lev);
  const Index n = n_;
  double scale2 = 0.0;
  double flops = level_rows(lv, &scale2);
  flops += 2.0 * static_cast<double>(lv.m * n) + 1.0;  // the scale's squares and root
  const double tol = rcond_ * std::sqrt(scale2);
  if (!(tol > 0.0)) return flops;                      // a zero level keeps nothing
  double* step = ws.step.data();
  Index r = 0;
  double min_pivot = 0.0, margin = kInf;
  flops += projection::lq_step(lv.J, ws.e.data(), tol, 0.0, lv.H, &r, &min_pivot, &margin, step,
                               ws);
  result_.ranks[lev] = r;
  if (r == 0) return flops;
  flops += map_step(step);
  flops += projection::add_step(ws, step, reproject_, result_.x.data());
  if (last) return flops;
  MatrixRef left{ws.left.data(), r, n, n}, right{ws.right.data(), r, n, n};
  for (Index l = 0; l < r; ++l) {
    double* vl = ws.basis.data() + l * n;
    flops += projection::reflector_column(lv.H, l, vl, n);
    flops += projector_factors(vl, left.row(l), right.row(l));
  }
  flops += projection::subtract_products(projector(), left, right, r);
  ws.projected = true;
  return flops;
}

}  // namespace prioik
