// A C++ program that uses prioik's core without Python: a humanoid-like stack of three
// levels on 12 joints (a 6-row contact, a 3-row hand target, a posture of the 6 actuated
// joints), prepared once and solved for a few targets, as a control loop would.
//
// Build (after `cmake --install` of core/ to PREFIX):
//   cmake -S core/examples -B build/example -DCMAKE_PREFIX_PATH="PREFIX;EIGEN_PREFIX"
//   cmake --build build/example && build/example/solve_stack
#include <cmath>
#include <cstdio>
#include <vector>

#include "prioik/extended_jacobian.hpp"

int main() {
  using prioik::Index;
  const Index n = 12;
  // the levels' row offsets: contact rows 0-5, hand rows 6-8, posture rows 9-14
  const std::vector<Index> starts = {0, 6, 9, 15};
  const Index M = starts.back();
  prioik::ExtendedJacobianOptions options;
  options.rcond = 1e-10;
  prioik::ExtendedJacobian solver(starts, n, options);   // every workspace allocated here

  std::vector<double> A(M * n, 0.0), b(M, 0.0), sqrt_weight(M, 1.0);
  for (Index i = 0; i < 6; ++i)                         // contact: the floating base
    for (Index j = 0; j < n; ++j) A[i * n + j] = (i == j) ? 1.0 : 0.1 * std::sin(1.0 + i + 2 * j);
  for (Index i = 6; i < 9; ++i)                         // hand: a dense 3 × 12 Jacobian
    for (Index j = 0; j < n; ++j) A[i * n + j] = std::cos(0.3 * i * j + 0.5);
  for (Index i = 9; i < 15; ++i) A[i * n + (i - 3)] = 1.0;   // posture on joints 6-11

  int status = 0;
  for (int step = 0; step < 3; ++step) {
    for (Index i = 6; i < 9; ++i) b[i] = 0.1 * (step + 1) * (i - 5);   // the hand's target
    const prioik::ExtendedJacobianResult& res =
        solver.solve(prioik::StackArrays{A.data(), b.data(), sqrt_weight.data()});
    std::printf("step %d: ranks", step);
    for (Index r : res.ranks) std::printf(" %td", r);
    std::printf(", residuals");
    for (double w : res.residuals) std::printf(" %.3g", w);
    std::printf(", |x| %.6f\n", std::sqrt(prioik::dot(res.x.data(), res.x.data(), n)));
    // the contact and the hand are met exactly (12 joints, 9 rows of rank 9)
    if (!res.solved || !res.finite || res.residuals[0] > 1e-12 || res.residuals[1] > 1e-12)
      status = 1;
  }
  std::printf(status == 0 ? "ok\n" : "FAILED\n");
  return status;
}
