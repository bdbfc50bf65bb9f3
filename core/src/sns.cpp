// Saturation in the Null Space, compiled (closed_form.hpp, SnsSolver): the readable
// path's rounds (formulations/sns.py) on the projector recursion's steps.
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "prioik/closed_form.hpp"
#include "projection_steps.hpp"

namespace prioik {

namespace {

constexpr double kMaxFinite = std::numeric_limits<double>::max();
// scales within this factor of max(1, |s|) of each other are one: joints leaving their
// bounds at such scales leave them together (the lowest column goes first), and a scaling
// interval [s_min, s_t] that much narrower than empty is the point s_t (formulations.sns
// SATURATION_TIE)
constexpr double kSaturationTie = 1e-9;

// kSaturationTie at the scale s (0 where s is not finite)
inline double tie_at(double s) {
  return std::isfinite(s) ? kSaturationTie * std::max(1.0, std::fabs(s)) : 0.0;
}

inline double f(Index v) { return static_cast<double>(v); }

// p = 0, 1, …, m − 1 (a row-pivoted LQ permutes it with the rows: then p[i] is the row
// that became row i)
void identity_order(double* p, Index m) {
  for (Index i = 0; i < m; ++i) p[i] = static_cast<double>(i);
}

// ‖B v − c‖ over B's rows; flops 2 m n + 2 m + 1
double residual_norm(MatrixRef B, const double* c, const double* v) {
  double acc = 0.0;
  for (Index i = 0; i < B.rows; ++i) {
    const double r = dot(B.row(i), v, B.cols) - c[i];
    acc += r * r;
  }
  return std::sqrt(acc);
}

// numpy.nan_to_num(v, nan=fill): NaN → fill, ±inf → ±the largest finite double
inline double nan_to_num(double v, double fill) {
  if (std::isnan(v)) return fill;
  if (v == kInf) return kMaxFinite;
  if (v == -kInf) return -kMaxFinite;
  return v;
}

// numpy.clip(v, lo, hi)
inline double clip(double v, double lo, double hi) { return std::min(std::max(v, lo), hi); }

}  // namespace

SnsWorkspace::SnsWorkspace(Index n, Index m_max)
    : tol(n, 0.0), x_free(n, 0.0), x_new(n, 0.0), best(n, 0.0), xs(n, 0.0), cvec(n, 0.0),
      a(n, 0.0), corr(n, 0.0), u(n, 0.0), x_sat(n, 0.0), col_hi(n, 0.0), free(n, 1),
      Pbar(n * n, 0.0), Jm(m_max * n, 0.0), perm_m(std::max(m_max, n), 0.0), Vm(n * n, 0.0),
      beta_m(n, 0.0), pos_m(n, 0), Jb(n * n, 0.0), perm_b(n, 0.0), Vb(n * n, 0.0),
      beta_b(n, 0.0), pos_b(n, 0), y(std::max(m_max, n), 0.0), v(n, 0.0) {}

SnsSolver::SnsSolver(std::vector<Index> starts, Index n, SnsOptions options)
    : ProjectionSolver(std::move(starts), n, options.rcond, 0.0), options_(options) {
  if (!(options_.bound_tolerance >= 0.0 && options_.bound_tolerance < kInf))
    throw InputError("bound_tolerance must be finite and >= 0, got " +
                     projection::fmt(options_.bound_tolerance));
  if (options_.max_saturations < -1)
    throw InputError("max_saturations must be >= 0 (or -1: the bounded columns), got " +
                     std::to_string(options_.max_saturations));
  const Index m_max = static_cast<Index>(work_.e.size());
  work_ = ProjectionWorkspace(M_, n_, k_, std::max(m_max, n_));   // B has up to n rows
  rounds_ = SnsWorkspace(n_, m_max);
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.task_scaling.assign(k_, 1.0);
  result_.margins.assign(k_, kInf);
  result_.ranks.assign(k_, 0);
  result_.iterations.assign(k_, 0);
  result_.saturated.assign(k_ * n_, 0);
  result_.saturated_count.assign(k_, 0);
  result_.lower.assign(n_, -kInf);
  result_.upper.assign(n_, kInf);
}

bool SnsSolver::read_bounds(const StackArrays& data, const double* lower, const double* upper) {
  SnsWorkspace& rw = rounds_;
  SnsResult& res = result_;
  const Index n = n_;
  std::fill(res.lower.begin(), res.lower.end(), -kInf);
  std::fill(res.upper.begin(), res.upper.end(), kInf);
  const Index rows = options_.bounds_level ? starts_[1] : 0;
  for (Index i = 0; i < rows; ++i) {
    const double lo = lower[i], up = upper[i];
    if (std::isnan(lo) || std::isnan(up) || lo == kInf || up == -kInf || lo > up)
      throw InputError("the bounds of row " + std::to_string(i) + " are not an interval (" +
                       projection::fmt(lo) + ", " + projection::fmt(up) + ")");
    const double* row = data.A + i * n;
    Index col = -1, count = 0;
    for (Index j = 0; j < n; ++j)
      if (row[j] != 0.0) {
        if (count == 0) col = j;
        ++count;
      }
    if (count != 1) {
      res.bounds = SnsBounds::not_single_column;
      res.bad_entry = i;
      return false;
    }
    const double c = row[col];
    const double lo_x = c > 0.0 ? lo / c : up / c, up_x = c > 0.0 ? up / c : lo / c;
    res.lower[col] = std::max(res.lower[col], lo_x);
    res.upper[col] = std::min(res.upper[col], up_x);
  }
  rw.bounded = 0;
  for (Index j = 0; j < n; ++j) {
    if (res.lower[j] > res.upper[j]) {
      res.bounds = SnsBounds::empty_box;
      res.bad_entry = j;
      return false;
    }
    const double lo = std::fabs(res.lower[j]), up = std::fabs(res.upper[j]);
    rw.tol[j] = options_.bound_tolerance *
              std::max(1.0, std::max(lo == kInf ? 0.0 : lo, up == kInf ? 0.0 : up));
    if (res.lower[j] != -kInf || res.upper[j] != kInf) ++rw.bounded;
  }
  return true;
}

bool SnsSolver::feasible(const double* v) const {
  const SnsWorkspace& rw = rounds_;
  for (Index j = 0; j < n_; ++j)
    if (!(v[j] >= result_.lower[j] - rw.tol[j]) || !(v[j] <= result_.upper[j] + rw.tol[j]))
      return false;
  return true;
}

double SnsSolver::scale_interval(double* s_min, double* s_max) {
  SnsWorkspace& rw = rounds_;
  const Index n = n_;
  const double* lower = result_.lower.data();
  const double* upper = result_.upper.data();
  double peak = 0.0;
  for (Index j = 0; j < n; ++j) peak = std::max(peak, std::fabs(rw.a[j]));
  const double small = 1e-14 * std::max(1.0, peak);
  // a saturated column has a = 0 exactly (its row of P̄ is zero): whatever rounding left
  // in it, it takes no part
  double lo_max = -kInf, hi_min = kInf;
  for (Index j = 0; j < n; ++j) {
    const double a = rw.a[j], c = rw.cvec[j];
    double s_lo, s_hi;
    if (!rw.free[j] || std::fabs(a) <= small) {
      const bool inside = c >= lower[j] - rw.tol[j] && c <= upper[j] + rw.tol[j];
      s_lo = inside ? -kInf : kInf;
      s_hi = inside ? kInf : -kInf;
    } else {
      s_lo = nan_to_num(a > 0.0 ? (lower[j] - c) / a : (upper[j] - c) / a, -kInf);
      s_hi = nan_to_num(a > 0.0 ? (upper[j] - c) / a : (lower[j] - c) / a, kInf);
    }
    rw.col_hi[j] = s_hi;
    lo_max = std::max(lo_max, s_lo);
    hi_min = std::min(hi_min, s_hi);
  }
  *s_min = lo_max;
  *s_max = hi_min;
  return 4.0 * f(n);
}

double SnsSolver::apply_pinv(MatrixRef J, const double* perm, const Reflectors& H, Index rank,
                             const double* y, double* z) {
  ProjectionWorkspace& ws = work_;
  const Index n = n_;
  std::fill(z, z + n, 0.0);
  if (rank == 0) return 0.0;
  for (Index i = 0; i < J.rows; ++i) ws.e[i] = y[static_cast<Index>(perm[i])];
  double flops = projection::level_unknowns(J, ws.e.data(), rank, 0.0, z, ws);
  return flops + projection::apply_leading_reflectors(H, rank - 1, z, n);
}

double SnsSolver::factor_saturated(Index lev, Index count, Index* rank_m, Index* rank_b) {
  SnsWorkspace& rw = rounds_;
  ProjectionWorkspace& ws = work_;
  const Index n = n_, s0 = starts_[lev], m = starts_[lev + 1] - s0;
  const Index* sat = result_.saturated.data() + lev * n;
  double flops = 0.0, dummy = 0.0, margin = kInf;
  std::copy(ws.N.begin(), ws.N.end(), rw.Pbar.begin());
  *rank_b = 0;
  if (count > 0) {
    // B = the rows `sat` of P, factored; P̄ = P − B⁺B = P − Σ_l q_l q_lᵀ (q_l = Qᵀ e_l)
    MatrixRef Bm{rw.Jb.data(), count, n, n};
    double norm2 = 0.0;
    for (Index l = 0; l < count; ++l) {
      std::copy(ws.N.begin() + sat[l] * n, ws.N.begin() + (sat[l] + 1) * n, Bm.row(l));
      norm2 += dot(Bm.row(l), Bm.row(l), n);
    }
    flops += 2.0 * f(count * n) + 1.0;
    identity_order(rw.perm_b.data(), count);
    Reflectors Hb{MatrixRef{rw.Vb.data(), n, n, n}, rw.beta_b.data(), rw.pos_b.data(), 0};
    flops += projection::pivoted_lq(Bm, rw.perm_b.data(), 1e-12 * std::max(1.0, std::sqrt(norm2)),
                                    ws.norms.data(), Hb, rank_b, &dummy, &margin);
    MatrixRef basis{ws.basis.data(), n, n, n};
    for (Index l = 0; l < *rank_b; ++l)
      flops += projection::reflector_column(Hb, l, basis.row(l), n);
    flops += projection::subtract_products(MatrixRef{rw.Pbar.data(), n, n, n}, basis, basis,
                                           *rank_b);
  }
  // M = A_i P̄ (P̄ symmetric: row i = P̄ a_i), factored with the level's rank rule
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  MatrixRef Jm{rw.Jm.data(), m, n, n};
  const MatrixRef Pbar{rw.Pbar.data(), n, n, n};
  for (Index i = 0; i < m; ++i) flops += projection::multiply_rows(Pbar, B.row(i), Jm.row(i));
  identity_order(rw.perm_m.data(), m);
  Reflectors Hm{MatrixRef{rw.Vm.data(), n, n, n}, rw.beta_m.data(), rw.pos_m.data(), 0};
  margin = kInf;
  flops += projection::pivoted_lq(Jm, rw.perm_m.data(), options_.rcond * ws.scales[lev],
                                  ws.norms.data(), Hm, rank_m, &dummy, &margin);
  return flops;
}

double SnsSolver::saturate(Index lev, Index rank, double* x_new, double* scale, bool* found) {
  SnsWorkspace& rw = rounds_;
  ProjectionWorkspace& ws = work_;
  SnsResult& res = result_;
  const Index n = n_, s0 = starts_[lev], m = starts_[lev + 1] - s0;
  const double* x = res.x.data();
  const double* c_level = ws.c.data() + s0;
  const double* lower = res.lower.data();
  const double* upper = res.upper.data();
  MatrixRef B{ws.B.data() + s0 * n, m, n, n};
  MatrixRef Jm{rw.Jm.data(), m, n, n};
  Index* sat = res.saturated.data() + lev * n;
  // a free bounded joint outside its bounds at x_s
  const auto candidate = [&](Index j) {
    const bool bounded = lower[j] != -kInf || upper[j] != kInf;
    const bool violated = rw.xs[j] < lower[j] - rw.tol[j] || rw.xs[j] > upper[j] + rw.tol[j];
    return rw.free[j] && bounded && violated;
  };
  const Index cap = options_.max_saturations < 0 ? rw.bounded : options_.max_saturations;
  Index rank_m = 0, rank_b = 0, count = 0, rounds = 0;
  double flops = factor_saturated(lev, 0, &rank_m, &rank_b);
  std::fill(rw.free.begin(), rw.free.end(), 1);
  std::fill(rw.x_sat.begin(), rw.x_sat.end(), 0.0);
  double best_s = -kInf;
  *found = false;
  while (true) {
    ++rounds;
    const Reflectors Hm{MatrixRef{rw.Vm.data(), n, n, n}, rw.beta_m.data(), rw.pos_m.data(),
                        rank_m};
    // corr = (I − M⁺ A_i) B⁺ (x_N − x)_sat
    std::fill(rw.corr.begin(), rw.corr.end(), 0.0);
    if (count > 0) {
      for (Index l = 0; l < count; ++l) rw.v[l] = rw.x_sat[sat[l]] - x[sat[l]];
      const Reflectors Hb{MatrixRef{rw.Vb.data(), n, n, n}, rw.beta_b.data(), rw.pos_b.data(),
                          rank_b};
      flops += f(count) + apply_pinv(MatrixRef{rw.Jb.data(), count, n, n}, rw.perm_b.data(), Hb,
                                     rank_b, rw.v.data(), rw.u.data());
      flops += projection::multiply_rows(B, rw.u.data(), rw.y.data());
      flops += apply_pinv(Jm, rw.perm_m.data(), Hm, rank_m, rw.y.data(), rw.corr.data());
      for (Index j = 0; j < n; ++j) rw.corr[j] = rw.u[j] - rw.corr[j];
      flops += f(n);
    }
    // a = M⁺ b_i, c = x − M⁺ A_i x + corr, x_s = c + a
    flops += apply_pinv(Jm, rw.perm_m.data(), Hm, rank_m, c_level, rw.a.data());
    flops += projection::multiply_rows(B, x, rw.y.data());
    flops += apply_pinv(Jm, rw.perm_m.data(), Hm, rank_m, rw.y.data(), rw.cvec.data());
    for (Index j = 0; j < n; ++j) {
      rw.cvec[j] = x[j] - rw.cvec[j] + rw.corr[j];
      rw.xs[j] = rw.cvec[j] + rw.a[j];
    }
    flops += 3.0 * f(n);
    if (feasible(rw.xs.data())) {
      std::copy(rw.xs.begin(), rw.xs.end(), x_new);
      *scale = 1.0;
      *found = true;
      break;
    }
    double s_min = 0.0, s_max = 0.0;
    flops += scale_interval(&s_min, &s_max);
    const double s_t = s_max < 1.0 ? s_max : 1.0;
    if (s_min <= s_t + tie_at(s_t) && s_t >= 0.0 && s_t > best_s) {
      best_s = s_t;
      for (Index j = 0; j < n; ++j) rw.best[j] = rw.cvec[j] + s_t * rw.a[j];
      flops += 2.0 * f(n);
    }
    // the most critical free bounded joint: the first to leave its bounds as s grows, the
    // lowest of those within kSaturationTie of it
    Index pick = -1;
    double first = kInf;
    for (Index j = 0; j < n; ++j) {
      if (!candidate(j)) continue;
      if (pick < 0 || rw.col_hi[j] < first) first = rw.col_hi[j];
      pick = 0;
    }
    if (pick == 0) {
      pick = -1;
      for (Index j = 0; j < n && pick < 0; ++j)
        if (candidate(j) && rw.col_hi[j] <= first + tie_at(first)) pick = j;
    }
    if (pick < 0 || count >= cap) break;
    rw.free[pick] = 0;
    rw.x_sat[pick] = clip(rw.xs[pick], lower[pick], upper[pick]);
    sat[count++] = pick;
    flops += factor_saturated(lev, count, &rank_m, &rank_b);
    if (rank_m < rank) break;
  }
  res.iterations[lev] = rounds;
  res.saturated_count[lev] = count;
  if (!*found && best_s > 0.0) {      // the best scaled solution (best_s = -inf: none)
    std::copy(rw.best.begin(), rw.best.end(), x_new);
    *scale = best_s;
    *found = true;
  }
  return flops;
}

double SnsSolver::solve_level(Index lev, bool last) {
  SnsWorkspace& rw = rounds_;
  ProjectionWorkspace& ws = work_;
  SnsResult& res = result_;
  const Index n = n_;
  Level lv = level(lev);
  const Index m = lv.m;
  const MatrixRef B = lv.B;
  const double* c_level = ws.c.data() + lv.s0;
  // nullspace's step: x_free = x + N_{i-1} Ĵ_i^# (b_i − A_i x)
  std::copy(res.x.begin(), res.x.end(), rw.x_free.begin());
  Index r = 0;
  double min_pivot = 0.0;
  double flops = projected_step(lv, options_.rcond * ws.scales[lev], 0.0, true,
                                rw.x_free.data(), &r, &min_pivot, &res.margins[lev]);
  res.ranks[lev] = r;
  const double res_free = residual_norm(B, c_level, rw.x_free.data());
  // the level's answer within the box
  double s_level = 1.0;
  const double* chosen = res.x.data();
  if (r > 0 && feasible(rw.x_free.data())) {
    chosen = rw.x_free.data();
  } else if (r > 0) {
    bool found = false;
    flops += saturate(lev, r, rw.x_new.data(), &s_level, &found);
    chosen = found ? rw.x_new.data() : nullptr;
  }
  if (chosen == nullptr || !feasible(chosen)) {      // dropped (or round-off)
    s_level = 0.0;
    for (Index j = 0; j < n; ++j) rw.x_new[j] = clip(res.x[j], res.lower[j], res.upper[j]);
    chosen = feasible(res.x.data()) ? res.x.data() : rw.x_new.data();
  }
  const double residual = residual_norm(B, c_level, chosen);
  double b_norm = 0.0;
  for (Index i = 0; i < m; ++i) b_norm += c_level[i] * c_level[i];
  if (residual > res_free + 1e-9 * std::max(1.0, std::sqrt(b_norm))) res.exact = false;
  flops += 3.0 * (2.0 * f(m * n) + 2.0 * f(m) + 1.0);
  if (chosen != res.x.data()) std::copy(chosen, chosen + n, res.x.begin());
  res.task_scaling[lev] = s_level;
  if (r > 0 && !last) flops += projection::update_projector(ws, lv.H, r);
  return flops;
}

const SnsResult& SnsSolver::solve(const StackArrays& data, const double* lower,
                                  const double* upper) {
  BusyGuard guard(busy_);
  SnsResult& res = result_;
  std::fill(res.task_scaling.begin(), res.task_scaling.end(), 1.0);
  std::fill(res.margins.begin(), res.margins.end(), kInf);
  std::fill(res.ranks.begin(), res.ranks.end(), 0);
  std::fill(res.iterations.begin(), res.iterations.end(), 0);
  std::fill(res.saturated_count.begin(), res.saturated_count.end(), 0);
  res.bounds = SnsBounds::ok;
  res.bad_entry = -1;
  res.exact = true;
  if (!open_solve(data, res) || !read_bounds(data, lower, upper)) return res;
  res.solved = true;
  const Index first = options_.bounds_level ? 1 : 0;
  const double flops = run_levels(first);
  if (first == k_ && !feasible(res.x.data()))      // bounds alone: the box's minimum-norm point
    for (Index j = 0; j < n_; ++j) res.x[j] = clip(res.x[j], res.lower[j], res.upper[j]);
  close_solve(data, flops, res);
  if (first == 1) {          // the bounds rows: the distance of A_0 x to [lower, upper]
    double acc = 0.0;
    for (Index i = 0; i < starts_[1]; ++i) {
      const double r = dot(data.A + i * n_, res.x.data(), n_);
      const double v = data.sqrt_weight[i] *
                       (std::max(lower[i] - r, 0.0) + std::max(r - upper[i], 0.0));
      acc += v * v;
    }
    res.residuals[0] = std::sqrt(acc);
    res.finite = res.finite && std::isfinite(res.residuals[0]);
  }
  return res;
}

}  // namespace prioik
