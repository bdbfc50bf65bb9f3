// The row writers' own tests, without Python (ctest; `make asan` runs them under
// -fsanitize=address,undefined): log3 against the rotation it came from (near 0 and
// pi too), a frame's rows against Eigen's cross products on row- and column-major
// Jacobians, the bound, activation and target formulas, state_is_valid.
#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "prioik/rows.hpp"
#include "check.hpp"

using namespace prioik::rows;
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ColMat = Eigen::MatrixXd;

namespace {

template <class M>
Matrix view(M& m) {
  return Matrix{m.data(), m.rows(), m.cols(), m.rowStride(), m.colStride()};
}
template <class M>
ConstMatrix cview(const M& m) {
  return ConstMatrix{m.data(), m.rows(), m.cols(), m.rowStride(), m.colStride()};
}
Vector view(Eigen::VectorXd& v) { return Vector{v.data(), v.size(), 1}; }
ConstVector cview(const Eigen::VectorXd& v) { return ConstVector{v.data(), v.size(), 1}; }
ConstVector cview(const Eigen::Vector3d& v) { return ConstVector{v.data(), 3, 1}; }
ConstIndices cview(const std::vector<std::int64_t>& v) {
  return ConstIndices{v.data(), static_cast<Index>(v.size()), 1};
}

void test_log3_returns_the_rotation_vector() {
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  const double pi = 3.141592653589793;
  for (double theta : {0.0, 1e-9, 5e-5, 1e-4, 0.5, 2.0, pi - 2e-3, pi - 1e-4, pi}) {
    for (int trial = 0; trial < 20; ++trial) {
      Eigen::Vector3d u(g(rng), g(rng), g(rng));
      if (trial < 3) u = Eigen::Vector3d::Unit(trial);
      u.normalize();
      const Eigen::Matrix3d R = Eigen::AngleAxisd(theta, u).toRotationMatrix();
      Eigen::VectorXd out = Eigen::VectorXd::Zero(5);
      log3(cview(R), view(out), 1);
      const Eigen::Vector3d w = out.segment<3>(1);
      CHECK(out[0] == 0.0 && out[4] == 0.0);
      const double err = std::min((w - theta * u).norm(), (w + theta * u).norm());
      CHECK(err <= 1e-7 * std::max(theta, 1.0));     // the sign of u is free at pi
      if (theta < pi - 1e-3) CHECK((w - theta * u).norm() <= 1e-12);
    }
  }
}

// A frame pose's rows (6 rows at s = 1 of A: 8 x n) against Eigen, for J stored
// row-major and column-major: the same bits.
void test_frame_rows_equal_eigens_cross_products() {
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  const Index n = 7, m = 8;
  ColMat Jc(6, n);
  for (Index i = 0; i < 6; ++i)
    for (Index j = 0; j < n; ++j) Jc(i, j) = g(rng);
  const RowMat Jr = Jc;
  const Eigen::Vector3d t(g(rng), g(rng), g(rng)), axis = Eigen::Vector3d(1, 2, 3).normalized();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, axis).toRotationMatrix();
  RowMat geo = RowMat::Zero(5, 3);
  geo.row(GEO_OFFSET) << 0.1, -0.2, 0.05;
  geo.block(GEO_ROTATION, 0, 3, 3) = Eigen::Matrix3d::Identity();
  const std::vector<std::int64_t> spec = {1, POSE, 1, 0, 2, 3, 6};
  const Eigen::Vector3d x(0.3, 0.2, 0.1), zero = Eigen::Vector3d::Zero();
  Eigen::VectorXd aj = Eigen::VectorXd::Zero(6), vj = Eigen::VectorXd::Zero(6);
  RowMat out_r[2], q_r[2];
  for (int layout = 0; layout < 2; ++layout) {
    RowMat A = RowMat::Constant(m, n, 9.0), Q = RowMat::Constant(6, m, 9.0);
    FrameArgs f{view(A), view(Q), layout == 0 ? cview(Jr) : cview(Jc), cview(t), cview(R),
                cview(spec), cview(geo), cview(aj), cview(vj)};
    frame_rows(f, cview(x), cview(zero), cview(zero), cview(R), cview(zero), cview(zero));
    out_r[layout] = A;
    q_r[layout] = Q;
  }
  CHECK(out_r[0] == out_r[1] && q_r[0] == q_r[1]);
  const RowMat& A = out_r[0];
  const RowMat& Q = q_r[0];
  const Eigen::Vector3d p = t + R * geo.row(GEO_OFFSET).transpose();
  for (Index c = 0; c < n; ++c) {
    const bool on = c == 0 || c == 2 || c == 3 || c == 6;
    const Eigen::Vector3d lin = Jc.block<3, 1>(0, c) + Jc.block<3, 1>(3, c).cross(p);
    for (Index i = 0; i < 3; ++i) {
      CHECK(std::abs(A(1 + i, c) - (on ? lin[i] : 0.0)) <= 1e-14);
      CHECK(A(4 + i, c) == (on ? Jc(3 + i, c) : 0.0));
    }
    CHECK(A(0, c) == 9.0 && A(7, c) == 9.0);     // other rows untouched
  }
  for (Index i = 0; i < 3; ++i) {
    CHECK(std::abs(Q(ERROR, 1 + i) - (x - p)[i]) <= 1e-15);
    CHECK(Q(ERROR, 4 + i) == 0.0);                 // R* = R: no orientation error
    CHECK(Q(DRIFT, 1 + i) == 0.0 && Q(DRIFT, 4 + i) == 0.0);
  }
}

void test_bounds_and_activation_formulas() {
  const double inf = std::numeric_limits<double>::infinity();
  Eigen::VectorXd qa(3), va(3), lo(3), hi(3), vmax(3), width(3);
  qa << 0.0, 0.95, -2.0;
  va << 1.0, 2.0, -1.0;
  lo << -1.0, -1.0, -inf;
  hi << 1.0, 1.0, inf;
  vmax << 2.0, 2.0, inf;
  width << 0.1, 0.1, 1.0;
  Eigen::VectorXd lower = Eigen::VectorXd::Zero(4), upper = Eigen::VectorXd::Zero(4);
  velocity_bounds(view(lower), view(upper), 1, cview(qa), cview(lo), cview(hi), cview(vmax),
                  0.5, true, true);
  CHECK(lower[1] == -2.0 && upper[1] == 2.0);              // the speed limit binds
  CHECK(lower[2] == -2.0 && std::abs(upper[2] - 0.1) <= 1e-15);
  CHECK(lower[3] == -inf && upper[3] == inf);               // a continuous joint
  acceleration_bounds(view(lower), view(upper), 1, cview(qa), cview(va), cview(lo), cview(hi),
                      cview(vmax), 0.1, 0.01, true, true);
  for (Index k = 1; k < 4; ++k) CHECK(lower[k] <= upper[k]);
  CHECK(upper[2] < 0.0);                                    // joint 1 must brake
  RowMat A = RowMat::Zero(3, 5), Q = RowMat::Zero(6, 3);
  const Index active = limit_activation_rows(view(A), view(Q), 0, 2, cview(qa), cview(lo),
                                             cview(hi), cview(width), 10.0, 2.0);
  CHECK(active == 1);
  CHECK(A(1, 3) == 1.0 && A(0, 2) == 0.0 && A(2, 4) == 0.0);
  CHECK(std::abs(Q(ERROR, 1) - (-0.5 * 0.05)) <= 1e-12);   // depth 0.05 of 0.1, pushed down
  CHECK(Q(KP, 1) == 10.0 && std::abs(Q(KD, 1) - 1.0) <= 1e-12);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(3), v = Eigen::VectorXd::Zero(5);
  velocity_targets(view(b), cview(Q));
  CHECK(b[0] == 0.0 && std::abs(b[1] - 10.0 * Q(ERROR, 1)) <= 1e-15);
  v[3] = 0.5;
  acceleration_targets(cview(A), view(b), cview(Q), cview(v));
  CHECK(std::abs(b[1] - (Q(KD, 1) * (0.0 - 0.5) + 10.0 * Q(ERROR, 1))) <= 1e-15);
}

void test_state_is_valid() {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(9), v = Eigen::VectorXd::Zero(8);
  q[6] = 1.0;                                               // the base's quaternion (x y z w)
  const std::vector<std::int64_t> unit = {3, 4};
  CHECK(state_is_valid(cview(q), cview(v), cview(unit), 1e-6));
  q[6] = 1.1;
  CHECK(!state_is_valid(cview(q), cview(v), cview(unit), 1e-6));
  q[6] = 1.0;
  v[2] = std::numeric_limits<double>::quiet_NaN();
  CHECK(!state_is_valid(cview(q), cview(v), cview(unit), 1e-6));
}

}  // namespace

int main() {
  test_log3_returns_the_rotation_vector();
  test_frame_rows_equal_eigens_cross_products();
  test_bounds_and_activation_formulas();
  test_state_is_valid();
  std::printf(prioik_test::failures == 0 ? "row tests: all passed\n" : "row tests: %d failed\n", prioik_test::failures);
  return prioik_test::failures == 0 ? 0 : 1;
}
