// The prepared control step (control_step.hpp): frame placements, the tasks' rows by
// rows.hpp's writers, the velocity targets, the active set's solve and the integration.
#include "prioik/control_step.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "busy_guard.hpp"

namespace prioik {

namespace {

using rows::ConstIndices;
using rows::ConstMatrix;
using rows::ConstVector;
using rows::Index;
using rows::Matrix;
using rows::Vector;

constexpr double kEps = std::numeric_limits<double>::epsilon();
// a unit-norm part of q (a quaternion, a unit complex) off norm 1 by more is refused
// (robots.models.UNIT_NORM_TOL)
constexpr double kUnitNormTol = 1e-6;

ConstVector cvec(const double* p, Index n) { return ConstVector{p, n, 1}; }
ConstMatrix cmat(const double* p, Index r, Index c) { return ConstMatrix{p, r, c, c, 1}; }
ConstIndices cidx(const std::vector<std::int64_t>& v) {
    return ConstIndices{v.data(), static_cast<Index>(v.size()), 1};
}

// The frame writer of one frame op at its placement (placement updated by the caller).
void write_frame(const FrameOp& op, const ConstMatrix& J, const double* zeros) {
    const rows::FrameArgs f{op.A,
                            op.Q,
                            J,
                            cvec(op.placement.t.data(), 3),
                            cmat(op.placement.R.data(), 3, 3),
                            cidx(op.spec),
                            cmat(op.geo.data(), 5, 3),
                            cvec(zeros, 6),
                            cvec(zeros, 6)};
    const double* r = op.ref.data();
    if (op.position_only) {
        rows::point_rows(f, cvec(r, 3), cvec(r + 3, 3), cvec(zeros, 3), true);
    } else {
        rows::frame_rows(f, cvec(r, 3), cvec(r + 3, 3), cvec(zeros, 3), cmat(r + 6, 3, 3),
                         cvec(r + 15, 3), cvec(zeros, 3));
    }
}

// pinocchio's SE(3) integrate of a free flyer (q: position, quaternion x y z w; v: the
// local twist, linear then angular, already scaled by dt): q ⊕ exp6(v), the quaternion
// of the same sign as q's, renormalised to first order (special-euclidean.hpp,
// explog-quaternion.hpp).
void integrate_free_flyer(const double* q, const double* v, double* out) {
    const double w0 = v[3], w1 = v[4], w2 = v[5];
    const double t2 = w0 * w0 + w1 * w1 + w2 * w2;
    const double t2e = t2 + kEps * kEps;
    const double t = std::sqrt(t2e);
    const double st = std::sin(t), ct = std::cos(t);
    const double inv_t2 = 1.0 / t2e;
    static const double ts_prec = std::pow(kEps, 1.0 / 4.0);
    const double alpha_wxv = t < ts_prec ? 0.5 - t2e / 24.0 : (1.0 - ct) * inv_t2;
    const double alpha_w2 = t < ts_prec ? 1.0 / 6.0 - t2e / 120.0 : (t - st) * inv_t2 / t;
    // w x v and w x (w x v)
    const double c0 = w1 * v[2] - w2 * v[1], c1 = w2 * v[0] - w0 * v[2], c2 = w0 * v[1] - w1 * v[0];
    const double d0 = w1 * c2 - w2 * c1, d1 = w2 * c0 - w0 * c2, d2 = w0 * c1 - w1 * c0;
    const double p0 = v[0] + alpha_wxv * c0 + alpha_w2 * d0;
    const double p1 = v[1] + alpha_wxv * c1 + alpha_w2 * d1;
    const double p2 = v[2] + alpha_wxv * c2 + alpha_w2 * d2;
    // exp3 of w (pinocchio compares |w|² with the Taylor threshold)
    const double tq = std::sqrt(t2 + kEps * kEps);
    double ex, ey, ez, ew;
    if (t2 > ts_prec) {
        const double ha = 0.5 * tq, s = std::sin(ha);
        ex = s * (w0 / tq);
        ey = s * (w1 / tq);
        ez = s * (w2 / tq);
        ew = std::cos(ha);
    } else {
        const double h = t2 / 4.0;
        const double f = 0.5 * (1.0 - h / 6.0 + h * h / 120.0);
        ex = f * w0;
        ey = f * w1;
        ez = f * w2;
        ew = 1.0 - h / 2.0 + h * h / 24.0;
    }
    const double qx = q[3], qy = q[4], qz = q[5], qw = q[6];
    // the translation: q's rotation of p (Eigen's _transformVector), plus q's position
    double u0 = qy * p2 - qz * p1, u1 = qz * p0 - qx * p2, u2 = qx * p1 - qy * p0;
    u0 += u0;
    u1 += u1;
    u2 += u2;
    out[0] = p0 + qw * u0 + (qy * u2 - qz * u1) + q[0];
    out[1] = p1 + qw * u1 + (qz * u0 - qx * u2) + q[1];
    out[2] = p2 + qw * u2 + (qx * u1 - qy * u0) + q[2];
    // the rotation: q * exp3(w), the sign of q's, then first-order normalisation
    double rw = qw * ew - qx * ex - qy * ey - qz * ez;
    double rx = qw * ex + qx * ew + qy * ez - qz * ey;
    double ry = qw * ey + qy * ew + qz * ex - qx * ez;
    double rz = qw * ez + qz * ew + qx * ey - qy * ex;
    const double dot = rx * qx + ry * qy + rz * qz + rw * qw;
    if (dot < 0.0) {
        rx = -rx;
        ry = -ry;
        rz = -rz;
        rw = -rw;
    }
    const double n2 = rx * rx + ry * ry + rz * rz + rw * rw;
    const double alpha = (3.0 - n2) / 2.0;
    out[3] = rx * alpha;
    out[4] = ry * alpha;
    out[5] = rz * alpha;
    out[6] = rw * alpha;
}

}  // namespace

void FramePlacement::update() {
    const ConstMatrix& Rj = joint_R;
    const double* Rl = local_R.data();
    for (Index i = 0; i < 3; ++i) {
        for (Index j = 0; j < 3; ++j)
            R[3 * i + j] = Rj(i, 0) * Rl[j] + Rj(i, 1) * Rl[3 + j] + Rj(i, 2) * Rl[6 + j];
        t[i] = joint_t[i] + (Rj(i, 0) * local_t[0] + Rj(i, 1) * local_t[1] +
                             Rj(i, 2) * local_t[2]);
    }
}

ControlStep::ControlStep(ActiveSetSolver& solver, ControlStepArrays arrays, Index nq,
                         double dt, std::vector<std::int64_t> unit,
                         std::vector<JointSegment> joints, bool integrable)
    : solver_(solver),
      arrays_(arrays),
      nq_(nq),
      nv_(solver.layout().n),
      dt_(dt),
      unit_(std::move(unit)),
      joints_(std::move(joints)),
      integrable_(integrable) {
    const ActiveSetLayout& layout = solver.layout();
    if (arrays.A.rows != layout.M || arrays.A.cols != layout.n)
        throw std::invalid_argument("the stack's arrays are not of the solver's layout");
    bool any_equality = false;
    for (std::int8_t e : layout.row_eq) any_equality = any_equality || e != 0;
    try_first_ = solver.options().warm_start && any_equality;
    zeros_.assign(static_cast<size_t>(std::max<Index>(nv_, 6)), 0.0);
    qa_.assign(static_cast<size_t>(std::max<Index>(nv_, 1)), 0.0);
    vdt_.assign(static_cast<size_t>(std::max<Index>(nv_, 1)), 0.0);
    result_.q_next.assign(static_cast<size_t>(nq), 0.0);
    result_.velocity.assign(static_cast<size_t>(nv_), 0.0);
}

Index ControlStep::add_frame(FrameOp op) {
    frames_.push_back(std::move(op));
    return static_cast<Index>(frames_.size()) - 1;
}

Index ControlStep::add_com(ComOp op) {
    coms_.push_back(std::move(op));
    return static_cast<Index>(coms_.size()) - 1;
}

Index ControlStep::add_posture(PostureOp op) {
    postures_.push_back(std::move(op));
    return static_cast<Index>(postures_.size()) - 1;
}

Index ControlStep::add_limits(LimitOp op) {
    limits_.push_back(std::move(op));
    return static_cast<Index>(limits_.size()) - 1;
}

Index ControlStep::add_region(RegionOp op) {
    const size_t k = op.lo.size();
    op.y.assign(k, 0.0);
    op.yd.assign(k, 0.0);
    op.vmax.assign(k, std::numeric_limits<double>::infinity());
    if (op.on_frame) {
        op.point_rows.assign(static_cast<size_t>(3 * nv_), 0.0);
        op.point_values.assign(18, 0.0);
    }
    regions_.push_back(std::move(op));
    return static_cast<Index>(regions_.size()) - 1;
}

void ControlStep::add_cap(Index start, Index stop, double cap) {
    caps_.push_back({static_cast<double>(start), static_cast<double>(stop), cap});
}

void ControlStep::set_hard(std::vector<std::int64_t> levels, double tol) {
    for (std::int64_t i : levels)
        if (i < 0 || i >= solver_.layout().k)
            throw std::invalid_argument("a hard level is not a level of the layout");
    hard_ = std::move(levels);
    hard_tol_ = tol;
}

bool ControlStep::hard_levels_clear() const {
    const ActiveSetLayout& layout = solver_.layout();
    const ControlStepArrays& a = arrays_;
    const std::vector<double>& x = solver_.result().x;
    for (std::int64_t level : hard_) {
        double terms = 0.0, rows_sq = 0.0;
        for (Index j = layout.starts[level]; j < layout.starts[level + 1]; ++j) {
            double ax = 0.0, abs_ax = 0.0, row_sq = 0.0;
            for (Index c = 0; c < nv_; ++c) {
                const double v = a.A(j, c);
                ax += v * x[c];
                abs_ax += std::abs(v) * std::abs(x[c]);
                row_sq += v * v;
            }
            const double target = layout.row_eq[j] ? a.b[j]
                                                   : std::min(std::max(ax, a.lower[j]), a.upper[j]);
            const double w = a.sqrt_weight[j];
            const double term = w * (abs_ax + std::abs(target));
            terms += term * term;
            rows_sq += w * w * row_sq;
        }
        const double scale = std::sqrt(terms) + std::sqrt(rows_sq);
        // (squares beyond float64's safe range: not decided here)
        if (!(scale > 1e-150 && scale < 1e150)) return false;
        if (!(solver_.result().res[level] <= 0.5 * hard_tol_ * scale)) return false;
    }
    return true;
}

bool ControlStep::state_is_valid(const double* q) const {
    return rows::state_is_valid(cvec(q, nq_), cvec(zeros_.data(), 0), cidx(unit_), kUnitNormTol);
}

void ControlStep::write_rows(const double* q) {
    const ControlStepArrays& a = arrays_;
    const double* zeros = zeros_.data();
    for (FrameOp& op : frames_) {
        op.placement.update();
        write_frame(op, a.J, zeros);
    }
    for (const ComOp& op : coms_) {
        const Index k = static_cast<Index>(op.axes.size());
        rows::com_rows(a.A, a.Q, op.start, a.Jcom, a.com, cvec(zeros, 3), cidx(op.axes),
                       cvec(op.ref.data(), k), cvec(op.ref.data() + k, k), cvec(zeros, k),
                       true);
    }
    for (const PostureOp& op : postures_)
        rows::posture_error(a.Q, op.start, cvec(q, nq_), cvec(op.ref.data(), nq_), cidx(op.iq));
    for (const LimitOp& op : limits_) {
        const Index na = static_cast<Index>(op.iq.size());
        const Vector qa{qa_.data(), na, 1};
        if (op.bounds)
            rows::bounds_at(a.lower, a.upper, cvec(q, nq_), cvec(zeros, nv_), cidx(op.iq),
                            cmat(op.lim.data(), 3, na), cvec(op.params.data(), 6), qa);
        else
            rows::activation_at(a.A, a.Q, cvec(q, nq_), cidx(op.iq), cmat(op.lim.data(), 3, na),
                                cvec(op.params.data(), 4), qa);
    }
    write_regions();
}

void ControlStep::write_regions() {
    const ControlStepArrays& a = arrays_;
    const double* zeros = zeros_.data();
    for (RegionOp& op : regions_) {
        const Index k = static_cast<Index>(op.lo.size());
        ConstMatrix Jp = a.Jcom;
        ConstVector p = a.com, drift = cvec(zeros, 3);
        double psign = 1.0;
        if (op.on_frame) {
            FrameOp& point = op.point;
            point.A = Matrix{op.point_rows.data(), 3, nv_, nv_, 1};
            point.Q = Matrix{op.point_values.data(), 6, 3, 3, 1};
            point.placement.update();
            std::fill(point.ref.begin(), point.ref.end(), 0.0);   // target 0: error -p
            write_frame(point, a.J, zeros);
            Jp = cmat(op.point_rows.data(), 3, nv_);
            p = cvec(op.point_values.data() + 3 * rows::ERROR, 3);
            drift = cvec(op.point_values.data() + 3 * rows::DRIFT, 3);
            psign = -1.0;
        }
        rows::region_rows(a.A, a.lower, a.upper, op.start, cmat(op.C.data(), k, 3), Jp, p,
                          psign, cvec(zeros, nv_), drift, cvec(op.lo.data(), k),
                          cvec(op.hi.data(), k), Vector{op.y.data(), k, 1},
                          Vector{op.yd.data(), k, 1}, cvec(op.vmax.data(), k), op.T, op.dt,
                          false);
    }
}

void ControlStep::targets() {
    const ControlStepArrays& a = arrays_;
    rows::velocity_targets(a.b, ConstMatrix{a.Q.data, a.Q.rows, a.Q.cols, a.Q.rs, a.Q.cs});
    for (const auto& cap : caps_) {
        const Index start = static_cast<Index>(cap[0]), stop = static_cast<Index>(cap[1]);
        double acc = 0.0;
        for (Index i = start; i < stop; ++i) acc += a.b[i] * a.b[i];
        const double norm = std::sqrt(acc);
        if (norm > cap[2]) {
            const double s = cap[2] / norm;
            for (Index i = start; i < stop; ++i) a.b[i] *= s;
        }
    }
}

SolveCode ControlStep::solve() {
    const ControlStepArrays& a = arrays_;
    const double *A = a.A.data, *b = a.b.data, *lo = a.lower.data, *up = a.upper.data;
    const double* sw = a.sqrt_weight;
    SolveCode code = try_first_ ? solver_.equality_first(A, b, lo, up, sw) : SolveCode::not_tried;
    bool first = code != SolveCode::not_tried;
    if (!first) code = solver_.solve(A, b, lo, up, sw);
    if (code == SolveCode::other && solver_.options().warm_start &&
        solver_.result().ambiguous > 0) {
        // ambiguous or flagged rank decisions: the cold answer (Prepared.solve_checked)
        solver_.reset();
        first = false;
        code = solver_.solve(A, b, lo, up, sw);
    }
    result_.equality_first = first;
    return code;
}

StepCode ControlStep::step(const double* q) {
    BusyGuard guard(busy_);
    if (!state_is_valid(q)) {
        result_.code = static_cast<int>(StepCode::invalid_state);
        return StepCode::invalid_state;
    }
    write_rows(q);
    targets();
    const auto t0 = std::chrono::steady_clock::now();
    const SolveCode code = solve();
    result_.solve_time_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    result_.code = static_cast<int>(code);
    if (code == SolveCode::clean || code == SolveCode::infeasible) {
        if (!hard_.empty() && !hard_levels_clear()) return StepCode::hard_unclear;
        const std::vector<double>& x = solver_.result().x;
        std::copy(x.begin(), x.end(), result_.velocity.begin());
        if (integrable_) integrate(q, result_.velocity.data(), result_.q_next.data());
    }
    return static_cast<StepCode>(code);
}

void ControlStep::integrate(const double* q, const double* v, double* out) const {
    double vdt[6];
    for (const JointSegment& s : joints_) {
        if (s.free_flyer) {
            for (Index i = 0; i < 6; ++i) vdt[i] = v[s.idx_v + i] * dt_;
            integrate_free_flyer(q + s.idx_q, vdt, out + s.idx_q);
        } else {
            for (Index i = 0; i < s.nq; ++i)
                out[s.idx_q + i] = q[s.idx_q + i] + v[s.idx_v + i] * dt_;
        }
    }
}

}  // namespace prioik
