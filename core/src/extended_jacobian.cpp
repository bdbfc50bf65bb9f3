#include "prioik/extended_jacobian.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

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

}  // namespace

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
  // selective damping needs both values (the Python layer passes 0 for λ otherwise)
  params_.rcond = options_.rcond;
  params_.level_damping = options_.singular_threshold > 0.0 ? options_.level_damping : 0.0;
  params_.singular_threshold = options_.singular_threshold;
  params_.step_bound = options_.step_bound.data();
  B_.assign(M_ * n_, 0.0);
  c_.assign(M_, 0.0);
  scales_.assign(k_, 0.0);
  qr_ = NestedQRWorkspace(M_, n_);
  result_.x.assign(n_, 0.0);
  result_.residuals.assign(k_, 0.0);
  result_.level_mu2.assign(k_, 0.0);
  result_.margins.assign(k_, kInf);
  result_.ranks.assign(k_, 0);
}

bool ExtendedJacobian::weigh_and_scale(const StackArrays& data) {
  const bool weights_ok = weigh_rows(data.A, data.b, data.sqrt_weight, M_, n_, B_.data(),
                                     c_.data());
  const bool scales_ok = level_scales(B_.data(), c_.data(), M_, n_, starts_.data(), k_,
                                      scales_.data());
  return weights_ok && scales_ok;
}

void ExtendedJacobian::check_entries(const StackArrays& data) const {
  for (Index i = 0; i < M_; ++i)
    for (Index j = 0; j < n_; ++j)
      if (!std::isfinite(data.A[i * n_ + j]))
        throw InputError("A[" + std::to_string(i) + ", " + std::to_string(j) +
                         "] is not finite (" + fmt(data.A[i * n_ + j]) + ")");
  for (Index i = 0; i < M_; ++i)
    if (!std::isfinite(data.b[i]))
      throw InputError("b[" + std::to_string(i) + "] is not finite (" + fmt(data.b[i]) + ")");
  for (Index i = 0; i < M_; ++i) {
    const double w = data.sqrt_weight[i];
    if (!(w > 0.0 && w < kInf))
      throw InputError("sqrt_weight[" + std::to_string(i) + "] must be finite and > 0, got " +
                       fmt(w));
  }
}

void ExtendedJacobian::summarize(const StackArrays& data) {
  ExtendedJacobianResult& res = result_;
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

const ExtendedJacobianResult& ExtendedJacobian::solve(const StackArrays& data) {
  BusyGuard guard(busy_);
  ExtendedJacobianResult& res = result_;
  res.solved = weigh_and_scale(data);
  if (!res.solved) {
    // a NaN, an inf or a √w ≤ 0 is an input error; finite rows of extreme scale are not
    check_entries(data);
    res.finite = res.ambiguous = res.near_ambiguous = res.precision_limited = false;
    return res;
  }
  MatrixRef B{B_.data(), M_, n_, n_};
  const NestedQROutput out{res.x.data(), res.ranks.data(), res.level_mu2.data(),
                           res.margins.data(), nullptr};
  nested_qr(B, c_.data(), starts_.data(), k_, scales_.data(), params_, trust_region_, qr_, out);
  summarize(data);
  return res;
}

ExtendedJacobianBatch ExtendedJacobian::solve_batch(const double* A, const double* b,
                                                    const double* sqrt_weight, Index N) {
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
  for (Index s = 0; s < N; ++s) {
    const StackArrays one{A + s * M_ * n_, b + s * M_, sqrt_weight + s * M_};
    try {
      solve(one);
    } catch (const InputError& e) {
      throw InputError("stack " + std::to_string(s) + ": " + e.what());
    }
    const ExtendedJacobianResult& res = result_;
    std::copy(res.x.begin(), res.x.end(), out.x.begin() + s * n_);
    std::copy(res.residuals.begin(), res.residuals.end(), out.residuals.begin() + s * k_);
    std::copy(res.level_mu2.begin(), res.level_mu2.end(), out.level_mu2.begin() + s * k_);
    std::copy(res.margins.begin(), res.margins.end(), out.margins.begin() + s * k_);
    std::copy(res.ranks.begin(), res.ranks.end(), out.ranks.begin() + s * k_);
    out.solved[s] = res.solved;
    out.finite[s] = res.finite;
    out.ambiguous[s] = res.ambiguous;
    out.near_ambiguous[s] = res.near_ambiguous;
  }
  return out;
}

}  // namespace prioik
