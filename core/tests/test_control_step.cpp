// The control step's own tests, without Python (ctest; `make asan` runs them under
// -fsanitize=address,undefined): a step over a random chain's Jacobians writes the rows
// the row writers write, solves them with its ActiveSetSolver and integrates; an invalid
// q is refused before anything is written; the free flyer's integration is the SE(3)
// exponential of the local twist (Eigen's, on the rotation matrix), of unit quaternion.
#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "check.hpp"
#include "prioik/active_set.hpp"
#include "prioik/control_step.hpp"

using namespace prioik;
using rows::ConstMatrix;
using rows::ConstVector;
using rows::Index;
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

namespace {

// A stack of three levels on n = 7 columns: joint-limit bounds (7 rows), a frame's
// position (3) with a max_rate cap, a posture (7).
struct Scene {
    static constexpr Index n = 7, M = 17;
    RowMat A = RowMat::Zero(M, n);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(M), lower = Eigen::VectorXd::Constant(M, -1e300),
                    upper = Eigen::VectorXd::Constant(M, 1e300),
                    sw = Eigen::VectorXd::Ones(M);
    RowMat Q = RowMat::Zero(6, M);
    Eigen::MatrixXd J;                       // 6 x n, column-major as pinocchio's
    Eigen::Vector3d joint_t{0.1, -0.2, 0.3};
    Eigen::Matrix3d joint_R;                 // column-major as pinocchio's
    std::vector<std::int64_t> iq{0, 1, 2, 3, 4, 5, 6};

    explicit Scene(unsigned seed) {
        std::mt19937 rng(seed);
        std::normal_distribution<double> g;
        J = Eigen::MatrixXd::NullaryExpr(6, n, [&] { return g(rng); });
        joint_R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
        A.block(0, 0, n, n).setIdentity();
        A.block(10, 0, n, n).setIdentity();
        for (Index i = 7; i < 10; ++i) Q(rows::KP, i) = 10.0;
        for (Index i = 10; i < 17; ++i) Q(rows::KP, i) = 1.0;
    }

    ActiveSetLayout layout() const {
        ActiveSetLayout l;
        l.n = n;
        l.M = M;
        l.k = 3;
        l.starts = {0, 7, 10, 17};
        l.row_eq.assign(M, 1);
        for (Index i = 0; i < 7; ++i) l.row_eq[i] = 0;
        return l;
    }

    ControlStepArrays arrays() {
        ControlStepArrays a;
        a.A = rows::Matrix{A.data(), M, n, n, 1};
        a.b = rows::Vector{b.data(), M, 1};
        a.lower = rows::Vector{lower.data(), M, 1};
        a.upper = rows::Vector{upper.data(), M, 1};
        a.sqrt_weight = sw.data();
        a.Q = rows::Matrix{Q.data(), 6, M, M, 1};
        a.J = ConstMatrix{J.data(), 6, n, 1, 6};
        return a;
    }
};

void add_tasks(ControlStep& step, Scene& s, const Eigen::Vector3d& target) {
    LimitOp lim;
    lim.bounds = true;
    lim.iq = s.iq;
    lim.lim.assign(21, 0.0);
    for (Index k = 0; k < 7; ++k) {
        lim.lim[k] = -2.0;
        lim.lim[7 + k] = 2.0;
        lim.lim[14 + k] = 3.0;
    }
    lim.params = {0.0, 0.002, 0.002, 1.0, 1.0, 0.0};
    step.add_limits(lim);
    FrameOp frame;
    frame.placement.joint_t = ConstVector{s.joint_t.data(), 3, 1};
    frame.placement.joint_R = ConstMatrix{s.joint_R.data(), 3, 3, 1, 3};
    frame.placement.local_t = {0.0, 0.0, 0.1};
    frame.placement.local_R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    frame.spec = {7, rows::POSITION, 1, 0, 1, 2, 3, 4, 5, 6};
    frame.geo = {0, 0, 0, 0, 0, 0.1, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    frame.ref[0] = target[0];
    frame.ref[1] = target[1];
    frame.ref[2] = target[2];
    frame.position_only = true;
    frame.A = step.stack_rows();
    frame.Q = step.per_row();
    step.add_frame(frame);
    PostureOp posture;
    posture.start = 10;
    posture.iq = s.iq;
    posture.ref.assign(7, 0.1);
    step.add_posture(posture);
    step.add_cap(7, 10, 0.5);
}

void test_a_step_writes_solves_and_integrates() {
    Scene s(11);
    ActiveSetSolver solver(s.layout(), ActiveSetOptions{});
    const Eigen::Vector3d target(0.5, 0.1, 0.4);
    ControlStep step(solver, s.arrays(), 7, 0.002, {}, {{0, 0, 7, 7, false}}, true);
    add_tasks(step, s, target);
    std::vector<double> q{0.1, -0.3, 0.2, 0.0, 0.4, -0.1, 0.3};
    const StepCode code = step.step(q.data());
    CHECK(code == StepCode::clean || code == StepCode::infeasible);
    // the frame's rows: J_lin + J_ang x p on every column, p = t + R (0, 0, 0.1)
    const Eigen::Vector3d p = s.joint_t + s.joint_R * Eigen::Vector3d(0, 0, 0.1);
    for (Index c = 0; c < 7; ++c) {
        const Eigen::Vector3d col =
            s.J.block<3, 1>(0, c) + s.J.block<3, 1>(3, c).cross(p);
        CHECK((s.A.block<3, 1>(7, c).transpose() - col.transpose()).norm() <= 1e-14);
    }
    // the capped target: ‖b‖ at most 0.5 along K e
    const Eigen::Vector3d e = target - p;
    const Eigen::Vector3d b = s.b.segment<3>(7);
    CHECK(std::abs(b.norm() - std::min(0.5, 10.0 * e.norm())) <= 1e-14);
    CHECK((b.normalized() - e.normalized()).norm() <= 1e-14);
    // posture targets, bounds, the answer and its integration
    for (Index k = 0; k < 7; ++k) {
        CHECK(s.b[10 + k] == 1.0 * (0.1 - q[k]));
        CHECK(s.lower[k] == std::max((-2.0 - q[k]) / 0.002, -3.0));
        CHECK(step.result().velocity[k] == solver.result().x[k]);
        CHECK(step.result().q_next[k] == q[k] + step.result().velocity[k] * 0.002);
    }
}

void test_an_invalid_state_writes_nothing() {
    Scene s(12);
    ActiveSetSolver solver(s.layout(), ActiveSetOptions{});
    ControlStep step(solver, s.arrays(), 7, 0.002, {}, {{0, 0, 7, 7, false}}, true);
    add_tasks(step, s, Eigen::Vector3d(0.5, 0.1, 0.4));
    std::vector<double> q(7, 0.0);
    q[3] = std::nan("");
    CHECK(step.step(q.data()) == StepCode::invalid_state);
    CHECK(s.b.isZero() && s.Q.row(rows::ERROR).isZero());
}

// the SE(3) exponential of a twist (v, w) by Eigen: rotation exp(w), translation
// V(w) v with V = I + (1 - cos t)/t² [w] + (t - sin t)/t³ [w]²
Eigen::Matrix<double, 7, 1> expected_free_flyer(const Eigen::Matrix<double, 7, 1>& q,
                                                const Eigen::Matrix<double, 6, 1>& v) {
    const Eigen::Vector3d lin = v.head<3>(), w = v.tail<3>();
    const double t = w.norm();
    Eigen::Matrix3d W;
    W << 0, -w[2], w[1], w[2], 0, -w[0], -w[1], w[0], 0;
    const Eigen::Matrix3d V = Eigen::Matrix3d::Identity() + (1 - std::cos(t)) / (t * t) * W +
                              (t - std::sin(t)) / (t * t * t) * W * W;
    const Eigen::Quaterniond q0(q[6], q[3], q[4], q[5]);
    const Eigen::Matrix3d R = q0.toRotationMatrix() * Eigen::AngleAxisd(t, w / t).toRotationMatrix();
    Eigen::Quaterniond r(R);
    if (r.coeffs().dot(q0.coeffs()) < 0) r.coeffs() *= -1.0;
    Eigen::Matrix<double, 7, 1> out;
    out.head<3>() = q.head<3>() + q0.toRotationMatrix() * (V * lin);
    out.tail<4>() = r.coeffs();
    return out;
}

void test_the_free_flyer_is_the_se3_exponential() {
    Scene s(13);
    ActiveSetSolver solver(s.layout(), ActiveSetOptions{});
    std::vector<std::int64_t> unit{3, 4};
    const double dt = 0.5;
    ControlStep step(solver, s.arrays(), 7, dt, unit, {{0, 0, 7, 6, true}}, true);
    std::mt19937 rng(4);
    std::normal_distribution<double> g;
    for (int trial = 0; trial < 50; ++trial) {
        Eigen::Matrix<double, 7, 1> q;
        Eigen::Vector4d quat(g(rng), g(rng), g(rng), g(rng));
        quat.normalize();
        q << g(rng), g(rng), g(rng), quat;
        Eigen::Matrix<double, 6, 1> v;
        for (Index i = 0; i < 6; ++i) v[i] = g(rng);
        Eigen::Matrix<double, 7, 1> out;
        step.integrate(q.data(), v.data(), out.data());
        const Eigen::Matrix<double, 7, 1> expect = expected_free_flyer(q, v * dt);
        CHECK((out - expect).norm() <= 1e-12 * std::max(1.0, expect.norm()));
        CHECK(std::abs(out.tail<4>().norm() - 1.0) <= 1e-14);
        CHECK(step.state_is_valid(out.data()));
    }
}

}  // namespace

int main() {
    test_a_step_writes_solves_and_integrates();
    test_an_invalid_state_writes_nothing();
    test_the_free_flyer_is_the_se3_exponential();
    std::printf(prioik_test::failures == 0 ? "control step tests: all passed\n"
                                           : "control step tests: %d failed\n",
                prioik_test::failures);
    return prioik_test::failures == 0 ? 0 : 1;
}
