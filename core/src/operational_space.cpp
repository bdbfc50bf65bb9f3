// Prioritized operational-space control, compiled (closed_form.hpp).
#include <algorithm>
#include <cmath>
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
    : MassMatrixSolver(std::move(starts), n, options.rcond), options_(options) {}

double OperationalSpaceSolver::solve_level(Index lev, bool last) {
  ProjectionWorkspace& ws = work_;
  UnifyingResult& res = result_;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_;
  const MatrixRef chol{ws.chol.data(), n, n, n};
  MatrixRef N{ws.N.data(), n, n, n};
  MatrixRef J{ws.J.data(), m, n, n};
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  // the scale ‖A_i L⁻ᵀ‖_F (row by row in ws.aux), B = A_i N L⁻ᵀ and e = b_i − A_i x
  double flops = 0.0, scale2 = 0.0;
  for (Index i = 0; i < m; ++i) {
    std::copy(B.row(i), B.row(i) + n, ws.aux.begin());
    flops += lower_solve(chol, ws.aux.data());
    scale2 += dot(ws.aux.data(), ws.aux.data(), n);
  }
  flops += 2.0 * static_cast<double>(m * n) + 1.0;
  if (ws.projected) {
    flops += right_multiply(B, N, J);
  } else {
    std::copy(B.data, B.data + m * n, J.data);
  }
  for (Index i = 0; i < m; ++i) flops += lower_solve(chol, J.row(i));
  flops += projection::multiply_rows(B, res.x.data(), ws.e.data());
  for (Index i = 0; i < m; ++i) ws.e[i] = ws.c[s0 + i] - ws.e[i];
  flops += static_cast<double>(m);
  const double tol = options_.rcond * std::sqrt(scale2);
  if (!(tol > 0.0)) return flops;
  Reflectors H{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0};
  // the step J̄ e = L⁻ᵀ B⁺ e, reprojected by N_{i-1}
  double* step = ws.step.data();
  Index r = 0;
  double min_pivot = 0.0, margin = kInf;
  flops += projection::lq_step(J, ws.e.data(), tol, 0.0, H, &r, &min_pivot, &margin, step, ws);
  res.ranks[lev] = r;
  if (r == 0) return flops;
  flops += lower_transpose_solve(chol, step);
  flops += projection::add_step(ws, step, options_.reproject, res.x.data());
  if (last) return flops;
  // N_i = N_{i-1} − (L⁻ᵀ V)(L V)ᵀ, V = Q_rᵀ
  MatrixRef left{ws.left.data(), r, n, n}, right{ws.right.data(), r, n, n};
  for (Index l = 0; l < r; ++l) {
    double* vl = ws.basis.data() + l * n;
    flops += projection::reflector_column(H, l, vl, n);
    double* rl = right.row(l);
    for (Index a = 0; a < n; ++a) rl[a] = dot(chol.row(a), vl, a + 1);
    flops += static_cast<double>(n * (n + 1));
    std::copy(vl, vl + n, left.row(l));
    flops += lower_transpose_solve(chol, left.row(l));
  }
  flops += projection::subtract_products(N, left, right, r);
  ws.projected = true;
  return flops;
}

}  // namespace prioik
