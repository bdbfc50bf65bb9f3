// Prioritized operational-space control, compiled (closed_form.hpp): its parts of
// MassMatrixSolver's level step.
#include <algorithm>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

namespace {

// v = L⁻¹ v (forward substitution, L in the lower triangle of chol); returns the flops
double lower_solve(MatrixRef chol, double* v) {
  const Index n = chol.rows;
  for (Index a = 0; a < n; ++a) v[a] = (v[a] - dot(chol.row(a), v, a)) / chol(a, a);
  return static_cast<double>(n * n);
}

// v = L⁻ᵀ v (back substitution on the transpose); returns the flops
double lower_transpose_solve(MatrixRef chol, double* v) {
  const Index n = chol.rows;
  for (Index a = n - 1; a >= 0; --a) {
    double acc = v[a];
    for (Index c = a + 1; c < n; ++c) acc -= chol(c, a) * v[c];
    v[a] = acc / chol(a, a);
  }
  return static_cast<double>(n * n);
}

// J = B N for a general N (n × n; the dynamically consistent projector is not symmetric),
// row by row as combinations of N's rows; returns the flops
double right_multiply(MatrixRef B, MatrixRef N, MatrixRef J) {
  const Index n = N.cols;
  for (Index i = 0; i < B.rows; ++i) {
    double* Ji = J.row(i);
    std::fill(Ji, Ji + n, 0.0);
    const double* Bi = B.row(i);
    for (Index k = 0; k < n; ++k) {
      const double bik = Bi[k];
      const double* Nk = N.row(k);
      for (Index j = 0; j < n; ++j) Ji[j] += bik * Nk[j];
    }
  }
  return 2.0 * static_cast<double>(B.rows * n * n);
}

}  // namespace

OperationalSpaceSolver::OperationalSpaceSolver(std::vector<Index> starts, Index n,
                                               OperationalSpaceOptions options)
    : MassMatrixSolver(std::move(starts), n, options.rcond, options.reproject) {}

double OperationalSpaceSolver::level_rows(const Level& lv, double* scale2) {
  ProjectionWorkspace& ws = work_;
  const Index m = lv.m, n = n_;
  const MatrixRef chol = mass_factor();
  // the scale ‖A_i L⁻ᵀ‖_F (row by row in ws.aux), J = A_i N L⁻ᵀ and e = b_i − A_i x
  double flops = 0.0;
  for (Index i = 0; i < m; ++i) {
    std::copy(lv.B.row(i), lv.B.row(i) + n, ws.aux.begin());
    flops += lower_solve(chol, ws.aux.data());
    *scale2 += dot(ws.aux.data(), ws.aux.data(), n);
  }
  if (ws.projected) {
    flops += right_multiply(lv.B, projector(), lv.J);
  } else {
    std::copy(lv.B.data, lv.B.data + m * n, lv.J.data);
  }
  for (Index i = 0; i < m; ++i) flops += lower_solve(chol, lv.J.row(i));
  flops += projection::multiply_rows(lv.B, result_.x.data(), ws.e.data());
  for (Index i = 0; i < m; ++i) ws.e[i] = ws.c[lv.s0 + i] - ws.e[i];
  return flops + static_cast<double>(m);
}

// J̄ e = L⁻ᵀ B⁺ e (reprojected by N_{i-1} when options.reproject)
double OperationalSpaceSolver::map_step(double* z) {
  return lower_transpose_solve(mass_factor(), z);
}

// N_i = N_{i-1} − (L⁻ᵀ V)(L V)ᵀ, V = Q_rᵀ
double OperationalSpaceSolver::projector_factors(const double* v, double* p, double* q) {
  const Index n = n_;
  const MatrixRef chol = mass_factor();
  for (Index a = 0; a < n; ++a) q[a] = dot(chol.row(a), v, a + 1);
  std::copy(v, v + n, p);
  return static_cast<double>(n * (n + 1)) + lower_transpose_solve(chol, p);
}

}  // namespace prioik
