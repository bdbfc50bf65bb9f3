// A prepared velocity-level control step (prioik.robots.ControlStep): from the joint
// placements and Jacobians pinocchio computed at q, one call writes every task's rows
// (the row writers of rows.hpp), forms the velocity targets b = xd* + K e (with the
// max_rate caps), solves the stack on a prepared ActiveSetSolver (the warm start's
// equality-first try, then the active set, and a cold re-solve after an ambiguous warm
// one: formulations/hierarchical_active_set.py, Prepared.solve_checked) and, on a clean
// answer, integrates q ⊕ q̇ dt.
//
// The step reads and writes through views fixed at prepare: pinocchio's Data (J, Jcom,
// com, each frame's parent joint placement oMi) and the stack's arrays (A, b, lower,
// upper, sqrt_weight, the per-row quantities Q). Everything else (the tasks' constant
// geometry, their references, scratch, the next configuration) is in the step's own
// workspace, allocated when a task is added; a step allocates nothing.
//
// Arithmetic: the row writers' and the active set's (IEEE double, no contraction).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <vector>

#include "prioik/active_set.hpp"
#include "prioik/rows.hpp"

namespace prioik {

/// What ControlStep::step returns: the active set's SolveCode, or invalid_state.
enum class StepCode : int {
    not_solved = 0,      ///< SolveCode::not_solved
    clean = 1,           ///< SolveCode::clean (q_next integrated)
    infeasible = 2,      ///< SolveCode::infeasible (q_next integrated)
    other = 3,           ///< SolveCode::other: the caller reads the solver's summary
    invalid_state = -3,  ///< q not finite or a unit-norm part not of norm 1: nothing done
    /// a clean answer whose hard levels (set_hard) are not clearly held: the caller
    /// checks them (result().code holds the kernel's code; q_next not written)
    hard_unclear = 4,
};

/// The views of pinocchio's Data and of the stack's arrays a step reads and writes.
struct ControlStepArrays {
    rows::Matrix A;              ///< m x n_v (row-major, C-contiguous)
    rows::Vector b, lower, upper;
    const double* sqrt_weight = nullptr;
    rows::Matrix Q;              ///< 6 x m per-row quantities (rows.hpp QRow)
    rows::ConstMatrix J;         ///< 6 x n_v world-frame joint Jacobians (data.J)
    rows::ConstMatrix Jcom;      ///< 3 x n_v (data.Jcom), when a task reads it
    rows::ConstVector com;       ///< 3 (data.com[0]), when a task reads it
};

/// One frame's world placement, oMf = oMi[parent] · (its placement in the parent joint).
struct FramePlacement {
    rows::ConstVector joint_t;   ///< data.oMi[parent].translation
    rows::ConstMatrix joint_R;   ///< data.oMi[parent].rotation
    std::array<double, 3> local_t{};
    std::array<double, 9> local_R{};  ///< row-major
    std::array<double, 3> t{};
    std::array<double, 9> R{};        ///< row-major, written by update()

    void update();
};

/// A frame task (position, point, orientation, pose, contact): rows.hpp's frame writers.
/// ref: x (3), xd (3), R* (9, row-major), w (3).
struct FrameOp {
    FramePlacement placement;
    std::vector<std::int64_t> spec;   ///< rows.hpp SpecField layout
    std::array<double, 15> geo{};     ///< 5 x 3 row-major (rows.hpp GeoRow)
    std::vector<double> ref = std::vector<double>(18, 0.0);
    bool position_only = true;
    rows::Matrix A, Q;                ///< where it writes (the stack's or a region's scratch)
};

/// The centre of mass on some axes. ref: x (axes), xd (axes).
struct ComOp {
    rows::Index start = 0;
    std::vector<std::int64_t> axes;
    std::vector<double> ref;
};

/// A posture: error q_ref[iq] - q[iq]. ref: q_ref (n_q).
struct PostureOp {
    rows::Index start = 0;
    std::vector<std::int64_t> iq;
    std::vector<double> ref;
};

/// Joint limits as bounds (rows.hpp bounds_at) or activation rows (activation_at).
struct LimitOp {
    bool bounds = true;
    std::vector<std::int64_t> iq;
    std::vector<double> lim;      ///< 3 x n_a row-major
    std::vector<double> params;   ///< bounds_at's 6 or activation_at's 4
};

/// A region lower <= C p <= upper on a frame's point (on_frame: the point's position
/// rows written by `point` into point_rows, 3 x n_v, and point_values, 6 x 3: a target
/// of 0 makes its error row -p) or on the centre of mass.
struct RegionOp {
    rows::Index start = 0;
    bool on_frame = false;
    FrameOp point;
    std::vector<double> point_rows, point_values;
    std::vector<double> C, lo, hi;           ///< k x 3 row-major, k, k (the references)
    std::vector<double> y, yd, vmax;         ///< scratch, and no speed limit (inf)
    double T = 0.0, dt = 0.0;
};

/// A joint's part of q and v for the integration: euclidean (n_q == n_v: q + v dt) or
/// a free flyer (pinocchio's SE(3) integrate: q ⊕ exp6(v dt), unit quaternion).
struct JointSegment {
    rows::Index idx_q = 0, idx_v = 0, nq = 0, nv = 0;
    bool free_flyer = false;
};

/// The step's answer, by name.
struct ControlStepResult {
    std::vector<double> q_next;    ///< n_q: q ⊕ q̇ dt (written on a clean answer)
    std::vector<double> velocity;  ///< n_v: q̇ (written on a clean answer)
    int code = 0;                  ///< StepCode
    bool equality_first = false;   ///< the answer is the equality-first try's
    double solve_time_s = 0.0;     ///< the active set's wall time
};

/// The prepared step over one stack layout and one pinocchio Data.
class ControlStep {
public:
    /// solver: the stack layout's prepared active set (held by reference: the caller
    /// keeps it alive); dt: the step; nq: configuration size; unit: (start, size) pairs
    /// of q's unit-norm parts; joints: q's and v's parts for the integration (empty
    /// segments' list or `integrable` false: the caller integrates).
    ControlStep(ActiveSetSolver& solver, ControlStepArrays arrays, rows::Index nq, double dt,
                std::vector<std::int64_t> unit, std::vector<JointSegment> joints,
                bool integrable);

    /// The tasks, added once at prepare (each returns its index in its list).
    rows::Index add_frame(FrameOp op);
    rows::Index add_com(ComOp op);
    rows::Index add_posture(PostureOp op);
    rows::Index add_limits(LimitOp op);
    rows::Index add_region(RegionOp op);
    /// b[start:stop] scaled down to norm cap where it is larger (a task's max_rate).
    void add_cap(rows::Index start, rows::Index stop, double cap);
    /// The hard levels (hierarchy.hard) and the certificate's tolerance: a clean answer
    /// is the step's only when each holds with a margin (hard_levels_clear).
    void set_hard(std::vector<std::int64_t> levels, double tol);
    /// Every hard level's residual r_i <= tol scale_i / 2, scale_i the certificate's
    /// ‖√w (|A_i| |x| + |t_i|)‖ + ‖√W_i A_i‖_F (hierarchy.hard_violations; t_i the
    /// equality targets and A_i x clipped to the bounds): held beyond rounding. False
    /// also when a scale cannot be formed in float64 (the caller then checks).
    bool hard_levels_clear() const;

    /// One step at q (n_q): rows, targets, solve, and on a clean answer q_next. Throws
    /// ConcurrentUse when another thread is in a step of this object.
    StepCode step(const double* q);
    /// out = q ⊕ v dt (n_q; the joints' segments; integrable() must hold).
    void integrate(const double* q, const double* v, double* out) const;
    bool integrable() const { return integrable_; }
    /// Every entry of q finite and its unit-norm parts of norm 1 within 1e-6
    /// (robots.models.UNIT_NORM_TOL).
    bool state_is_valid(const double* q) const;

    const ControlStepResult& result() const { return result_; }
    ControlStepResult& result() { return result_; }
    std::vector<FrameOp>& frames() { return frames_; }
    std::vector<ComOp>& coms() { return coms_; }
    std::vector<PostureOp>& postures() { return postures_; }
    std::vector<RegionOp>& regions() { return regions_; }
    /// Views of data.Jcom and data.com[0] (before a CoM or CoM-region task is added).
    void set_com(rows::ConstMatrix Jcom, rows::ConstVector com) {
        arrays_.Jcom = Jcom;
        arrays_.com = com;
    }
    bool has_com() const { return arrays_.Jcom.data != nullptr; }
    /// The stack's rows A and per-row quantities Q (where frame ops write).
    rows::Matrix stack_rows() const { return arrays_.A; }
    rows::Matrix per_row() const { return arrays_.Q; }
    rows::Index rows() const { return arrays_.A.rows; }
    rows::Index nq() const { return nq_; }
    rows::Index nv() const { return nv_; }

private:
    void write_rows(const double* q);
    void write_regions();
    void targets();
    SolveCode solve();

    ActiveSetSolver& solver_;
    ControlStepArrays arrays_;
    rows::Index nq_ = 0, nv_ = 0;
    double dt_ = 0.0;
    std::vector<std::int64_t> unit_;
    std::vector<JointSegment> joints_;
    bool integrable_ = false;
    bool try_first_ = false;
    std::vector<FrameOp> frames_;
    std::vector<ComOp> coms_;
    std::vector<PostureOp> postures_;
    std::vector<LimitOp> limits_;
    std::vector<RegionOp> regions_;
    std::vector<std::array<double, 3>> caps_;   ///< (start, stop, cap)
    std::vector<std::int64_t> hard_;
    double hard_tol_ = 0.0;
    // scratch: zeros (n_v), the actuated positions (n_v), the scaled step v dt (n_v)
    std::vector<double> zeros_, qa_, vdt_;
    ControlStepResult result_;
    std::atomic<bool> busy_{false};
};

}  // namespace prioik
