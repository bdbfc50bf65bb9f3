// The steps shared by the projector recursions (projection_steps.hpp).
#include "projection_steps.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace prioik::projection {

namespace {

// Python's min(a, b): a unless b < a
inline double first_min(double a, double b) { return b < a ? b : a; }

// The rows l < r of `basis` made orthonormal (classical Gram-Schmidt, twice); returns the
// flops.
double orthonormalize_rows(MatrixRef basis, Index r) {
  const Index n = basis.cols;
  double flops = 0.0;
  for (Index l = 0; l < r; ++l) {
    double* bl = basis.row(l);
    for (int pass = 0; pass < 2; ++pass) {
      for (Index p = 0; p < l; ++p) {
        const double* bp = basis.row(p);
        const double h = dot(bp, bl, n);
        for (Index j = 0; j < n; ++j) bl[j] -= h * bp[j];
      }
      flops += 4.0 * static_cast<double>(l * n);
    }
    const double norm = std::sqrt(dot(bl, bl, n));
    const double inv = 1.0 / norm;
    for (Index j = 0; j < n; ++j) bl[j] *= inv;
    flops += 3.0 * n + 2.0;
  }
  return flops;
}

// N ← N − Σ_{l<r} b_l b_lᵀ on the lower triangle, mirrored (N stays exactly symmetric);
// returns the flops.
double subtract_outer_products(MatrixRef N, MatrixRef basis, Index r) {
  const Index n = N.cols;
  for (Index l = 0; l < r; ++l) {
    const double* bl = basis.row(l);
    for (Index a = 0; a < n; ++a) {
      const double wa = bl[a];
      double* Na = N.row(a);
      for (Index b = 0; b <= a; ++b) Na[b] -= wa * bl[b];
    }
  }
  for (Index a = 0; a < n; ++a)
    for (Index b = 0; b < a; ++b) N(b, a) = N(a, b);
  return static_cast<double>(r * n * (n + 1));
}

}  // namespace

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// out[i] = dot(rows i of X, y) for the rows of X (rows × n): 2 n flops each
double multiply_rows(MatrixRef X, const double* y, double* out) {
  for (Index i = 0; i < X.rows; ++i) out[i] = dot(X.row(i), y, X.cols);
  return 2.0 * static_cast<double>(X.rows * X.cols);
}

// v ← H_{from} … H_1 H_0-ordered products: applies the reflectors t = from, from − 1, …, 0
// of H (pos_t = t) to v (n entries), so that v = H_0 H_1 … H_from v; returns the flops.
double apply_leading_reflectors(const Reflectors& H, Index from, double* v, Index n) {
  double flops = 0.0;
  for (Index t = from; t >= 0; --t) {
    const Index q = H.pos[t];
    const double* vt = H.V.row(t) + q;
    double* vq = v + q;
    const Index w = n - q;
    const double f = H.beta[t] * dot(vt, vq, w);
    flops += 2.0 * w + 1.0;
    if (f != 0.0) {
      for (Index c = 0; c < w; ++c) vq[c] -= f * vt[c];
      flops += 2.0 * w;
    }
  }
  return flops;
}

// The row-pivoted LQ of J (m × n) in place: one reflector per row whose pivot norm
// exceeds tol (H.V row r, pos r), applied to the rows after it; e permuted with the rows.
// Writes the rank into *rank, the smallest kept pivot into *min_pivot and the decision's
// margin into *margin; returns the flops.
double pivoted_lq(MatrixRef J, double* e, double tol, double* norms, Reflectors& H, Index* rank,
                  double* min_pivot, double* margin) {
  const Index m = J.rows, n = J.cols;
  double flops = 2.0 * static_cast<double>(m * n);
  for (Index i = 0; i < m; ++i) norms[i] = dot(J.row(i), J.row(i), n);
  Index r = 0;
  double kept_min = kInf;
  while (r < m && r < n) {
    Index p = argmax_from(norms, r, m);
    double exact = dot(J.row(p) + r, J.row(p) + r, n - r);
    flops += 2.0 * (n - r) + 1.0;
    if (!(std::sqrt(exact) > tol)) {
      // the downdated norms may have lost the largest remaining row: recompute them
      for (Index i = r; i < m; ++i) norms[i] = dot(J.row(i) + r, J.row(i) + r, n - r);
      flops += 2.0 * static_cast<double>((m - r) * (n - r));
      p = argmax_from(norms, r, m);
      exact = dot(J.row(p) + r, J.row(p) + r, n - r);
      flops += 2.0 * (n - r) + 1.0;
    }
    const double norm = std::sqrt(exact);
    if (!(norm > tol)) {
      if (exact > 0.0) *margin = first_min(kept_min / tol, tol / norm);
      break;
    }
    kept_min = first_min(kept_min, norm);
    if (p != r) {
      swap_rows(J, r, p);
      swap_entries(e, r, p);
      swap_entries(norms, r, p);
    }
    double* v = H.V.row(r);
    Index support_end = n;       // (the level's step applies over all n - r columns)
    const double bt = make_row_reflector(J.row(r), r, n, exact, v, &support_end);
    flops += 2.0 * (n - r) + 2.0;
    H.beta[r] = bt;
    H.pos[r] = r;
    const double* vr = v + r;
    const Index w = n - r;
    for (Index i = r + 1; i < m; ++i) {
      double* row = J.row(i) + r;
      flops += 2.0 * w;
      if (apply_row_reflector(row, vr, w, bt)) flops += 2.0 * w + 1.0;
      norms[i] -= row[0] * row[0];
      flops += 2.0;
    }
    ++r;
  }
  H.count = r;
  *rank = r;
  *min_pivot = r > 0 ? kept_min : 0.0;
  *margin = first_min(*margin, kept_min / tol);
  return flops;
}

// z[:r] = argmin ‖L z − e‖² + λ ‖z‖² for L = J[:m, :r] (lower trapezoidal): forward
// substitution when r = m and λ = 0, else small_least_squares; returns the flops.
double level_unknowns(MatrixRef J, const double* e, Index r, double damping, double* z,
                      ProjectionWorkspace& ws) {
  const Index m = J.rows;
  if (r == m && damping == 0.0) {
    for (Index i = 0; i < r; ++i) {
      double acc = e[i];
      const double* row = J.row(i);
      for (Index j = 0; j < i; ++j) acc -= row[j] * z[j];
      z[i] = acc / row[i];
    }
    return static_cast<double>(r * r);
  }
  MatrixRef L{ws.L.data(), m, r, r};
  for (Index i = 0; i < m; ++i)
    for (Index j = 0; j < r; ++j) L(i, j) = j <= i ? J(i, j) : 0.0;
  small_least_squares(L, e, m, r, damping, z, ws.spare.data());
  return small_least_squares_flops(m, r, damping > 0.0);
}

double lq_step(MatrixRef J, double* e, double tol, double damping, Reflectors& H, Index* rank,
               double* min_pivot, double* margin, double* z, ProjectionWorkspace& ws) {
  const Index n = J.cols;
  double flops = pivoted_lq(J, e, tol, ws.norms.data(), H, rank, min_pivot, margin);
  std::fill(z, z + n, 0.0);
  if (*rank == 0) return flops;
  flops += level_unknowns(J, e, *rank, damping, z, ws);
  flops += apply_leading_reflectors(H, *rank - 1, z, n);
  return flops;
}

double add_step(ProjectionWorkspace& ws, const double* z, bool reproject, double* x) {
  const Index n = static_cast<Index>(ws.aux.size());
  double flops = 0.0;
  const double* add = z;
  if (reproject && ws.projected) {
    flops += multiply_rows(MatrixRef{ws.N.data(), n, n, n}, z, ws.aux.data());
    add = ws.aux.data();
  }
  for (Index j = 0; j < n; ++j) x[j] += add[j];
  return flops + static_cast<double>(n);
}

double project_rows(MatrixRef B, const ProjectionWorkspace& ws, MatrixRef J) {
  if (!ws.projected) {
    std::copy(B.data, B.data + B.rows * B.cols, J.data);
    return 0.0;
  }
  const MatrixRef N{const_cast<double*>(ws.N.data()), B.cols, B.cols, B.cols};
  double flops = 0.0;
  for (Index i = 0; i < B.rows; ++i) flops += multiply_rows(N, B.row(i), J.row(i));
  return flops;
}

double update_projector(ProjectionWorkspace& ws, const Reflectors& H, Index r) {
  const Index n = H.V.cols;
  MatrixRef N{ws.N.data(), n, n, n};
  MatrixRef basis{ws.basis.data(), r, n, n};
  double flops = 0.0;
  for (Index l = 0; l < r; ++l) {
    double* bl = basis.row(l);
    flops += reflector_column(H, l, bl, n);
    if (ws.projected) {
      flops += multiply_rows(N, bl, ws.aux.data());
      std::copy(ws.aux.begin(), ws.aux.end(), bl);
    }
  }
  if (ws.projected) flops += orthonormalize_rows(basis, r);
  flops += subtract_outer_products(N, basis, r);
  ws.projected = true;
  return flops;
}

void reset(ProjectionWorkspace& ws) {
  const Index n = static_cast<Index>(ws.step.size());
  for (Index a = 0; a < n; ++a)
    for (Index b = 0; b < n; ++b) ws.N[a * n + b] = a == b ? 1.0 : 0.0;
  ws.projected = false;
}

double reflector_column(const Reflectors& H, Index l, double* v, Index n) {
  std::fill(v, v + n, 0.0);
  v[l] = 1.0;
  return apply_leading_reflectors(H, l, v, n);
}

double subtract_products(MatrixRef N, MatrixRef left, MatrixRef right, Index r) {
  const Index n = N.cols;
  for (Index l = 0; l < r; ++l) {
    const double* pl = left.row(l);
    const double* ql = right.row(l);
    for (Index a = 0; a < n; ++a) {
      const double pa = pl[a];
      double* Na = N.row(a);
      for (Index b = 0; b < n; ++b) Na[b] -= pa * ql[b];
    }
  }
  return 2.0 * static_cast<double>(r * n * n);
}

bool weigh_stack(const StackArrays& data, const std::vector<Index>& starts, Index n,
                 ProjectionWorkspace& ws) {
  const Index M = starts.back(), k = static_cast<Index>(starts.size()) - 1;
  const bool weights_ok = weigh_rows(data.A, data.b, data.sqrt_weight, M, n, ws.B.data(),
                                     ws.c.data());
  const bool scales_ok = level_scales(ws.B.data(), ws.c.data(), M, n, starts.data(), k,
                                      ws.scales.data());
  return weights_ok && scales_ok;
}

bool factor_mass_matrix(const double* mass, Index n, ProjectionWorkspace& ws) {
  bool mass_finite = true;
  for (Index i = 0; i < n * n; ++i) {
    ws.chol[i] = mass[i];
    if (!std::isfinite(mass[i])) mass_finite = false;
  }
  if (!mass_finite) check_mass_matrix(mass, n);
  return cholesky_lower(MatrixRef{ws.chol.data(), n, n, n}, n);
}

bool stack_residuals(const StackArrays& data, const std::vector<Index>& starts, Index n,
                     const double* x, double* residuals) {
  const Index k = static_cast<Index>(starts.size()) - 1;
  level_residuals(data.A, data.b, data.sqrt_weight, n, starts.data(), k, x, residuals);
  double acc = 0.0;
  for (Index lev = 0; lev < k; ++lev) acc += residuals[lev];
  return std::isfinite(acc);
}

Index check_layout(const std::vector<Index>& starts, Index n, double rcond, double damping) {
  if (starts.empty() || starts[0] != 0)
    throw InputError("starts must hold the k + 1 row offsets of the levels, from 0");
  Index m_max = 0;
  for (std::size_t i = 1; i < starts.size(); ++i) {
    if (starts[i] < starts[i - 1]) throw InputError("starts must be non-decreasing");
    m_max = std::max(m_max, starts[i] - starts[i - 1]);
  }
  if (n <= 0) throw InputError("n must be positive, got " + std::to_string(n));
  if (starts.back() <= 0) throw InputError("the layout has no rows");
  if (!(rcond > 0.0 && rcond < 1.0))
    throw InputError("rcond must be in (0, 1), got " + fmt(rcond));
  if (!(damping >= 0.0 && damping < kInf))
    throw InputError("damping must be finite and >= 0, got " + fmt(damping));
  return m_max;
}

// The flops of cholesky_lower on n × n, as its loops are written
double cholesky_flops(Index n) {
  double flops = 0.0;
  for (Index a = 0; a < n; ++a)
    for (Index b = 0; b <= a; ++b) flops += 2.0 * static_cast<double>(b) + 1.0;
  return flops;
}

// Throws InputError naming the first entry of M (n × n) that is not finite
void check_mass_matrix(const double* mass, Index n) {
  for (Index a = 0; a < n; ++a)
    for (Index b = 0; b < n; ++b)
      if (!std::isfinite(mass[a * n + b]))
        throw InputError("mass_matrix[" + std::to_string(a) + ", " + std::to_string(b) +
                         "] is not finite (" + fmt(mass[a * n + b]) + ")");
}

}  // namespace prioik::projection
