// Recursive null-space projection, compiled (closed_form.hpp).
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <utility>

#include "prioik/closed_form.hpp"

namespace prioik {

namespace {

// Marks a solver busy for the scope of a solve.
class BusyGuard {
 public:
  explicit BusyGuard(std::atomic<bool>& busy) : busy_(busy) {
    if (busy_.exchange(true, std::memory_order_acquire))
      throw ConcurrentUse("a prepared solver serves one thread at a time: another thread is "
                          "solving with it");
  }
  ~BusyGuard() { busy_.store(false, std::memory_order_release); }
  BusyGuard(const BusyGuard&) = delete;
  BusyGuard& operator=(const BusyGuard&) = delete;

 private:
  std::atomic<bool>& busy_;
};

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Python's min(a, b): a unless b < a
inline double first_min(double a, double b) { return b < a ? b : a; }

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
    double* pivot = J.row(r);
    const double alpha = pivot[r] >= 0.0 ? -norm : norm;
    double* v = H.V.row(r);
    v[r] = pivot[r] - alpha;
    double vtv = v[r] * v[r];
    for (Index j = r + 1; j < n; ++j) {
      v[j] = pivot[j];
      vtv += v[j] * v[j];
    }
    const double bt = vtv > 0.0 ? 2.0 / vtv : 0.0;
    flops += 2.0 * (n - r) + 2.0;
    H.beta[r] = bt;
    H.pos[r] = r;
    pivot[r] = alpha;
    for (Index j = r + 1; j < n; ++j) pivot[j] = 0.0;
    const double* vr = v + r;
    const Index w = n - r;
    for (Index i = r + 1; i < m; ++i) {
      double* row = J.row(i) + r;
      const double dt = dot(row, vr, w);
      flops += 2.0 * w;
      if (dt != 0.0) {
        const double f = bt * dt;
        for (Index j = 0; j < w; ++j) row[j] -= f * vr[j];
        flops += 2.0 * w + 1.0;
      }
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
                      NullspaceWorkspace& ws) {
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

NullspaceWorkspace::NullspaceWorkspace(Index M, Index n, Index k, Index m_max)
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
      spare(small_least_squares_scratch(m_max, std::min(m_max, n)), 0.0) {
  result.x.assign(n, 0.0);
  result.residuals.assign(k, 0.0);
  result.min_pivots.assign(k, 0.0);
  result.margins.assign(k, kInf);
  result.ranks.assign(k, 0);
}

NullspaceSolver::NullspaceSolver(std::vector<Index> starts, Index n, NullspaceOptions options)
    : starts_(std::move(starts)), n_(n), options_(options) {
  if (starts_.empty() || starts_[0] != 0)
    throw InputError("starts must hold the k + 1 row offsets of the levels, from 0");
  Index m_max = 0;
  for (std::size_t i = 1; i < starts_.size(); ++i) {
    if (starts_[i] < starts_[i - 1]) throw InputError("starts must be non-decreasing");
    m_max = std::max(m_max, starts_[i] - starts_[i - 1]);
  }
  if (n_ <= 0) throw InputError("n must be positive, got " + std::to_string(n_));
  k_ = static_cast<Index>(starts_.size()) - 1;
  M_ = starts_.back();
  if (M_ <= 0) throw InputError("the layout has no rows");
  if (!(options_.rcond > 0.0 && options_.rcond < 1.0))
    throw InputError("rcond must be in (0, 1), got " + fmt(options_.rcond));
  if (!(options_.damping >= 0.0 && options_.damping < kInf))
    throw InputError("damping must be finite and >= 0, got " + fmt(options_.damping));
  work_ = NullspaceWorkspace(M_, n_, k_, m_max);
}

double NullspaceSolver::solve_level(Index lev, bool last) {
  NullspaceWorkspace& ws = work_;
  NullspaceResult& res = ws.result;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_;
  const double tol = options_.rcond * ws.scales[lev];
  const bool identity = !ws.projected;                 // N_{i-1} = I: Ĵ_i = A_i
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  MatrixRef N{ws.N.data(), n, n, n};
  MatrixRef J{ws.J.data(), m, n, n};
  double flops = 0.0;
  // Ĵ_i = A_i N_{i-1} (N symmetric: row j of N is its column j) and e = b_i − A_i x
  if (identity) {
    std::copy(B.data, B.data + m * n, J.data);
  } else {
    for (Index i = 0; i < m; ++i) flops += multiply_rows(N, B.row(i), J.row(i));
  }
  flops += multiply_rows(B, res.x.data(), ws.e.data());
  for (Index i = 0; i < m; ++i) ws.e[i] = ws.c[s0 + i] - ws.e[i];
  flops += static_cast<double>(m);
  if (!(tol > 0.0)) return flops;                      // a zero level keeps nothing
  Reflectors H{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0};
  Index r = 0;
  flops += pivoted_lq(J, ws.e.data(), tol, ws.norms.data(), H, &r, &res.min_pivots[lev],
                      &res.margins[lev]);
  res.ranks[lev] = r;
  if (r == 0) return flops;
  // the step Q_rᵀ z, reprojected by N_{i-1}
  double* step = ws.step.data();
  std::fill(step, step + n, 0.0);
  flops += level_unknowns(J, ws.e.data(), r, options_.damping, step, ws);
  flops += apply_leading_reflectors(H, r - 1, step, n);
  if (options_.reproject && !identity) {
    flops += multiply_rows(N, step, ws.aux.data());
    std::copy(ws.aux.begin(), ws.aux.end(), ws.step.begin());
  }
  for (Index j = 0; j < n; ++j) res.x[j] += step[j];
  flops += static_cast<double>(n);
  if (last) return flops;
  // N_i = N_{i-1} − V Vᵀ, V = Q e_l (l < r) re-orthonormalised inside range(N_{i-1})
  MatrixRef basis{ws.basis.data(), r, n, n};
  for (Index l = 0; l < r; ++l) {
    double* bl = basis.row(l);
    std::fill(bl, bl + n, 0.0);
    bl[l] = 1.0;
    flops += apply_leading_reflectors(H, l, bl, n);
    if (!identity) {
      flops += multiply_rows(N, bl, ws.aux.data());
      std::copy(ws.aux.begin(), ws.aux.end(), bl);
    }
  }
  if (!identity) flops += orthonormalize_rows(basis, r);
  flops += subtract_outer_products(N, basis, r);
  ws.projected = true;
  return flops;
}

const NullspaceResult& NullspaceSolver::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  NullspaceWorkspace& ws = work_;
  NullspaceResult& res = ws.result;
  const bool weights_ok = weigh_rows(data.A, data.b, data.sqrt_weight, M_, n_, ws.B.data(),
                                     ws.c.data());
  const bool scales_ok = level_scales(ws.B.data(), ws.c.data(), M_, n_, starts_.data(), k_,
                                      ws.scales.data());
  res.flops = 0.0;
  std::fill(res.x.begin(), res.x.end(), 0.0);
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  std::fill(res.min_pivots.begin(), res.min_pivots.end(), 0.0);
  std::fill(res.margins.begin(), res.margins.end(), kInf);
  res.solved = weights_ok && scales_ok;
  if (!res.solved) {
    check_stack_entries(data, M_, n_);     // a NaN, inf or √w ≤ 0 is an input error
    res.finite = res.ambiguous = false;
    return res;
  }
  for (Index a = 0; a < n_; ++a)
    for (Index b = 0; b < n_; ++b) ws.N[a * n_ + b] = a == b ? 1.0 : 0.0;
  ws.projected = false;
  double flops = 0.0;
  for (Index lev = 0; lev < k_; ++lev) flops += solve_level(lev, lev == k_ - 1);
  res.flops = flops;
  level_residuals(data.A, data.b, data.sqrt_weight, n_, starts_.data(), k_, res.x.data(),
                  res.residuals.data());
  double acc = 0.0;
  res.ambiguous = false;
  for (Index lev = 0; lev < k_; ++lev) {
    acc += res.residuals[lev];
    if (res.margins[lev] <= kAmbiguity) res.ambiguous = true;
  }
  res.finite = std::isfinite(acc);
  return res;
}

}  // namespace prioik
