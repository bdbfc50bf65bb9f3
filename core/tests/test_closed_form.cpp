// The compiled closed-form formulations (closed_form.hpp) without Python (ctest; `make
// asan` runs them under -fsanitize=address,undefined): each against its recursion written
// with Eigen's dense decompositions on random stacks, their flop counts, bad input.
#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "prioik/closed_form.hpp"
#include "check.hpp"

using prioik::Index;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Vec = Eigen::VectorXd;

namespace {

struct Stack {
  Mat A;
  Vec b, w;
  std::vector<Index> starts;

  prioik::StackArrays arrays() const { return {A.data(), b.data(), w.data()}; }
  Mat rows(std::size_t lev) const { return A.middleRows(starts[lev], starts[lev + 1] - starts[lev]); }
  Vec targets(std::size_t lev) const {
    return b.segment(starts[lev], starts[lev + 1] - starts[lev]);
  }
  std::size_t levels() const { return starts.size() - 1; }
};

Stack random_stack(std::mt19937& rng, Index n, std::vector<Index> rows) {
  std::normal_distribution<double> g;
  Stack s;
  s.starts = {0};
  for (Index m : rows) s.starts.push_back(s.starts.back() + m);
  const Index M = s.starts.back();
  s.A = Mat(M, n);
  s.b = Vec(M);
  for (Index i = 0; i < M; ++i) {
    for (Index j = 0; j < n; ++j) s.A(i, j) = g(rng);
    s.b(i) = g(rng);
  }
  s.w = Vec::Ones(M);
  return s;
}

Mat random_spd(std::mt19937& rng, Index n) {
  std::normal_distribution<double> g;
  Mat G(n, n);
  for (Index i = 0; i < n; ++i)
    for (Index j = 0; j < n; ++j) G(i, j) = g(rng);
  return G * G.transpose() + static_cast<double>(n) * Mat::Identity(n, n);
}

// the truncated pseudo-inverse (σ > rcond ‖K‖_F)
Mat pinv(const Mat& K, double scale) {
  Eigen::JacobiSVD<Mat> svd(K, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Vec& s = svd.singularValues();
  Mat out = Mat::Zero(K.cols(), K.rows());
  for (Index j = 0; j < s.size(); ++j)
    if (s(j) > 1e-9 * scale)
      out += svd.matrixV().col(j) * svd.matrixU().col(j).transpose() / s(j);
  return out;
}

bool close(const Vec& got, const Vec& want) {
  return (got - want).norm() <= 1e-9 * std::max(1.0, want.norm());
}

Vec as_vec(const std::vector<double>& v) { return Eigen::Map<const Vec>(v.data(), v.size()); }

// x_i = x + N Ĵ⁺ (b − A x), N ← N − Ĵ⁺ Ĵ (Ĵ = A N)
Vec nullspace_reference(const Stack& s, Index n) {
  Vec x = Vec::Zero(n);
  Mat N = Mat::Identity(n, n);
  for (std::size_t lev = 0; lev < s.levels(); ++lev) {
    const Mat A = s.rows(lev), J = A * N, Jp = pinv(J, A.norm());
    x += N * (Jp * (s.targets(lev) - A * x));
    N -= Jp * J;
  }
  return x;
}

// Σ N^A_{i-1} A_i⁺ b_i
Vec chiaverini_reference(const Stack& s, Index n) {
  Vec x = Vec::Zero(n);
  Mat N = Mat::Identity(n, n);
  for (std::size_t lev = 0; lev < s.levels(); ++lev) {
    const Mat A = s.rows(lev), J = A * N;
    x += N * (pinv(A, A.norm()) * s.targets(lev));
    N -= pinv(J, A.norm()) * J;
  }
  return x;
}

// eq. 40: Σ N_i M⁻¹ (A_i M⁻¹)⁺ b_i, N_{i+1} = N_i (I − M⁻¹ (A_i M⁻¹)⁺ A_i)
Vec unifying_reference(const Stack& s, const Mat& M, Index n) {
  const Mat Mi = M.inverse();
  Vec x = Vec::Zero(n);
  Mat N = Mat::Identity(n, n);
  for (std::size_t lev = 0; lev < s.levels(); ++lev) {
    const Mat A = s.rows(lev), B = A * Mi, K = Mi * pinv(B, B.norm());
    x += N * (K * s.targets(lev));
    N = N * (Mat::Identity(n, n) - K * A);
  }
  return x;
}

// x += N J̄ (b − A x), J̄ = L⁻ᵀ (J L⁻ᵀ)⁺, N −= J̄ J (J = A N, M = L Lᵀ)
Vec operational_space_reference(const Stack& s, const Mat& M, Index n) {
  const Mat L = M.llt().matrixL();
  const Mat Lit = L.transpose().inverse();
  Vec x = Vec::Zero(n);
  Mat N = Mat::Identity(n, n);
  for (std::size_t lev = 0; lev < s.levels(); ++lev) {
    const Mat A = s.rows(lev), J = A * N, Jbar = Lit * pinv(J * Lit, (A * Lit).norm());
    x += N * (Jbar * (s.targets(lev) - A * x));
    N -= Jbar * J;
  }
  return x;
}

// nested SVD null spaces: y = V_r Σ_r⁻¹ U_rᵀ (b − A x), x += Z y, Z ← Z null(A Z); with a
// metric W, the tie-break z = −(ZᵀWZ)⁻¹ ZᵀW x
Vec reference_recursion(const Stack& s, Index n, const Mat* W) {
  Vec x = Vec::Zero(n);
  Mat Z = Mat::Identity(n, n);
  for (std::size_t lev = 0; lev < s.levels() && Z.cols() > 0; ++lev) {
    const Mat A = s.rows(lev), K = A * Z;
    Eigen::JacobiSVD<Mat> svd(K, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Vec& sv = svd.singularValues();
    Index r = 0;
    while (r < sv.size() && sv(r) > 1e-9 * A.norm()) ++r;
    const Vec c = s.targets(lev) - A * x;
    const Mat Vr = svd.matrixV().leftCols(r), Ur = svd.matrixU().leftCols(r);
    x += Z * (Vr * (sv.head(r).cwiseInverse().asDiagonal() * (Ur.transpose() * c)));
    Z = (Z * svd.matrixV().rightCols(K.cols() - r)).eval();
  }
  if (W != nullptr && Z.cols() > 0) {
    const Mat G = Z.transpose() * *W * Z;
    x -= Z * G.llt().solve(Z.transpose() * (*W * x));
  }
  return x;
}

// the reference solver against the recursion on stacks with dependent rows (a level's rows
// repeated in the next), with and without a metric
void test_reference_equals_nested_svd() {
  std::mt19937 rng(11);
  const std::vector<std::vector<Index>> layouts = {{3, 4, 5}, {4, 9}, {2, 2, 2, 2}, {12}, {6, 6}};
  for (const auto& rows : layouts) {
    const Index n = 10;
    Stack s = random_stack(rng, n, rows);
    if (s.levels() > 1) s.A.row(s.starts[1]) = 2.0 * s.A.row(0);   // a dependent row
    const Mat W = random_spd(rng, n);
    prioik::ReferenceSolver plain(s.starts, n, prioik::ReferenceOptions{});
    const auto& rp = plain.solve(s.arrays());
    CHECK(rp.solved && rp.finite && rp.flops > 0.0 && rp.sweeps > 0);
    CHECK(close(as_vec(rp.x), reference_recursion(s, n, nullptr)));
    prioik::ReferenceOptions o;
    o.metric.assign(W.data(), W.data() + n * n);
    prioik::ReferenceSolver metric(s.starts, n, o);
    const auto& rm = metric.solve(s.arrays());
    CHECK(rm.solved && rm.finite && rm.metric_positive_definite);
    CHECK(close(as_vec(rm.x), reference_recursion(s, n, &W)));
  }
}

// SNS: without bounds NullspaceSolver's answer bit for bit; under a box too tight for the
// tasks every answer within the box, every scaling in [0, 1]; a bounds row on two columns
// refused
void test_sns_stays_in_the_box() {
  std::mt19937 rng(5);
  const Index n = 9;
  const Stack free_stack = random_stack(rng, n, {2, 3, 1});
  prioik::SnsSolver unbounded(free_stack.starts, n, prioik::SnsOptions{});
  prioik::NullspaceSolver ns(free_stack.starts, n, prioik::NullspaceOptions{});
  const Vec none = Vec::Zero(free_stack.starts.back());
  const auto& ru = unbounded.solve(free_stack.arrays(), none.data(), none.data());
  CHECK(ru.solved && ru.finite && ru.exact);
  CHECK(as_vec(ru.x) == as_vec(ns.solve(free_stack.arrays()).x));
  for (double half_width : {0.05, 0.3, 2.0}) {
    Stack s = random_stack(rng, n, {n, 2, 3, 1});
    s.A.topRows(n) = Mat::Identity(n, n);
    s.b.head(n).setZero();
    const Vec lower = Vec::Constant(s.starts.back(), -half_width);
    const Vec upper = Vec::Constant(s.starts.back(), half_width);
    prioik::SnsOptions o;
    o.bounds_level = true;
    prioik::SnsSolver sns(s.starts, n, o);
    const auto& r = sns.solve(s.arrays(), lower.data(), upper.data());
    CHECK(r.solved && r.finite && r.flops > 0.0);
    for (Index j = 0; j < n; ++j) CHECK(std::fabs(r.x[j]) <= half_width * (1.0 + 1e-9));
    for (Index lev = 1; lev < 4; ++lev)
      CHECK(r.task_scaling[lev] >= 0.0 && r.task_scaling[lev] <= 1.0);
    const Index rounds = r.saturated_count[1] + r.saturated_count[2] + r.saturated_count[3];
    if (half_width == 0.05) CHECK(rounds > 0 && !r.exact);
    s.A(0, 1) = 1.0;                    // the first bounds row on two columns
    CHECK(!sns.solve(s.arrays(), lower.data(), upper.data()).solved);
    CHECK(sns.result().bounds == prioik::SnsBounds::not_single_column &&
          sns.result().bad_entry == 0);
  }
}

void test_each_solver_equals_its_recursion() {
  std::mt19937 rng(7);
  const std::vector<std::vector<Index>> layouts = {{3, 4, 5}, {4, 9}, {2, 2, 2, 2}, {12}};
  for (const auto& rows : layouts) {
    const Index n = 10;
    const Stack s = random_stack(rng, n, rows);
    const Mat M = random_spd(rng, n);
    prioik::NullspaceSolver ns(s.starts, n, prioik::NullspaceOptions{});
    const auto& rn = ns.solve(s.arrays());
    CHECK(rn.solved && rn.finite && rn.flops > 0.0);
    CHECK(close(as_vec(rn.x), nullspace_reference(s, n)));
    prioik::ChiaveriniSolver ch(s.starts, n, prioik::ChiaveriniOptions{});
    const auto& rc = ch.solve(s.arrays());
    CHECK(rc.solved && rc.finite && rc.flops > 0.0);
    CHECK(close(as_vec(rc.x), chiaverini_reference(s, n)));
    prioik::UnifyingSolver un(s.starts, n, 1e-9);
    const auto& ru = un.solve(s.arrays(), M.data());
    CHECK(ru.solved && ru.mass_positive_definite && ru.finite && ru.flops > 0.0);
    CHECK(close(as_vec(ru.x), unifying_reference(s, M, n)));
    prioik::OperationalSpaceSolver os(s.starts, n, prioik::OperationalSpaceOptions{});
    const auto& ro = os.solve(s.arrays(), M.data());
    CHECK(ro.solved && ro.finite && ro.flops > 0.0);
    CHECK(close(as_vec(ro.x), operational_space_reference(s, M, n)));
  }
}

void test_damped_nullspace_stays_bounded() {
  // a second level whose row tends to the first's: the damped step stays ≤ 1 / (2√λ) + 1
  const Index n = 4;
  Stack s;
  s.starts = {0, 1, 2};
  s.A = Mat::Zero(2, n);
  s.A(0, 0) = 1.0;
  s.A(1, 0) = 1.0;
  s.A(1, 1) = 1e-9;
  s.b = Vec::Zero(2);
  s.b(1) = 1.0;
  s.w = Vec::Ones(2);
  prioik::NullspaceOptions o;
  o.damping = 1e-2;
  prioik::NullspaceSolver ns(s.starts, n, o);
  const auto& r = ns.solve(s.arrays());
  CHECK(r.finite && as_vec(r.x).norm() <= 1.0 / (2.0 * std::sqrt(1e-2)) + 1.0);
  CHECK(std::fabs(r.x[0]) <= 1e-15);          // the first level is met exactly
}

void test_bad_input() {
  std::mt19937 rng(3);
  const Index n = 5;
  Stack s = random_stack(rng, n, {2, 3});
  prioik::NullspaceSolver ns(s.starts, n, prioik::NullspaceOptions{});
  s.A(1, 2) = std::numeric_limits<double>::quiet_NaN();
  bool threw = false;
  try {
    ns.solve(s.arrays());
  } catch (const prioik::InputError&) {
    threw = true;
  }
  CHECK(threw);
  s.A(1, 2) = 1.0;
  Mat M = -Mat::Identity(n, n);
  prioik::UnifyingSolver un(s.starts, n, 1e-9);
  CHECK(!un.solve(s.arrays(), M.data()).mass_positive_definite);
  prioik::OperationalSpaceSolver os(s.starts, n, prioik::OperationalSpaceOptions{});
  CHECK(!os.solve(s.arrays(), M.data()).solved);
  threw = false;
  try {
    prioik::ChiaveriniSolver bad({0, 3, 2}, n, prioik::ChiaveriniOptions{});
  } catch (const prioik::InputError&) {
    threw = true;
  }
  CHECK(threw);
  threw = false;
  try {
    prioik::ReferenceOptions o;
    o.level_damping = {1.0};
    prioik::ReferenceSolver bad(s.starts, n, o);
  } catch (const prioik::InputError&) {
    threw = true;
  }
  CHECK(threw);
}

}  // namespace

int main() {
  test_each_solver_equals_its_recursion();
  test_reference_equals_nested_svd();
  test_sns_stays_in_the_box();
  test_damped_nullspace_stays_bounded();
  test_bad_input();
  std::printf(prioik_test::failures == 0 ? "closed-form tests: all passed\n"
                                         : "closed-form tests: %d failed\n",
              prioik_test::failures);
  return prioik_test::failures == 0 ? 0 : 1;
}
