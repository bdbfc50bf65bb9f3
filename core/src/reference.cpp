// The exact lexicographic least squares by nested SVD null spaces, compiled
// (closed_form.hpp, ReferenceSolver).
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
// Jacobi sweeps before giving up on the last pairs' orthogonality (a sweep converges
// quadratically once the columns are nearly orthogonal; 6-10 sweeps are the rule)
constexpr Index kMaxSweeps = 60;
// the steps of iterative refinement an undamped level's step gets (formulations.nullspace
// REFINEMENT_STEPS)
constexpr int kRefinementSteps = 2;

inline double f(Index v) { return static_cast<double>(v); }

// One-sided (Hestenes) Jacobi on the p rows of Gt (m entries each): a rotation of every
// pair of rows whose cosine exceeds m ε, sweep after sweep until none does; Wt (p × p,
// from I) receives the same rotations, so that Gt_out = Wt Gt_in with Wt orthogonal.
// sigma = the rows' norms after it. Returns the flops; *sweeps and *rotations count the
// sweeps and the rotations.
double jacobi_rows(MatrixRef Gt, MatrixRef Wt, double* sigma, Index* sweeps, Index* rotations) {
  const Index p = Gt.rows, m = Gt.cols;
  const double threshold = f(std::max<Index>(m, 1)) * kEps;
  for (Index a = 0; a < p; ++a)
    for (Index b = 0; b < p; ++b) Wt(a, b) = a == b ? 1.0 : 0.0;
  double flops = 0.0;
  for (Index sweep = 0; sweep < kMaxSweeps; ++sweep) {
    bool rotated = false;
    ++*sweeps;
    for (Index i = 0; i + 1 < p; ++i) {
      for (Index j = i + 1; j < p; ++j) {
        double* gi = Gt.row(i);
        double* gj = Gt.row(j);
        const double alpha = dot(gi, gi, m), beta = dot(gj, gj, m), gamma = dot(gi, gj, m);
        flops += 6.0 * f(m) + 3.0;
        if (!(std::fabs(gamma) > threshold * std::sqrt(alpha) * std::sqrt(beta))) continue;
        // t = tan θ, the smaller root of t² + 2ζ t − 1 = 0: the pair made orthogonal
        const double zeta = (beta - alpha) / (2.0 * gamma);
        const double sign = zeta >= 0.0 ? 1.0 : -1.0;
        const double az = std::fabs(zeta);
        const double t = az > 1e150 ? 0.5 / zeta : sign / (az + std::sqrt(1.0 + zeta * zeta));
        const double c = 1.0 / std::sqrt(1.0 + t * t), s = c * t;
        flops += 12.0;
        rotate_rows(gi, gj, m, c, s);
        rotate_rows(Wt.row(i), Wt.row(j), p, c, s);
        flops += 6.0 * f(m + p);
        rotated = true;
        ++*rotations;
      }
    }
    if (!rotated) break;
  }
  for (Index a = 0; a < p; ++a) sigma[a] = std::sqrt(dot(Gt.row(a), Gt.row(a), m));
  return flops + f(p) * (2.0 * f(m) + 1.0);
}

// z[0:d] ← z H_0 H_1 … H_{count-1} (a row vector times the reflectors, in order)
double reflect_row(const Reflectors& H, double* z, Index d) {
  double flops = 0.0;
  for (Index t = 0; t < H.count; ++t) {
    const Index q = H.pos[t];
    const double* v = H.V.row(t) + q;
    const double g = H.beta[t] * dot(v, z + q, d - q);
    for (Index c = 0; c < d - q; ++c) z[q + c] -= g * v[c];
    flops += 4.0 * f(d - q) + 1.0;
  }
  return flops;
}

}  // namespace

ReferenceWorkspace::ReferenceWorkspace(Index n, Index m_max)
    : Z(n * n, 0.0),
      Gt(n * std::max<Index>(m_max, 1), 0.0),
      Wt(n * n, 0.0),
      sigma(n, 0.0),
      order(n, 0),
      gain(n, 0.0),
      res0(std::max<Index>(m_max, 1), 0.0),
      row(n, 0.0),
      G(n * n, 0.0),
      WZ(n * n, 0.0) {}

ReferenceSolver::ReferenceSolver(std::vector<Index> starts, Index n, ReferenceOptions options)
    : ProjectionSolver(std::move(starts), n, options.rcond, 0.0), options_(std::move(options)) {
  if (options_.level_damping.empty()) options_.level_damping.assign(k_, 0.0);
  if (static_cast<Index>(options_.level_damping.size()) != k_)
    throw InputError("level_damping must hold " + std::to_string(k_) + " values (one μ² per "
                     "level), got " + std::to_string(options_.level_damping.size()));
  for (double mu2 : options_.level_damping)
    if (!(mu2 >= 0.0 && mu2 < kInf))
      throw InputError("level_damping must be finite and >= 0, got " + projection::fmt(mu2));
  if (!options_.metric.empty()) {
    if (static_cast<Index>(options_.metric.size()) != n_ * n_)
      throw InputError("metric must have shape (" + std::to_string(n_) + ", " +
                       std::to_string(n_) + ")");
    for (double w : options_.metric)
      if (!std::isfinite(w)) throw InputError("metric must be finite, got " + projection::fmt(w));
  }
  nested_ = ReferenceWorkspace(n_, static_cast<Index>(work_.e.size()));
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.ranks.assign(k_, 0);
  result_.ambiguous.assign(k_, 0);
}

double ReferenceSolver::level_step(Index lev, Index s0, Index m, Index r) {
  ProjectionWorkspace& ws = work_;
  const Index n = n_, p = r;
  const double mu2 = options_.level_damping[lev];
  MatrixRef Zq{nested_.Z.data(), n, n, n};
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  double* step = ws.step.data();
  double* t = ws.aux.data();
  double flops = 0.0;
  for (int pass = 0; pass <= (mu2 > 0.0 ? 0 : kRefinementSteps); ++pass) {
    if (pass > 0) {
      // the correction V_r Σ_r⁻² V_rᵀ Mᵀ (c − M y), M y = A (Z y) formed row by row
      for (Index i = 0; i < m; ++i) ws.e[i] = nested_.res0[i] - dot(B.row(i), step, n);
      std::fill(t, t + n, 0.0);
      for (Index i = 0; i < m; ++i) {
        const double ri = ws.e[i];
        const double* bi = B.row(i);
        for (Index j = 0; j < n; ++j) t[j] += ri * bi[j];
      }
      flops += 4.0 * f(m * n) + f(m);
      for (Index l = 0; l < p; ++l) {
        const Index col = nested_.order[l];
        double h = 0.0;
        for (Index a = 0; a < n; ++a) h += Zq(a, col) * t[a];
        nested_.gain[l] += h / (nested_.sigma[col] * nested_.sigma[col]);
        flops += 2.0 * f(n) + 3.0;
      }
    }
    // y = Σ_l gain_l Zq[:, order_l]
    std::fill(step, step + n, 0.0);
    for (Index a = 0; a < n; ++a) {
      const double* za = Zq.row(a);
      double acc = 0.0;
      for (Index l = 0; l < p; ++l) acc += nested_.gain[l] * za[nested_.order[l]];
      step[a] = acc;
    }
    flops += 2.0 * f(n * p);
  }
  for (Index a = 0; a < n; ++a) result_.x[a] += step[a];
  return flops + f(n);
}

double ReferenceSolver::solve_level(Index lev, bool /*last*/) {
  ProjectionWorkspace& ws = work_;
  ReferenceResult& res = result_;
  const Index s0 = starts_[lev], m = starts_[lev + 1] - s0, n = n_, d = nested_.d;
  const double tol = options_.rcond * ws.scales[lev];
  if (d == 0 || m == 0 || !(tol > 0.0)) return 0.0;   // nothing left, or a zero level
  MatrixRef Z{nested_.Z.data(), n, d, n};
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  MatrixRef M{ws.J.data(), m, d, n};
  // M_i = A_i Z_i and the level's residual c − A_i x
  double flops = 2.0 * f(m * n * d) + 2.0 * f(m * n) + f(m);
  for (Index i = 0; i < m; ++i) {
    const double* bi = B.row(i);
    double* mi = M.row(i);
    std::fill(mi, mi + d, 0.0);
    for (Index a = 0; a < n; ++a) {
      const double w = bi[a];
      const double* za = Z.row(a);
      for (Index j = 0; j < d; ++j) mi[j] += w * za[j];
    }
    nested_.res0[i] = ws.c[s0 + i] - dot(bi, res.x.data(), n);
    ws.e[i] = nested_.res0[i];
  }
  // M = Pᵀ [L 0] Q, then L W = U Σ (Jacobi on L's columns, held as Gt's rows)
  Reflectors H{MatrixRef{ws.V.data(), n, n, n}, ws.beta.data(), ws.pos.data(), 0};
  Index p = 0;
  double min_pivot = 0.0, margin = kInf;
  flops += projection::pivoted_lq(M, ws.e.data(), std::numeric_limits<double>::min(),
                                  ws.norms.data(), H, &p, &min_pivot, &margin);
  MatrixRef Gt{nested_.Gt.data(), p, m, m};
  for (Index j = 0; j < p; ++j)
    for (Index i = 0; i < m; ++i) Gt(j, i) = M(i, j);
  MatrixRef Wt{nested_.Wt.data(), p, p, p};
  flops += jacobi_rows(Gt, Wt, nested_.sigma.data(), &res.sweeps, &res.rotations);
  // the rank rule and the ambiguity of the readable path, on σ
  Index r = 0, nulls = 0;
  for (Index j = 0; j < p; ++j) {
    const double s = nested_.sigma[j];
    if (s > tol / kAmbiguity && s <= tol * kAmbiguity) res.ambiguous[lev] = 1;
    if (s > tol) nested_.order[r++] = j;
  }
  res.ranks[lev] = r;
  if (r == 0) return flops;                     // nested_.Z{i+1} = Z_i (the same span)
  for (Index j = 0; j < p; ++j)
    if (!(nested_.sigma[j] > tol)) nested_.order[r + nulls++] = j;
  for (Index j = p; j < d; ++j) nested_.order[r + nulls++] = j;
  // the step's coordinates Σ_r⁻¹ U_rᵀ e = (Gt_j · e) / σ_j² (σ/(σ² + μ²) when damped)
  const double mu2 = options_.level_damping[lev];
  for (Index l = 0; l < r; ++l) {
    const Index j = nested_.order[l];
    nested_.gain[l] = dot(Gt.row(j), ws.e.data(), m) / (nested_.sigma[j] * nested_.sigma[j] + mu2);
  }
  flops += f(r) * (2.0 * f(m) + 3.0);
  // Zq = Z Qᵀ [W 0; 0 I]: the singular directions of M_i mapped by Z
  for (Index a = 0; a < n; ++a) {
    double* za = Z.row(a);
    flops += reflect_row(H, za, d);
    for (Index j = 0; j < p; ++j) nested_.row[j] = dot(Wt.row(j), za, p);
    std::copy(nested_.row.begin(), nested_.row.begin() + p, za);
  }
  flops += 2.0 * f(n * p * p);
  flops += level_step(lev, s0, m, r);
  // nested_.Z{i+1} = the columns of Zq past the kept ones, in nested_.order
  for (Index a = 0; a < n; ++a) {
    double* za = Z.row(a);
    for (Index l = 0; l < d - r; ++l) nested_.row[l] = za[nested_.order[r + l]];
    std::copy(nested_.row.begin(), nested_.row.begin() + (d - r), za);
  }
  nested_.d = d - r;
  return flops;
}

double ReferenceSolver::metric_step() {
  const Index n = n_, d = nested_.d;
  const double* W = options_.metric.data();
  MatrixRef Z{nested_.Z.data(), n, d, n};
  MatrixRef WZ{nested_.WZ.data(), n, d, n};
  MatrixRef G{nested_.G.data(), d, d, n};
  double* x = result_.x.data();
  double* wx = nested_.row.data();
  // WZ = W_x Z, G = Zᵀ W_x Z, rhs = −Zᵀ W_x x
  for (Index a = 0; a < n; ++a) {
    double* wz = WZ.row(a);
    std::fill(wz, wz + d, 0.0);
    for (Index b = 0; b < n; ++b) {
      const double w = W[a * n + b];
      const double* zb = Z.row(b);
      for (Index j = 0; j < d; ++j) wz[j] += w * zb[j];
    }
    wx[a] = dot(W + a * n, x, n);
  }
  for (Index i = 0; i < d; ++i)
    for (Index j = 0; j < d; ++j) {
      double acc = 0.0;
      for (Index a = 0; a < n; ++a) acc += Z(a, i) * WZ(a, j);
      G(i, j) = acc;
    }
  double* rhs = nested_.gain.data();
  for (Index j = 0; j < d; ++j) {
    double acc = 0.0;
    for (Index a = 0; a < n; ++a) acc += Z(a, j) * wx[a];
    rhs[j] = -acc;
  }
  double flops = 2.0 * f(n * n * d) + 2.0 * f(n * n) + 2.0 * f(d * d * n) + 2.0 * f(n * d) +
                 f(d) + projection::cholesky_flops(d);
  result_.metric_positive_definite = cholesky_lower(G, d);
  if (!result_.metric_positive_definite) return flops;
  cholesky_solve(G, rhs, d);
  for (Index a = 0; a < n; ++a) x[a] += dot(Z.row(a), rhs, d);
  return flops + 2.0 * f(d * d) + f(d) + 2.0 * f(n * d) + f(n);
}

const ReferenceResult& ReferenceSolver::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  ReferenceResult& res = result_;
  res.sweeps = 0;
  res.rotations = 0;
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  std::fill(res.ambiguous.begin(), res.ambiguous.end(), 0);
  res.metric_positive_definite = true;
  res.null_space_dim = 0;
  res.solved = open_solve(data, res);
  if (!res.solved) return res;
  for (Index a = 0; a < n_; ++a)
    for (Index b = 0; b < n_; ++b) nested_.Z[a * n_ + b] = a == b ? 1.0 : 0.0;
  nested_.d = n_;
  double flops = run_levels(0);
  if (!options_.metric.empty() && nested_.d > 0) flops += metric_step();
  res.null_space_dim = nested_.d;
  close_solve(data, flops, res);
  return res;
}

}  // namespace prioik
