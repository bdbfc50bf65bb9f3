// The unifying framework (eq. 40 of Jeong & Chang 2009), compiled (closed_form.hpp): its
// parts of MassMatrixSolver's level step.
#include <algorithm>
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

UnifyingSolver::UnifyingSolver(std::vector<Index> starts, Index n, double rcond)
    : MassMatrixSolver(std::move(starts), n, rcond, true) {}

double UnifyingSolver::level_rows(const Level& lv, double* scale2) {
  ProjectionWorkspace& ws = work_;
  const MatrixRef chol = mass_factor();
  double flops = 0.0;
  for (Index i = 0; i < lv.m; ++i) {
    std::copy(lv.B.row(i), lv.B.row(i) + n_, lv.J.row(i));
    flops += mass_solve(chol, lv.J.row(i));
    *scale2 += dot(lv.J.row(i), lv.J.row(i), n_);
    ws.e[i] = ws.c[lv.s0 + i];
  }
  return flops;
}

double UnifyingSolver::map_step(double* z) { return mass_solve(mass_factor(), z); }

double UnifyingSolver::projector_factors(const double* v, double* p, double* q) {
  ProjectionWorkspace& ws = work_;
  const Index n = n_;
  const MatrixRef chol = mass_factor();
  // M v from the factor: M v = L (Lᵀ v)
  for (Index a = 0; a < n; ++a) {
    double acc = 0.0;
    for (Index c = a; c < n; ++c) acc += chol(c, a) * v[c];
    ws.aux[a] = acc;
  }
  for (Index a = 0; a < n; ++a) q[a] = dot(chol.row(a), ws.aux.data(), a + 1);
  double flops = 2.0 * static_cast<double>(n * (n + 1));
  std::copy(v, v + n, p);
  flops += mass_solve(chol, p);
  if (ws.projected) {
    flops += projection::multiply_rows(projector(), p, ws.aux.data());
    std::copy(ws.aux.begin(), ws.aux.end(), p);
  }
  return flops;
}

}  // namespace prioik
