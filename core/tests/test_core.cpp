// The core's own tests, without Python (ctest; `make asan` runs them under
// -fsanitize=address,undefined): the Householder steps and the nested QR against Eigen's
// dense decompositions, the unit-rows and trust-region paths, the batch, bad input.
#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "prioik/extended_jacobian.hpp"
#include "prioik/householder.hpp"
#include "check.hpp"

using prioik::Index;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Vec = Eigen::VectorXd;

namespace {

Mat random_matrix(std::mt19937& rng, Index rows, Index cols) {
  std::normal_distribution<double> g;
  Mat m(rows, cols);
  for (Index i = 0; i < rows; ++i)
    for (Index j = 0; j < cols; ++j) m(i, j) = g(rng);
  return m;
}

Vec random_vector(std::mt19937& rng, Index n) {
  std::normal_distribution<double> g;
  Vec v(n);
  for (Index i = 0; i < n; ++i) v(i) = g(rng);
  return v;
}

// The lexicographic minimum-norm optimum by Eigen: per level the least squares in the
// null space of the levels above (complete orthogonal decompositions), ranks by rcond.
Vec nested_reference(const Mat& A, const Vec& b, const std::vector<Index>& starts) {
  const Index n = A.cols();
  Vec x = Vec::Zero(n);
  Mat N = Mat::Identity(n, n);     // an orthonormal basis of the free directions
  for (std::size_t lev = 0; lev + 1 < starts.size(); ++lev) {
    const Index s0 = starts[lev], m = starts[lev + 1] - s0;
    if (m == 0 || N.cols() == 0) continue;
    const Mat K = A.middleRows(s0, m) * N;
    const Vec p = b.segment(s0, m) - A.middleRows(s0, m) * x;
    Eigen::JacobiSVD<Mat> svd(K, Eigen::ComputeFullV | Eigen::ComputeThinU);
    const Vec& s = svd.singularValues();
    const double tol = 1e-10 * K.norm();
    Index r = 0;
    while (r < s.size() && s(r) > tol) ++r;
    Vec z = Vec::Zero(N.cols());
    for (Index j = 0; j < r; ++j)
      z += svd.matrixV().col(j) * (svd.matrixU().col(j).dot(p) / s(j));
    x += N * z;
    N = N * svd.matrixV().rightCols(N.cols() - r);
  }
  return x;
}

struct Stack {
  Mat A;
  Vec b, w;
  std::vector<Index> starts;
};

Stack random_stack(std::mt19937& rng, Index n, std::vector<Index> rows) {
  Stack s;
  s.starts = {0};
  for (Index m : rows) s.starts.push_back(s.starts.back() + m);
  s.A = random_matrix(rng, s.starts.back(), n);
  s.b = random_vector(rng, s.starts.back());
  s.w = Vec::Ones(s.starts.back());
  return s;
}

const prioik::ExtendedJacobianResult& solve(prioik::ExtendedJacobian& solver, const Stack& s) {
  return solver.solve(prioik::StackArrays{s.A.data(), s.b.data(), s.w.data()});
}

double relative(const Vec& a, const Vec& b) { return (a - b).norm() / std::max(1.0, b.norm()); }

void test_small_least_squares_equals_eigen() {
  std::mt19937 rng(1);
  for (Index m : {3, 7, 12}) {
    for (Index r : {1, 3}) {
      Mat L = random_matrix(rng, m, 12);
      Vec rhs = random_vector(rng, m);
      for (double mu2 : {0.0, 0.3}) {
        std::vector<double> scratch(prioik::small_least_squares_scratch(m, r));
        Vec z(r);
        prioik::small_least_squares(prioik::MatrixRef{L.data(), m, 12, 12}, rhs.data(), m, r,
                                    mu2, z.data(), scratch.data());
        const Mat Lr = L.leftCols(r);
        const Mat G = Lr.transpose() * Lr + mu2 * Mat::Identity(r, r);
        const Vec ref = G.ldlt().solve(Lr.transpose() * rhs);
        CHECK(relative(z, ref) < 1e-12);
      }
    }
  }
}

void test_cholesky_and_reflectors() {
  std::mt19937 rng(2);
  const Index m = 6;
  Mat R = random_matrix(rng, m, m);
  Mat G = R * R.transpose() + Mat::Identity(m, m);
  Mat F = G;
  CHECK(prioik::cholesky_lower(prioik::MatrixRef{F.data(), m, m, m}, m));
  Vec t = random_vector(rng, m), t0 = t;
  prioik::cholesky_solve(prioik::MatrixRef{F.data(), m, m, m}, t.data(), m);
  CHECK(relative(G * t, t0) < 1e-12);
  Mat Neg = -G;
  CHECK(!prioik::cholesky_lower(prioik::MatrixRef{Neg.data(), m, m, m}, m));
}

void test_nested_qr_equals_the_nested_reference() {
  std::mt19937 rng(3);
  const std::vector<std::vector<Index>> shapes = {{3, 4, 20}, {6, 6, 6, 6}, {2, 30}, {1, 1, 1}};
  for (const auto& rows : shapes) {
    Stack s = random_stack(rng, 12, rows);
    prioik::ExtendedJacobian solver(s.starts, 12, {});
    const auto& res = solve(solver, s);
    const Vec x = Eigen::Map<const Vec>(res.x.data(), 12);
    CHECK(res.solved && res.finite && !res.ambiguous);
    CHECK(relative(x, nested_reference(s.A, s.b, s.starts)) < 1e-10);
    // the residuals are the solution's
    for (std::size_t lev = 0; lev + 1 < s.starts.size(); ++lev) {
      const Index s0 = s.starts[lev], m = s.starts[lev + 1] - s0;
      const double w = (s.A.middleRows(s0, m) * x - s.b.segment(s0, m)).norm();
      CHECK(std::fabs(res.residuals[lev] - w) <= 1e-12 * std::max(1.0, w));
    }
  }
}

void test_a_unit_row_posture_takes_the_woodbury_step() {
  std::mt19937 rng(4);
  const Index n = 20;
  for (Index top : {4, 8, 14}) {
    Stack s = random_stack(rng, n, {top, n - 6});
    s.A.bottomRows(n - 6).setZero();
    for (Index i = 0; i < n - 6; ++i) s.A(top + i, 6 + i) = (i % 2) ? 2.0 : -2.0;
    prioik::ExtendedJacobian solver(s.starts, n, {});
    const auto& res = solve(solver, s);
    const Vec x = Eigen::Map<const Vec>(res.x.data(), n);
    CHECK(relative(x, nested_reference(s.A, s.b, s.starts)) < 1e-10);
    CHECK(res.ranks[1] == std::min(n - 6, n - top));
  }
}

void test_step_bound_bounds_each_step_and_damping_reports_mu2() {
  std::mt19937 rng(5);
  Stack s = random_stack(rng, 10, {3, 12});
  prioik::ExtendedJacobianOptions o;
  o.step_bound = {0.0, 0.05};
  prioik::ExtendedJacobian bounded(s.starts, 10, o);
  const auto& res = solve(bounded, s);
  prioik::ExtendedJacobian top({0, 3}, 10, {});
  Stack first{s.A.topRows(3), s.b.head(3), s.w.head(3), {0, 3}};
  const Vec x0 = Eigen::Map<const Vec>(top.solve({first.A.data(), first.b.data(),
                                                  first.w.data()}).x.data(), 10);
  const Vec x = Eigen::Map<const Vec>(res.x.data(), 10);
  CHECK(res.level_mu2[1] > 0.0 && res.level_mu2[0] == 0.0);
  CHECK(std::fabs((x - x0).norm() - 0.05) <= 1e-9 * 0.05);
  CHECK(res.residuals[0] < 1e-12);
}

void test_batch_equals_single_solves() {
  std::mt19937 rng(6);
  const Index n = 9, N = 4;
  std::vector<Stack> stacks;
  for (Index i = 0; i < N; ++i) stacks.push_back(random_stack(rng, n, {2, 5, 7}));
  const std::vector<Index>& starts = stacks[0].starts;
  const Index M = starts.back();
  std::vector<double> A, b, w;
  for (const Stack& s : stacks) {
    A.insert(A.end(), s.A.data(), s.A.data() + M * n);
    b.insert(b.end(), s.b.data(), s.b.data() + M);
    w.insert(w.end(), s.w.data(), s.w.data() + M);
  }
  prioik::ExtendedJacobian solver(starts, n, {});
  for (unsigned threads : {1u, 3u, 8u}) {
    const prioik::ExtendedJacobianBatch batch =
        solver.solve_batch(A.data(), b.data(), w.data(), N, threads);
    for (Index i = 0; i < N; ++i) {
      const auto& one = solve(solver, stacks[i]);
      for (Index j = 0; j < n; ++j) CHECK(batch.x[i * n + j] == one.x[j]);
    }
  }
  // the first stack with a bad value is named, whichever thread met it
  A[2 * starts.back() * n + 5] = std::numeric_limits<double>::quiet_NaN();
  A[3 * starts.back() * n + 1] = std::numeric_limits<double>::quiet_NaN();
  bool named = false;
  try {
    solver.solve_batch(A.data(), b.data(), w.data(), N, 3);
  } catch (const prioik::InputError& e) {
    named = std::string(e.what()).rfind("stack 2: A[0, 5]", 0) == 0;
  }
  CHECK(named);
}

void test_bad_input_throws_input_error() {
  std::mt19937 rng(7);
  Stack s = random_stack(rng, 5, {2, 3});
  prioik::ExtendedJacobian solver(s.starts, 5, {});
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(),
                        std::numeric_limits<double>::infinity()};
  for (double v : bad) {
    Stack t = s;
    t.A(3, 4) = v;
    bool thrown = false;
    try {
      solve(solver, t);
    } catch (const prioik::InputError& e) {
      thrown = std::string(e.what()).find("A[3, 4]") != std::string::npos;
    }
    CHECK(thrown);
  }
  Stack t = s;
  t.w(1) = 0.0;
  bool thrown = false;
  try {
    solve(solver, t);
  } catch (const prioik::InputError& e) {
    thrown = std::string(e.what()).find("sqrt_weight[1]") != std::string::npos;
  }
  CHECK(thrown);
  CHECK(solve(solver, s).finite);     // still works after refusing
  thrown = false;
  try {
    prioik::ExtendedJacobian malformed({0, 3, 1}, 5, {});
  } catch (const prioik::InputError&) {
    thrown = true;
  }
  CHECK(thrown);
}

void test_extreme_scale_is_reported_not_solved() {
  Stack s;
  s.A = 1e-200 * Mat::Identity(2, 2);
  s.b = Vec::Ones(2);
  s.w = Vec::Ones(2);
  s.starts = {0, 2};
  prioik::ExtendedJacobian solver(s.starts, 2, {});
  CHECK(!solve(solver, s).solved);
}

}  // namespace

int main() {
  test_small_least_squares_equals_eigen();
  test_cholesky_and_reflectors();
  test_nested_qr_equals_the_nested_reference();
  test_a_unit_row_posture_takes_the_woodbury_step();
  test_step_bound_bounds_each_step_and_damping_reports_mu2();
  test_batch_equals_single_solves();
  test_bad_input_throws_input_error();
  test_extreme_scale_is_reported_not_solved();
  std::printf(prioik_test::failures == 0 ? "core tests: all passed\n" : "core tests: %d failed\n", prioik_test::failures);
  return prioik_test::failures == 0 ? 0 : 1;
}
