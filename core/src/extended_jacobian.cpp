#include "prioik/extended_jacobian.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <thread>
#include <utility>

#include "busy_guard.hpp"
#include "vector_clones.hpp"

namespace prioik {

namespace {

// Whether a level (rows s0:s1) with ‖A_i‖_F² = lev_sq is of extreme scale: beyond
// kScaleHigh (or not finite), or below kScaleLow with a non-zero entry (a zero level is
// fine; squares of entries below ~1e-154 underflow).
bool level_extreme(const double* A, Index n, double lev_sq, Index s0, Index s1) {
  if (!(lev_sq <= kScaleHigh * kScaleHigh)) return true;
  if (lev_sq < kScaleLow * kScaleLow) {
    for (Index i = s0 * n; i < s1 * n; ++i)
      if (A[i] != 0.0) return true;
  }
  return false;
}

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace

ExtendedJacobianWorkspace::ExtendedJacobianWorkspace(Index M, Index n, Index k)
    : B(M * n, 0.0), c(M, 0.0), scales(k, 0.0), qr(M, n) {
  result.x.assign(n, 0.0);
  result.residuals.assign(k, 0.0);
  result.level_mu2.assign(k, 0.0);
  result.margins.assign(k, kInf);
  result.ranks.assign(k, 0);
}

PRIOIK_VECTOR_CLONES
bool weigh_rows(const double* A, const double* b, const double* w, Index M, Index n, double* B,
                double* c) {
  bool ok = true;
  for (Index i = 0; i < M; ++i) {
    const double wi = w[i];
    if (!(wi > 0.0 && wi < kInf)) ok = false;
    for (Index j = 0; j < n; ++j) B[i * n + j] = wi * A[i * n + j];
    c[i] = wi * b[i];
  }
  return ok;
}

PRIOIK_VECTOR_CLONES
bool level_scales(const double* A, const double* b, Index M, Index n, const Index* starts,
                  Index k, double* scales) {
  bool finite = true;
  for (Index lev = 0; lev < k; ++lev) {
    double acc = 0.0;
    for (Index i = starts[lev]; i < starts[lev + 1]; ++i) acc += dot(A + i * n, A + i * n, n);
    scales[lev] = std::sqrt(acc);
    if (level_extreme(A, n, acc, starts[lev], starts[lev + 1])) finite = false;
  }
  for (Index i = 0; i < M; ++i) {   // entry by entry: b may be large (x is then large)
    if (!std::isfinite(b[i])) finite = false;
  }
  return finite;
}

PRIOIK_VECTOR_CLONES
void level_residuals(const double* A, const double* b, const double* w, Index n,
                     const Index* starts, Index k, const double* x, double* out) {
  for (Index lev = 0; lev < k; ++lev) {
    double acc = 0.0;
    for (Index i = starts[lev]; i < starts[lev + 1]; ++i) {
      const double r = w[i] * (dot(A + i * n, x, n) - b[i]);
      acc += r * r;
    }
    out[lev] = std::sqrt(acc);
  }
}

ExtendedJacobian::ExtendedJacobian(std::vector<Index> starts, Index n,
                                   ExtendedJacobianOptions options)
    : starts_(std::move(starts)), n_(n), options_(std::move(options)) {
  if (starts_.empty() || starts_[0] != 0)
    throw InputError("starts must hold the k + 1 row offsets of the levels, from 0");
  for (std::size_t i = 1; i < starts_.size(); ++i)
    if (starts_[i] < starts_[i - 1]) throw InputError("starts must be non-decreasing");
  if (n_ <= 0) throw InputError("n must be positive, got " + std::to_string(n_));
  k_ = static_cast<Index>(starts_.size()) - 1;
  M_ = starts_.back();
  if (M_ <= 0) throw InputError("the layout has no rows");
  if (!(options_.rcond > 0.0 && options_.rcond < 1.0))
    throw InputError("rcond must be in (0, 1), got " + fmt(options_.rcond));
  if (!(options_.level_damping >= 0.0 && options_.level_damping < kInf))
    throw InputError("level_damping must be finite and >= 0, got " + fmt(options_.level_damping));
  if (!(options_.singular_threshold >= 0.0 && options_.singular_threshold < kInf))
    throw InputError("singular_threshold must be finite and >= 0, got " +
                     fmt(options_.singular_threshold));
  if (options_.step_bound.empty()) options_.step_bound.assign(k_, 0.0);
  if (static_cast<Index>(options_.step_bound.size()) != k_)
    throw InputError("step_bound must hold one value per level (" + std::to_string(k_) + ")");
  trust_region_ = false;
  for (double v : options_.step_bound) {
    if (!(v >= 0.0 && v < kInf)) throw InputError("step_bound must be finite and >= 0");
    if (v > 0.0) trust_region_ = true;
  }
  // selective damping needs both values
  params_.rcond = options_.rcond;
  params_.level_damping = options_.singular_threshold > 0.0 ? options_.level_damping : 0.0;
  params_.singular_threshold = options_.singular_threshold;
  params_.step_bound = options_.step_bound.data();
  work_ = ExtendedJacobianWorkspace(M_, n_, k_);
}

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

void ExtendedJacobian::summarize(const StackArrays& data, ExtendedJacobianResult& res) const {
  level_residuals(data.A, data.b, data.sqrt_weight, n_, starts_.data(), k_, res.x.data(),
                  res.residuals.data());
  double acc = 0.0;
  res.ambiguous = false;
  res.near_ambiguous = false;
  for (Index lev = 0; lev < k_; ++lev) {
    acc += res.residuals[lev];
    if (res.margins[lev] <= kAmbiguity) {
      res.ambiguous = true;
    } else if (res.margins[lev] <= kNearAmbiguity * kAmbiguity) {
      res.near_ambiguous = true;
    }
  }
  res.finite = std::isfinite(acc);
  res.precision_limited = dot(res.x.data(), res.x.data(), n_) >
                          kPrecisionLimitNorm * kPrecisionLimitNorm;
}

void ExtendedJacobian::solve_on(const StackArrays& data, ExtendedJacobianWorkspace& work) const {
  ExtendedJacobianResult& res = work.result;
  const bool weights_ok = weigh_rows(data.A, data.b, data.sqrt_weight, M_, n_, work.B.data(),
                                     work.c.data());
  const bool scales_ok = level_scales(work.B.data(), work.c.data(), M_, n_, starts_.data(), k_,
                                      work.scales.data());
  res.solved = weights_ok && scales_ok;
  if (!res.solved) {
    // a NaN, an inf or a √w ≤ 0 is an input error; finite rows of extreme scale are not
    check_stack_entries(data, M_, n_);
    res.finite = res.ambiguous = res.near_ambiguous = res.precision_limited = false;
    return;
  }
  const NestedQROutput out{res.x.data(), res.ranks.data(), res.level_mu2.data(),
                           res.margins.data(), nullptr, &res.flops};
  nested_qr(MatrixRef{work.B.data(), M_, n_, n_}, work.c.data(), starts_.data(), k_,
            work.scales.data(), params_, trust_region_, work.qr, out);
  summarize(data, res);
}

const ExtendedJacobianResult& ExtendedJacobian::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  solve_on(data, work_);
  return work_.result;
}

namespace {

// stack s's answer into row s of the batch's parts
void store(const ExtendedJacobianResult& res, Index s, ExtendedJacobianBatch& out) {
  std::copy(res.x.begin(), res.x.end(), out.x.begin() + s * out.n);
  std::copy(res.residuals.begin(), res.residuals.end(), out.residuals.begin() + s * out.k);
  std::copy(res.level_mu2.begin(), res.level_mu2.end(), out.level_mu2.begin() + s * out.k);
  std::copy(res.margins.begin(), res.margins.end(), out.margins.begin() + s * out.k);
  std::copy(res.ranks.begin(), res.ranks.end(), out.ranks.begin() + s * out.k);
  out.solved[s] = res.solved;
  out.finite[s] = res.finite;
  out.ambiguous[s] = res.ambiguous;
  out.near_ambiguous[s] = res.near_ambiguous;
}

}  // namespace

ExtendedJacobianBatch ExtendedJacobian::solve_batch(const double* A, const double* b,
                                                    const double* sqrt_weight, Index N,
                                                    unsigned threads) {
  BusyGuard guard(busy_);
  ExtendedJacobianBatch out;
  out.N = N;
  out.n = n_;
  out.k = k_;
  out.x.assign(N * n_, 0.0);
  out.residuals.assign(N * k_, 0.0);
  out.level_mu2.assign(N * k_, 0.0);
  out.margins.assign(N * k_, kInf);
  out.ranks.assign(N * k_, 0);
  out.solved.assign(N, 0);
  out.finite.assign(N, 0);
  out.ambiguous.assign(N, 0);
  out.near_ambiguous.assign(N, 0);
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  const Index T = std::max<Index>(1, std::min<Index>(threads, N));
  // thread t solves stacks t, t + T, …; the first stack that fails is reported
  std::vector<std::string> errors(T);
  std::vector<Index> failed(T, N);
  auto work = [&](Index t, ExtendedJacobianWorkspace& ws) {
    for (Index s = t; s < N; s += T) {
      try {
        solve_on(StackArrays{A + s * M_ * n_, b + s * M_, sqrt_weight + s * M_}, ws);
      } catch (const InputError& e) {
        failed[t] = s;
        errors[t] = e.what();
        return;
      }
      store(ws.result, s, out);
    }
  };
  if (T == 1) {
    work(0, work_);
  } else {
    std::vector<ExtendedJacobianWorkspace> spaces;
    spaces.reserve(T - 1);
    for (Index t = 1; t < T; ++t) spaces.emplace_back(M_, n_, k_);
    std::vector<std::thread> pool;
    for (Index t = 1; t < T; ++t) pool.emplace_back(work, t, std::ref(spaces[t - 1]));
    work(0, work_);
    for (std::thread& th : pool) th.join();
  }
  const Index first = std::min_element(failed.begin(), failed.end()) - failed.begin();
  if (failed[first] < N)
    throw InputError("stack " + std::to_string(failed[first]) + ": " + errors[first]);
  return out;
}

}  // namespace prioik
