// The hierarchical active set (formulations/hierarchical_active_set.py): the
// lexicographic optimum of a stack of equality and inequality rows, level by level, on
// the rotated coordinates of the extended Jacobian's nested pivoted QR, with the warm
// start, the equality-first try and the minimum-norm tie-break.
//
// One ActiveSetSolver per layout: its workspace is allocated by the constructor and
// nothing is allocated by a solve. Rounding: IEEE double, no fast math, no contraction.
// One thread at a time per solver.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "prioik/nested_qr.hpp"

namespace prioik {

using index = std::int64_t;

/// What ActiveSetSolver::solve returns.
enum class SolveCode : int {
    /// a value is not valid, or a level is of extreme scale (the caller names the value
    /// or equilibrates the level)
    not_solved = 0,
    /// finite, settled, every rank decision clear, every box row resolved, every
    /// level's violation within primal_tol
    clean = 1,
    /// the same with some level's violation above primal_tol (infeasible levels)
    infeasible = 2,
    /// the caller reads the summary (cap, non-finite, ambiguous, flagged, unresolved,
    /// or ‖x‖ beyond PRECISION_LIMIT_NORM)
    other = 3,
    /// the equality-first try did not give the answer: run solve()
    not_tried = -1,
};

/// A level's flag (Result::flags): why its answer is capped or certified.
enum LevelFlag : index {
    FLAG_OK = 0,
    FLAG_ITERATION_CAP = 1,
    FLAG_AMBIGUOUS_PATH = 2,
    FLAG_NEAR_RELEASE = 3,
    FLAG_HELD_OFF_BOUND = 4,
    FLAG_NEAR_AMBIGUOUS = 5,
    FLAG_STALLED = 6,
};

/// The solver's options (hierarchical_active_set.OPTIONS).
struct ActiveSetOptions {
    double rcond = 1e-9;
    double primal_tol = 1e-10;
    double dual_tol = 1e-12;
    index max_iter = 500;
    bool warm_start = true;
};

/// The stack's layout: M rows of n columns in k levels (starts: k + 1 row offsets),
/// each row's equality flag (row_eq, M).
struct ActiveSetLayout {
    index M = 0, n = 0, k = 0;
    std::vector<index> starts;
    std::vector<std::int8_t> row_eq;
};

/// A solve's answer, by name (the last column of the per-level arrays is the
/// minimum-norm tie-break).
struct ActiveSetResult {
    std::vector<double> x;          ///< n
    std::vector<double> w2;         ///< k: each level's weighted squared violation
    std::vector<double> res;        ///< k: its square root
    std::vector<double> margins;    ///< k + 1: the rank decisions' margins
    std::vector<index> iterations;  ///< k + 1
    std::vector<index> flags;       ///< k + 1: LevelFlag
    std::vector<index> ranks;       ///< k + 1: rows fixed per level
    std::vector<index> over;        ///< k: 1 where the violation exceeds primal_tol max(1, ‖x‖)
    double x_norm = 0.0;
    /// 1 when an iteration cap was hit, −1 when x or a violation is not finite, else 0
    double cap_or_nonfinite = 0.0;
    bool large = false;             ///< ‖x‖ > PRECISION_LIMIT_NORM
    index ambiguous = 0;            ///< levels with an ambiguous margin or a certified flag
    index unresolved = 0;           ///< box rows near a bound x's precision cannot resolve
    /// 1: the answer is the equality-first try's; −1: that try (no row held) was
    /// refuted; −2: refuted with rows held; 0: not tried
    double equality_first = 0.0;
    /// the next warm solve tries the equality rows first: 0 no, 1 with no row held,
    /// 2 with the rows the answer held
    double next_try = 0.0;
};

/// The workspace of one prepared solver, R = M + n rows (the stack's and the
/// tie-break's). Sizes are fixed by the layout.
struct ActiveSetWorkspace {
    // rows in rotated coordinates (B), as weighed in x (Bo), the step's factorization (T)
    // and its reflectors (V, beta, vpos), the fixing reflectors (Vf, betaf, posf)
    std::vector<double> B, Bo, T, Lw, flat, V, Vf, Ts, ts_rows, lsq;
    std::vector<double> blo, bup, rnorm, rhs, norms, tgt, nu, tq;
    std::vector<double> beta, betaf, y, p, g, px, xc, xs;
    std::vector<index> rows, vpos, posf, nrot, ucol, perm, iscratch;
    std::vector<std::int8_t> state, saved, eqr, held;
    // the equality-first try: weighed rows, per-row and per-level vectors, its scratch
    // and the nested QR's workspace (nested_qr.hpp)
    std::vector<double> eflat, evec, efs;
    std::vector<index> eint, eispare;
    NestedQRWorkspace equality_qr;
    /// per level (k + 1), the working set at its optimum: −1/+1 held at lower/upper
    std::vector<std::int8_t> warm_state, warm_valid;

    void allocate(index M, index n, index k);
};

/// The active set prepared for one layout.
class ActiveSetSolver {
public:
    ActiveSetSolver(ActiveSetLayout layout, ActiveSetOptions options);

    /// The level-by-level active set on the stack's rows (A: M × n row-major, b, lower,
    /// upper, sw: M), from the kept working sets when warm. Throws ConcurrentUse when
    /// another thread is in a solve of this solver.
    SolveCode solve(const double* A, const double* b, const double* lower,
                    const double* upper, const double* sw);
    /// The warm start's equality-first try (not_tried when it is not the answer).
    SolveCode equality_first(const double* A, const double* b, const double* lower,
                             const double* upper, const double* sw);
    /// Forget the kept working sets (the next solve starts cold).
    void reset();

    const ActiveSetResult& result() const { return result_; }
    ActiveSetResult& result() { return result_; }
    const ActiveSetLayout& layout() const { return layout_; }
    const ActiveSetOptions& options() const { return options_; }
    ActiveSetWorkspace& workspace() { return ws_; }

private:
    ActiveSetLayout layout_;
    ActiveSetOptions options_;
    ActiveSetWorkspace ws_;
    ActiveSetResult result_;
    std::atomic<bool> busy_{false};
};

}  // namespace prioik
