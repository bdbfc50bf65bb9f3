// The certificate's dense steps (core/src/certificate_linalg.hpp), without Python (ctest;
// `make asan` runs them under -fsanitize=address,undefined): the row-pivoted LQ and its
// reflectors against the matrix they factor, and the preconditioned one-sided Jacobi SVD
// the certificate builds from them (Lᵀ's rows rotated) against Eigen's singular values,
// on random, rank-deficient and wide or tall matrices.
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "../src/certificate_linalg.hpp"
#include "check.hpp"

using prioik::Index;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

namespace {

/// rows × cols Gaussian entries of rank `rank` (a product of two Gaussian factors)
Mat random_matrix(std::mt19937& rng, Index rows, Index cols, Index rank) {
  std::normal_distribution<double> g;
  Mat a(rows, rank), b(rank, cols);
  for (Index i = 0; i < rows; ++i)
    for (Index j = 0; j < rank; ++j) a(i, j) = g(rng);
  for (Index i = 0; i < rank; ++i)
    for (Index j = 0; j < cols; ++j) b(i, j) = g(rng);
  return a * b;
}

/// Π P = [L 0] H_{m−1} ⋯ H_0 and the reflectors' product orthogonal, to 1e-13 ‖P‖
void the_lq_factors_its_rows(std::mt19937& rng, Index m, Index d, Index rank) {
  const Mat P = random_matrix(rng, m, d, rank);
  Mat F = P;
  std::vector<double> house(m * (d + 1)), norms(m), u(d);
  std::vector<Index> perm(m);
  prioik::cert::lq_rows(F.data(), m, d, d, house.data(), norms.data(), perm.data());
  const double tol = 1e-13 * std::max(1.0, P.norm());
  double worst = 0.0;
  for (Index i = 0; i < m; ++i) {
    for (Index c = i + 1; c < d; ++c) CHECK(F(i, c) == 0.0 || c >= m);
    for (Index c = 0; c < d; ++c) u[c] = c <= i ? F(i, c) : 0.0;
    prioik::cert::reflect_row(house.data(), m, d, u.data());
    for (Index c = 0; c < d; ++c) worst = std::max(worst, std::fabs(u[c] - P(perm[i], c)));
  }
  CHECK(worst <= tol);
  // Q Qᵀ = I: reflect_vector (Q y) undoes reflect_row (Qᵀ y); the rows of Z by
  // reflect_rows (two reflectors a pass) as each column by reflect_vector
  Mat Z = random_matrix(rng, d, 5, 5), Zq = Z;
  std::vector<double> proj(2 * 5);
  prioik::cert::reflect_rows(house.data(), m, d, Zq.data(), 5, 5, proj.data());
  double back = 0.0, rows = 0.0;
  for (Index c = 0; c < 5; ++c) {
    for (Index t = 0; t < d; ++t) u[t] = Z(t, c);
    prioik::cert::reflect_vector(house.data(), m, d, u.data());
    for (Index t = 0; t < d; ++t) rows = std::max(rows, std::fabs(u[t] - Zq(t, c)));
    prioik::cert::reflect_row(house.data(), m, d, u.data());
    for (Index t = 0; t < d; ++t) back = std::max(back, std::fabs(u[t] - Z(t, c)));
  }
  CHECK(rows <= 1e-13 * Z.norm());
  CHECK(back <= 1e-13 * Z.norm());
}

/// P's singular values as the certificate computes them (its m < d rows: LQ, then the
/// rows of Lᵀ rotated, accumulating G; Vt's first rows [G 0] Q) against Eigen's, and
/// P's rows read on those right vectors: P Vᵀ has orthogonal columns of norms σ
void the_preconditioned_jacobi_gives_the_singular_values(std::mt19937& rng, Index m,
                                                         Index d, Index rank) {
  const Mat P = random_matrix(rng, m, d, rank);
  Mat F = P;
  std::vector<double> house(m * (d + 1)), norms(m), Lt(m * m), sig(m);
  Mat Vt = Mat::Zero(m, d);
  prioik::cert::lq_rows(F.data(), m, d, d, house.data(), norms.data(), nullptr);
  for (Index i = 0; i < m; ++i)
    for (Index j = 0; j < m; ++j) Lt[i * m + j] = j >= i ? F(j, i) : 0.0;
  for (Index i = 0; i < m; ++i) Vt(i, i) = 1.0;
  prioik::cert::jacobi_rows(Lt.data(), m, m, m, Vt.data(), m, d, norms.data());
  for (Index i = 0; i < m; ++i) {
    sig[i] = std::sqrt(prioik::dot(Lt.data() + i * m, Lt.data() + i * m, m));
    prioik::cert::reflect_row(house.data(), m, d, Vt.data() + i * d);
  }
  std::sort(sig.begin(), sig.end(), [](double a, double b) { return a > b; });
  const Eigen::VectorXd ref = Eigen::JacobiSVD<Mat>(P).singularValues();
  const double tol = 1e-13 * std::max(1.0, ref(0));
  double worst = 0.0;
  for (Index i = 0; i < m; ++i) worst = std::max(worst, std::fabs(sig[i] - ref(i)));
  CHECK(worst <= tol);
  const Mat ortho = Vt * Vt.transpose() - Mat::Identity(m, m);
  CHECK(ortho.cwiseAbs().maxCoeff() <= 1e-13);
  const Mat C = P * Vt.transpose();     // orthogonal columns
  const Mat gram = C.transpose() * C;
  double off = 0.0;
  for (Index i = 0; i < m; ++i)
    for (Index j = 0; j < m; ++j)
      if (i != j) off = std::max(off, std::fabs(gram(i, j)));
  CHECK(off <= 1e-12 * ref(0) * ref(0));
}

}  // namespace

int main() {
  std::mt19937 rng(7);
  for (auto [m, d, rank] : {std::array<Index, 3>{1, 4, 1}, {5, 12, 5}, {7, 8, 3},
                            {20, 60, 20}, {30, 30, 30}, {30, 30, 12}, {45, 300, 40}}) {
    the_lq_factors_its_rows(rng, m, d, rank);
    the_preconditioned_jacobi_gives_the_singular_values(rng, m, d, rank);
  }
  if (prioik_test::failures) {
    std::printf("%d failure(s)\n", prioik_test::failures);
    return 1;
  }
  std::printf("certificate linalg: all passed\n");
  return 0;
}
