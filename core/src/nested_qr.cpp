#include "prioik/nested_qr.hpp"

#include "prioik/flops.hpp"

#include <algorithm>
#include <cmath>

#include "vector_clones.hpp"

namespace prioik {

namespace {

inline double to_flops(Index v) { return static_cast<double>(v); }

// Python's min(a, b): a unless b < a
inline double first_min(double a, double b) { return b < a ? b : a; }

// The nested QR's progress through the levels.
struct Progress {
  Index col = 0;       // the free coordinates are col:n
  Index nref = 0;      // reflectors so far
  Index rot_end = 0;   // rows [rot_end, M) are a deferred unit-row level, not yet rotated
  double unit_s = -1;  // that level's magnitude
};

// A last level of unit rows is not rotated with the others: at its turn it is solved by
// the unit-rows step on its rows as given, or else brought through the reflectors then
// (the same operations, in the same order, as rotating it level by level).
void defer_unit_level(MatrixRef B, const Index* starts, Index k, const NestedQRParameters& p,
                      NestedQRWorkspace& ws, Progress& at) {
  const Index M = B.rows;
  at.rot_end = M;
  at.unit_s = -1.0;
  const bool bounded = p.step_bound != nullptr && k > 0 && p.step_bound[k - 1] > 0.0;
  if (k > 0 && p.rcond > 0.0 && !bounded && !p.selective() && starts[k - 1] < M) {
    at.unit_s = unit_rows_of(B, starts[k - 1], M, ws.cover.data(), p.row_columns);
    if (at.unit_s > 0.0) at.rot_end = starts[k - 1];
  }
}

// The deferred unit-row level (rows s0:s0+m) at its turn: true when the unit-rows step
// solved it (y[col:] written, every coordinate claimed); else its rows are rotated.
bool solve_unit_level(MatrixRef B, const double* c, Index s0, Index m, double tol,
                      NestedQRWorkspace& ws, Progress& at, Index* rank, double* margin) {
  const Index M = B.rows, n = B.cols;
  const Index d = n - at.col;
  const Index nu = n - m;
  double* y = ws.y.data();
  if (m >= d && nu + std::max<Index>(1, 2 * nu) <= M) {
    double* g = ws.norms.data();        // Sᵀ c / s² (x_p's part: y[:col])
    for (Index j = 0; j < n; ++j) {
      g[j] = 0.0;
      const Index i = ws.cover[j];
      if (i >= 0) g[j] = B(s0 + i, j) * c[s0 + i] / (at.unit_s * at.unit_s);
    }
    MatrixRef L{ws.L.data(), M, n, n};
    const Index got = unit_rows_solve(ws.cover.data(), g, at.col, y + at.col,
                                      ws.reflectors(at.nref), L.middle_rows(0, nu),
                                      L.middle_rows(nu, std::max<Index>(1, 2 * nu)), y,
                                      ws.ucols.data());
    const double unit_margin = got > 0 ? at.unit_s * std::sqrt(kUnitRowsGap) : at.unit_s;
    if (got >= 0 && unit_margin > kAmbiguity * tol) {
      *rank = d;
      *margin = unit_margin / tol;
      at.col = n;
      return true;
    }
    for (Index j = at.col; j < n; ++j) y[j] = 0.0;
  }
  const Reflectors H = ws.reflectors(at.nref);
  for (Index i = at.rot_end; i < M; ++i) apply_qt(B.row(i), n, H);
  at.rot_end = M;
  return false;
}

// The level's right-hand side in rotated coordinates, c_i - B_i[:, :col] y[:col], and its
// rows' squared norms on the free columns.
void level_rhs_and_norms(MatrixRef B, const double* c, Index s0, Index m, Index col,
                         NestedQRWorkspace& ws) {
  const Index n = B.cols;
  for (Index i = 0; i < m; ++i) {
    const double* row = B.row(s0 + i);
    ws.rhs[i] = c[s0 + i] - dot(row, ws.y.data(), col);
    ws.norms[i] = dot(row + col, row + col, n - col);
  }
}

// The row-pivoted LQ of the level's rows B[s0:s0+m, col:]: one reflector per row whose
// pivot norm exceeds tol, applied to the level's other rows and the levels below (up to
// rot_end). Returns the rank r; *margin is the rank decision's margin.
Index pivoted_lq_level(MatrixRef B, Index s0, Index m, double tol, NestedQRWorkspace& ws,
                       Progress& at, Index* rowperm, double* margin) {
  const Index n = B.cols;
  const Index col = at.col;
  const Index d = n - col;
  double* norms = ws.norms.data();
  double* rhs = ws.rhs.data();
  MatrixRef V{ws.V.data(), n, n, n};
  Index r = 0;
  double kept_min = kInf;
  while (r < m && r < d) {
    // pivot: the remaining row of largest norm on the free columns, its norm recomputed
    // exactly (downdating loses accuracy; the first pivot's is level_rhs_and_norms', the
    // same sum)
    Index p = argmax_from(norms, r, m);
    double exact = r == 0 ? norms[p]
                          : dot(B.row(s0 + p) + col + r, B.row(s0 + p) + col + r, d - r);
    if (!(std::sqrt(exact) > tol) && tol > 0.0) {
      // the downdated norms may have lost the largest remaining row (their cancellation
      // error is ~ε‖row‖², above the rows a heavy first pivot leaves): recompute them
      for (Index i = r; i < m; ++i) {
        const double* rest = B.row(s0 + i) + col + r;
        norms[i] = dot(rest, rest, d - r);
      }
      p = argmax_from(norms, r, m);
      exact = dot(B.row(s0 + p) + col + r, B.row(s0 + p) + col + r, d - r);
    }
    if (!(std::sqrt(exact) > tol) || tol <= 0.0) {
      if (tol > 0.0 && exact > 0.0) *margin = first_min(kept_min / tol, tol / std::sqrt(exact));
      break;
    }
    kept_min = first_min(kept_min, std::sqrt(exact));
    if (p != r) {
      swap_rows(B, s0 + r, s0 + p);
      swap_entries(rhs, r, p);
      swap_entries(norms, r, p);
      if (rowperm != nullptr) swap_entries(rowperm, s0 + r, s0 + p);
    }
    const Index q = col + r;
    // H = I − β v vᵀ mapping the pivot row's entries q: onto α e_q, applied up to its
    // support's end (ws.end)
    double* v = V.row(at.nref);
    Index last = q + 1;
    const double bt = make_row_reflector(B.row(s0 + r), q, n, exact, v, &last);
    ws.beta[at.nref] = bt;
    ws.pos[at.nref] = q;
    ws.end[at.nref] = last;
    // applied to the level's other rows and to every lower level's rows
    for (Index i = s0 + r + 1; i < at.rot_end; ++i)
      apply_row_reflector(B.row(i) + q, v + q, last - q, bt);
    for (Index i = r + 1; i < m; ++i) norms[i] -= B(s0 + i, q) * B(s0 + i, q);
    ++at.nref;
    ++r;
  }
  if (tol > 0.0) *margin = first_min(*margin, kept_min / tol);
  return r;
}

// L[:m, :r] = the level's lower-trapezoidal rows on its r new coordinates
void copy_trapezoid(MatrixRef B, Index s0, Index m, Index r, Index col, MatrixRef L) {
  for (Index i = 0; i < m; ++i)
    for (Index j = 0; j < r; ++j) L(i, j) = j <= i ? B(s0 + i, col + j) : 0.0;
}

// The level's r new unknowns y[col:col+r] from its trapezoid: forward substitution, or a
// (damped) least squares, then the trust-region step when the level's step exceeds its
// bound. Returns the level's μ².
double solve_level_unknowns(MatrixRef B, Index s0, Index m, Index r, double scale, Index lev,
                            const NestedQRParameters& p, bool trust_region,
                            NestedQRWorkspace& ws, Index col) {
  const Index n = B.cols;
  double* y = ws.y.data();
  const double* rhs = ws.rhs.data();
  MatrixRef L{ws.L.data(), B.rows, n, n};
  double mu2 = 0.0;
  if (p.selective()) {
    const double sig = std::fabs(B(s0 + r - 1, col + r - 1));   // RRQR estimate of σ_min
    const double eps_abs = p.singular_threshold * scale;
    if (sig < eps_abs) {
      const double q = sig / eps_abs;
      mu2 = p.level_damping * (1.0 - q * q);
    }
  }
  if (r == m && mu2 == 0.0) {
    for (Index i = 0; i < r; ++i) {
      double acc = rhs[i];
      const double* row = B.row(s0 + i) + col;
      for (Index j = 0; j < i; ++j) acc -= row[j] * y[col + j];
      y[col + i] = acc / row[i];
    }
  } else {
    copy_trapezoid(B, s0, m, r, col, L);
    small_least_squares(L, rhs, m, r, mu2, y + col, ws.spare.data());
  }
  if (trust_region && p.step_bound[lev] > 0.0) {
    double znorm = 0.0;
    for (Index j = 0; j < r; ++j) znorm += y[col + j] * y[col + j];
    if (std::sqrt(znorm) > p.step_bound[lev]) {
      copy_trapezoid(B, s0, m, r, col, L);
      mu2 = bounded_step(L, rhs, m, r, mu2, p.step_bound[lev], y + col, ws.svd.data());
    }
  }
  return mu2;
}

// One-sided Jacobi SVD of W (r rows of m: the columns of L held transposed), rotating the
// rows of Vt (r × r) alike: afterwards W's rows are orthogonal, row j = σ_j u_jᵀ, and
// L = Σ_j σ_j u_j (Vt row j)ᵀ.
void jacobi_svd(MatrixRef W, MatrixRef Vt) {
  const Index r = W.rows, m = W.cols;
  for (Index a = 0; a < r; ++a)
    for (Index b = 0; b < r; ++b) Vt(a, b) = a == b ? 1.0 : 0.0;
  constexpr double eps = 2.220446049250313e-16;
  for (int sweep = 0; sweep < 60; ++sweep) {
    bool rotated = false;
    for (Index p = 0; p + 1 < r; ++p) {
      for (Index q = p + 1; q < r; ++q) {
        double* wp = W.row(p);
        double* wq = W.row(q);
        const double alpha = dot(wp, wp, m), beta = dot(wq, wq, m), gamma = dot(wp, wq, m);
        if (gamma == 0.0 || std::fabs(gamma) <= eps * std::sqrt(alpha) * std::sqrt(beta)) continue;
        rotated = true;
        const double zeta = (beta - alpha) / (2.0 * gamma);
        const double t = (zeta >= 0.0 ? 1.0 : -1.0) / (std::fabs(zeta) + std::hypot(1.0, zeta));
        const double cs = 1.0 / std::sqrt(1.0 + t * t);
        const double sn = cs * t;
        rotate_rows(wp, wq, m, cs, sn);
        rotate_rows(Vt.row(p), Vt.row(q), r, cs, sn);
      }
    }
    if (!rotated) break;
  }
}

}  // namespace

NestedQRWorkspace::NestedQRWorkspace(Index rows, Index cols)
    : M(rows),
      n(cols),
      V(cols * cols),
      beta(cols),
      pos(cols),
      end(cols),
      y(cols),
      norms(std::max(rows, cols)),
      rhs(rows),
      L(rows * cols),
      spare(cols * (rows + cols) + rows + 2 * cols),
      svd(bounded_step_scratch(rows, cols)),
      iscratch(cols),
      cover(cols),
      ucols(cols) {}

PRIOIK_VECTOR_CLONES
double bounded_step(MatrixRef L, const double* rhs, Index m, Index r, double mu2_min,
                    double step_bound, double* z, double* scratch) {
  MatrixRef W{scratch, r, m, m};
  MatrixRef Vt{scratch + r * m, r, r, r};
  double* s2 = scratch + r * m + r * r;    // σ_j²
  double* c = s2 + r;                      // σ_j u_jᵀ rhs
  for (Index j = 0; j < r; ++j)
    for (Index i = 0; i < m; ++i) W(j, i) = L(i, j);
  jacobi_svd(W, Vt);
  for (Index j = 0; j < r; ++j) {
    s2[j] = dot(W.row(j), W.row(j), m);
    c[j] = dot(W.row(j), rhs, m);
  }
  double mu2 = mu2_min;
  double* w = z;                           // the step in the SVD basis, until z is written
  double wbuf_norm = 0.0;
  for (Index j = 0; j < r; ++j) {
    w[j] = c[j] / (s2[j] + mu2);
    wbuf_norm += w[j] * w[j];
  }
  double norm = std::sqrt(wbuf_norm);
  if (norm > step_bound) {
    for (int it = 0; it < 100; ++it) {
      double dn = 0.0;
      for (Index j = 0; j < r; ++j) dn += w[j] * w[j] / (s2[j] + mu2);
      dn = -dn / norm;
      mu2 = std::max(mu2 + (1.0 / norm - 1.0 / step_bound) * norm * norm / dn, mu2_min);
      double acc = 0.0;
      for (Index j = 0; j < r; ++j) {
        w[j] = c[j] / (s2[j] + mu2);
        acc += w[j] * w[j];
      }
      norm = std::sqrt(acc);
      if (std::fabs(norm - step_bound) <= 1e-12 * step_bound) break;
    }
  }
  // z = Σ_j w_j (Vt row j); w lives in z: copy it aside into c (no longer needed)
  for (Index j = 0; j < r; ++j) c[j] = w[j];
  for (Index i = 0; i < r; ++i) {
    double acc = 0.0;
    for (Index j = 0; j < r; ++j) acc += Vt(j, i) * c[j];
    z[i] = acc;
  }
  return mu2;
}

PRIOIK_VECTOR_CLONES
void nested_qr(MatrixRef B, double* c, const Index* starts, Index k, const double* scales,
               const NestedQRParameters& params, bool trust_region, NestedQRWorkspace& ws,
               const NestedQROutput& out) {
  const Index n = B.cols;
  Progress at;
  std::fill(ws.y.begin(), ws.y.end(), 0.0);   // coordinates no level claims stay 0
  defer_unit_level(B, starts, k, params, ws, at);
  const bool bounded_any = trust_region && params.step_bound != nullptr;
  double flops = 0.0;     // by formula over the sizes each level used (flops.hpp)
  for (Index lev = 0; lev < k; ++lev) {
    const Index s0 = starts[lev];
    const Index m = starts[lev + 1] - s0;
    out.ranks[lev] = 0;
    out.level_mu2[lev] = 0.0;
    out.margins[lev] = kInf;
    if (m == 0 || at.col >= n) continue;
    const double tol = params.rcond * scales[lev];
    if (lev == k - 1 && at.rot_end < B.rows) {
      const Index col = at.col;
      const bool solved = solve_unit_level(B, c, s0, m, tol, ws, at, &out.ranks[lev],
                                           &out.margins[lev]);
      flops += solved ? unit_rows_flops(m, n, col, ws.pos.data(), at.nref)
                      : to_flops(m) * reflectors_flops(ws.pos.data(), at.nref, n);
      if (solved) continue;
    }
    level_rhs_and_norms(B, c, s0, m, at.col, ws);
    const Index d = n - at.col;
    const bool level_bounded = bounded_any && params.step_bound[lev] > 0.0;
    if (m >= d && !level_bounded && !params.selective() &&
        full_rank_least_squares(B, s0, m, at.col, ws.rhs.data(), tol, ws.y.data(),
                                &out.margins[lev], ws.spare.data(), ws.iscratch.data())) {
      out.ranks[lev] = d;
      out.margins[lev] = out.margins[lev] / tol;
      flops += to_flops(m) * (2.0 * to_flops(n) + 1.0) + full_rank_least_squares_flops(m, d);
      at.col = n;
      continue;
    }
    out.margins[lev] = kInf;    // (a full-rank attempt that failed wrote its pivots)
    const Index r = pivoted_lq_level(B, s0, m, tol, ws, at, out.rowperm, &out.margins[lev]);
    out.ranks[lev] = r;
    flops += pivoted_lq_level_flops(m, n, at.col, r, at.rot_end - (s0 + m));
    if (r == 0) continue;
    out.level_mu2[lev] = solve_level_unknowns(B, s0, m, r, scales[lev], lev, params,
                                              bounded_any, ws, at.col);
    flops += r == m && out.level_mu2[lev] == 0.0
                 ? to_flops(r * r)
                 : small_least_squares_flops(m, r, out.level_mu2[lev] > 0.0);
    at.col += r;
  }
  for (Index j = 0; j < n; ++j) out.x[j] = ws.y[j];
  apply_q(out.x, n, ws.reflectors(at.nref));
  flops += reflectors_flops(ws.pos.data(), at.nref, n);
  if (out.flops != nullptr) *out.flops = flops;
}

}  // namespace prioik
