// The active set's phases over one prepared solver's workspace (private).
#pragma once

#include <cstring>

#include "prioik/active_set.hpp"
#include "active_set_linalg.hpp"

namespace prioik::detail {

using dense::Mat;
using dense::inf;

/// The number of non-zero entries of a[:n] (±0 count as zero), by integer tests of
/// their bits in 32-bit halves (a pass the compiler vectorises even on baseline x86-64,
/// which has no 64-bit compare).
inline index count_nonzero(const double* a, index n) {
    std::uint32_t nz = 0;
    for (index k = 0; k < n; ++k) {
        std::uint64_t bits;
        std::memcpy(&bits, a + k, sizeof bits);
        const auto lo = static_cast<std::uint32_t>(bits);
        const auto hi = static_cast<std::uint32_t>(bits >> 32) & 0x7fffffffu;
        nz += (lo | hi) != 0u ? 1u : 0u;
    }
    return static_cast<index>(nz);
}

/// The bits of a[from:to] but their signs, or-ed (0: every entry is ±0).
inline std::uint64_t magnitude_bits(const double* a, index from, index to) {
    std::uint64_t acc = 0;
    for (index k = from; k < to; ++k) {
        std::uint64_t bits;
        std::memcpy(&bits, a + k, sizeof bits);
        acc |= bits;
    }
    return acc << 1;
}

/// The column of the only non-zero entry of a[:n] when it has nz = 1 of them (hint
/// first: the row's column at the last solve), else −1.
inline index one_column_hint(const double* a, index n, index nz, index hint) {
    if (nz != 1) return -1;
    if (hint >= 0 && hint < n && a[hint] != 0.0) return hint;
    for (index k = 0; k < n; ++k)
        if (a[k] != 0.0) return k;
    return -1;
}

/// one_column_hint(a, n, count_nonzero(a, n), hint) without counting every entry: when
/// a[hint] is non-zero the others are tested at once, else the scan stops at the second
/// non-zero entry (a row scan of every solve: rows keep their pattern from solve to solve).
inline index one_column(const double* a, index n, index hint) {
    index nz = 0;
    if (hint >= 0 && hint < n && magnitude_bits(a, hint, hint + 1) != 0) {
        nz = (magnitude_bits(a, 0, hint) | magnitude_bits(a, hint + 1, n)) != 0 ? 2 : 1;
    } else {
        for (index k = 0; k < n && nz < 2; ++k) nz += magnitude_bits(a, k, k + 1) != 0 ? 1 : 0;
    }
    return one_column_hint(a, n, nz, hint);
}

/// ‖a‖² as dot(a, a, n) sums it, a[:n] having its one non-zero entry at `column` when
/// column ≥ 0 (one_column's): that entry squared, the same bits (the other squares are
/// +0 and add nothing).
inline double norm2_of_row(const double* a, index n, index column) {
    return column >= 0 ? a[column] * a[column] : dot(a, a, n);
}

/// Exchange M[i, :w] and M[j, :w].
inline void swap_rows_upto(Mat M, index i, index j, index w) { swap_rows(M.ref(0, w), i, j); }

/// a non-working row blocks the step only if it moves by more than max(this, rcond)
/// ‖a_j‖ ‖p‖
constexpr double BLOCK_EPS = 1e-13;
/// a step shorter than this fraction of ‖y‖ is rounding noise, taken as zero
constexpr double ZERO_STEP = 1e-13;
/// a step of at most this length (of the full step) is degenerate
constexpr double DEGENERATE = 1e-12;
/// a wrong-signed multiplier below this times the level's gradient scale is rounding
constexpr double DUAL_FLOOR = 1e-14;
/// a held soft row leaves the working set beyond this times primal_tol inside its bound
constexpr double RELEASE = 1e-3;
/// the equality-first try's verdict when held box rows cannot be fixed coordinates
constexpr index FIXED_REFUSED = -4;
/// the equality-first guesses tried before the active set runs
constexpr index GUESSES = 6;

/// Views of one call: the data, the options, the workspace's parts and the result's.
struct Ctx {
    Mat A;
    const double *b, *lower, *upper, *sw;
    index M, n, k, R;
    const index* starts;
    const std::int8_t* row_eq;
    double rcond, primal_tol, dual_tol;
    index max_iter;
    Mat B, Bo, T, Lw, V, Vf, Ts;
    double *flat, *ts_rows, *lsq;
    double *blo, *bup, *rnorm, *rhs, *norms, *tgt, *nu, *tq;
    double *beta, *betaf, *y, *p, *g, *px, *xc, *xs;
    index *rows, *vpos, *posf, *nrot, *ucol, *perm, *iscratch;
    std::int8_t *state, *saved, *eqr, *held, *warm_state, *warm_valid;
    double *x, *w2, *res, *margins;
    index *iters, *flags, *ranks, *over;
    ActiveSetResult* out;
    // the solve's fixed coordinates and fixing reflectors so far
    index col = 0, nf = 0;
    /// start every level from its kept working set
    bool use_warm = false;

    Ctx(ActiveSetSolver& s, const double* A, const double* b, const double* lower,
        const double* upper, const double* sw);
};

/// A step's factorization: hard rows kept, soft rank, reflectors, a full-rank step,
/// the soft rows' margin, and ‖g‖ when the step gave the multipliers (else −1).
struct StepOut {
    index hr = 0, rs = 0, nref = 0;
    bool full = false;
    double margin = inf, gn = -1.0;
};

// ---- primitives of rows (active_set_step.cpp)
/// row j of the original rows times v (its one column's product for a box row)
inline double odot(const Ctx& c, index j, const double* v) {
    index col = c.ucol[j];
    if (col >= 0) return c.Bo(j, col) * v[col];
    return dot(c.Bo.row(j), v, c.n);
}
double row_size(const Ctx& c, index j, double ynorm, const double* x);
inline double tol_of(double primal_tol, double size, double bound) {
    return primal_tol * (size + std::fabs(bound));
}
int violated_side(double r, double lo, double up, double tol_lo, double tol_up);
void bring(Ctx& c, index j);
void lift(Ctx& c, const double* p, double* px);
void reflect_vector(double* x, index d, index r, Mat V, const double* beta, const index* vpos,
                    bool transposed);
void reflect_row(Mat T, index i, index q, index w, Mat V, double* beta, index nref,
                 index first, index last);
void lq_multipliers(double* g, index d, index r, Mat T, Mat V, const double* beta,
                    const index* vpos, double* out);
bool box_row_unresolved(double a, double xc, double ax, double lo, double up, double xn,
                        double primal_tol);

// ---- the step (active_set_step.cpp)
StepOut step(Ctx& c, index nh, index nw, double soft_tol, bool reach, bool held_rows_step);
StepOut eqp_append(Ctx& c, index nh, index nw, double soft_tol, index jb, double tb);
double hard_multipliers(Ctx& c, index nh, index hr, index nw);
void soft_gradient(Ctx& c, index nh, index nw, double* g);
void soft_gradient_x(Ctx& c, index nh, index nw, double* gx, double* g);
void freed_gain(Ctx& c, index nh, index hr, index nw, index rs, index i, double& un,
                double& gain);

// ---- a degenerate point's working set (active_set_degenerate.cpp)
void rows_at_bounds(Ctx& c, index hard_end, double ynorm, index& m, index& extra);
bool nnls_working_set(Ctx& c, index m, index d, double gscale);

// ---- the phases of solve (active_set_solve.cpp, active_set_fix.cpp)
bool load_and_scale(Ctx& c);
void solve_levels(Ctx& c);
void fix_level(Ctx& c, index lev, index s0, index s1, double scale, double soft_tol,
               const StepOut& st, index nh, index nw, bool settled);
SolveCode finish_solve(Ctx& c);
SolveCode summary(Ctx& c, double total, index unresolved);

}  // namespace prioik::detail
