// The extended Jacobian's prepared solve (eq. 15-18 by the nested pivoted QR of
// nested_qr.hpp): a layout's levels and options fixed once, every workspace allocated
// then; a solve weighs the rows (diag(√w) A, √w ∘ b), takes the level scales ‖A_i‖_F with
// the finite check in the same pass, runs the nested QR and the per-level residuals
// ‖√w ∘ (A_i x - b_i)‖, and allocates nothing.
//
// One thread at a time per solver (a second concurrent call throws ConcurrentUse).
#pragma once

#include <atomic>
#include <stdexcept>
#include <string>
#include <vector>

#include "prioik/nested_qr.hpp"

namespace prioik {

// Finite rows are taken when each level's ‖A_i‖_F lies in [kScaleLow, kScaleHigh] (or the
// level is zero): beyond, the squares overflow, lose precision or underflow, and the
// caller equilibrates the stack (TaskStack.equilibrated).
constexpr double kScaleHigh = 1e100;
constexpr double kScaleLow = 1e-100;

// An input the solver cannot take; what() names the array (and the entry) at fault.
class InputError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// A second thread called a solver during a solve.
class ConcurrentUse : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ExtendedJacobianOptions {
  double rcond = 1e-10;
  double level_damping = 0.0;        // λ_max of the selective damping (0: off)
  double singular_threshold = 0.0;   // ε: damp a level whose projected σ_min < ε ‖A_i‖_F
  std::vector<double> step_bound;    // k bounds Δ_i on the levels' steps (0 or empty: none)
};

// The answer of one solve, read by name.
struct ExtendedJacobianResult {
  std::vector<double> x;            // n
  std::vector<double> residuals;    // k: ‖√w ∘ (A_i x - b_i)‖
  std::vector<double> level_mu2;    // k: the damping μ_i² (0 where the level is exact)
  std::vector<double> margins;      // k: the rank decisions' margins (inf: none decided)
  std::vector<Index> ranks;         // k: r_i
  double flops = 0.0;               // floating-point operations of the nested QR (flops.hpp)
  bool solved = false;       // false: some level's scale is outside [1e-100, 1e100] and
                             // nothing was solved (the caller equilibrates)
  bool finite = false;       // the residuals (and so x) are finite
  bool ambiguous = false;    // some level's margin ≤ kAmbiguity
  bool near_ambiguous = false;  // another's ≤ kNearAmbiguity kAmbiguity
  bool precision_limited = false;  // ‖x‖ > kPrecisionLimitNorm
};

// Stack data of a layout: A (M × n, row-major), b and √w (M).
struct StackArrays {
  const double* A = nullptr;
  const double* b = nullptr;
  const double* sqrt_weight = nullptr;
};

// Throws InputError naming the first entry of A or b that is not finite, or the first
// √w not finite and > 0 (M rows of n columns).
void check_stack_entries(const StackArrays& data, Index M, Index n);

// The answers of many stacks of one layout, stack s in row s of each part.
struct ExtendedJacobianBatch {
  Index N = 0, n = 0, k = 0;
  std::vector<double> x;            // N × n
  std::vector<double> residuals;    // N × k
  std::vector<double> level_mu2;    // N × k
  std::vector<double> margins;      // N × k
  std::vector<Index> ranks;         // N × k
  std::vector<unsigned char> solved, finite, ambiguous, near_ambiguous;   // N
};

// What one solve works in, allocated at prepare: the weighted rows and targets, the
// level scales, the nested QR's scratch, and the answer.
struct ExtendedJacobianWorkspace {
  ExtendedJacobianWorkspace() = default;
  ExtendedJacobianWorkspace(Index M, Index n, Index k);

  std::vector<double> B;        // M × n: diag(√w) A, then the nested QR's rotated rows
  std::vector<double> c;        // M: √w ∘ b
  std::vector<double> scales;   // k: ‖A_i‖_F of the weighted rows
  NestedQRWorkspace qr;
  ExtendedJacobianResult result;
};

class ExtendedJacobian {
 public:
  // starts: the k + 1 row offsets of the levels (starts[0] = 0, non-decreasing);
  // n: the columns. Throws InputError on a malformed layout or options.
  ExtendedJacobian(std::vector<Index> starts, Index n, ExtendedJacobianOptions options);

  // Solve one stack of the layout; the result is this solver's, overwritten by the next
  // solve. Throws InputError naming the array of a non-finite entry or a √w ≤ 0.
  const ExtendedJacobianResult& solve(const StackArrays& data);

  // Solve N stacks of the layout (A: N × M × n, b and √w: N × M), each on its own, as
  // solve does, on up to `threads` threads (0: one per hardware thread; each its own
  // workspace, allocated here). Throws InputError naming the first stack of a non-finite
  // entry or a √w ≤ 0.
  ExtendedJacobianBatch solve_batch(const double* A, const double* b, const double* sqrt_weight,
                                    Index N, unsigned threads = 0);

  const ExtendedJacobianResult& result() const { return work_.result; }
  Index rows() const { return M_; }
  Index cols() const { return n_; }
  Index levels() const { return k_; }
  const std::vector<Index>& starts() const { return starts_; }
  const ExtendedJacobianOptions& options() const { return options_; }
  bool trust_region() const { return trust_region_; }

 private:
  // one solve on `work` (this solver's or a batch thread's)
  void solve_on(const StackArrays& data, ExtendedJacobianWorkspace& work) const;
  void summarize(const StackArrays& data, ExtendedJacobianResult& res) const;

  std::vector<Index> starts_;
  Index M_, n_, k_;
  ExtendedJacobianOptions options_;
  bool trust_region_;
  NestedQRParameters params_;
  ExtendedJacobianWorkspace work_;
  std::atomic<bool> busy_{false};
};

// B = diag(w) A, c = w ∘ b (M × n, M); false when a √w is not finite and > 0.
bool weigh_rows(const double* A, const double* b, const double* w, Index M, Index n, double* B,
                double* c);

// scales[i] = ‖A_i‖_F of every level; false when a scale or an entry of b is not finite, or
// a level's scale is outside [kScaleLow, kScaleHigh] with a non-zero entry.
bool level_scales(const double* A, const double* b, Index M, Index n, const Index* starts,
                  Index k, double* scales);

// out[i] = ‖w ∘ (A_i x - b_i)‖ per level
void level_residuals(const double* A, const double* b, const double* w, Index n,
                     const Index* starts, Index k, const double* x, double* out);

}  // namespace prioik
