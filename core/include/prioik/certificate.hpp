// The lexicographic certificate (hierarchy.analysis.check_lexicographic) in the core: the
// verdict a prepared hierarchical active set gives a flagged answer without leaving C++.
//
// For each level i (highest first) x must solve the level's problem with the levels
// above held at x's own violations: the KKT system A_iᵀ W_i r_i + Σ A_Sᵀ μ = 0 with the
// free multipliers of the rows fixed above projected out (nested null spaces Z_i by the
// rank rule rcond·‖√W A_fixed‖_F), the residual read in task space through the
// pseudo-inverse of √W A_act Z_i (singular values floored at 1e-6 of its norm, directions
// it cannot move by the rank rule read at 1/‖B‖) and the sign-constrained multipliers of
// the rows held at one bound by a non-negative least squares (Lawson & Hanson). A level
// passing that test is walked along its descent directions (a verified drop of its value
// keeping the rows above rejects x); rows a little violated get the feasibility check
// below; a failing first reading is read again with the band rows (just beyond a bound on
// a violated level) fixed, and a failing x is moved onto its near-active bounds (the
// snap). Same rules, tolerances and order as the Python oracle; see its docstring.
//
// The feasibility question of the slack rows (Python: an LP, HiGHS, primal feasibility
// 1e-10 on unit rows) is answered by the core's own active set on the same unit rows in
// two levels: first the rows kept at their values at x (lower = upper), then the others
// (the slack rows to meet, the rest inside their intervals). The rows are met together
// when the lexicographic optimum y leaves every row within 1e-10 + 16 eps |â_j| |y| of
// its interval (HiGHS's absolute tolerance and y's rounding); the kept rows being a
// level above, a direction they pin (by the rank rule) is not traded for the others,
// as the LP's equalities are not.
//
// The SVDs are one-sided Jacobi (Hestenes) rotations over the workspace's rows; rows
// fewer than their length are first reduced by a row-pivoted Householder LQ and the
// rotations orthogonalise the rows of its triangular factor's transpose (Drmač &
// Veselić 2008), the LQ's reflectors completing the right basis. Levels of extreme
// scale (an entry beyond 1e100, or a level whose entries are all below 1e-100) are not
// checked here (CertificateCode::extreme_scale: the caller equilibrates them).
//
// One Certificate per layout: its workspace is allocated by the constructor, nothing by
// a check. Rounding: IEEE double, no fast math, no contraction. One thread at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "prioik/active_set.hpp"

namespace prioik {

/// What Certificate::check returns.
enum class CertificateCode : int {
    /// the verdict is in the result
    checked = 1,
    /// a level of extreme scale: check the equilibrated stack (the Python oracle)
    extreme_scale = 0,
};

/// The certificate's tolerances (check_lexicographic's tol and rcond).
struct CertificateOptions {
    double tol = 1e-8;
    double rcond = 1e-9;
};

/// A check's verdict, by name; the per-level arrays have k + 1 entries (the minimum-norm
/// tie-break last, when it was asked).
struct CertificateResult {
    bool ok = false;
    /// the first failing level (k: the tie-break), −1 when none fails
    index failing_level = -1;
    std::vector<double> residual;            ///< ‖w_i(x)‖ (‖x‖ at the tie-break)
    std::vector<double> projected_gradient;  ///< the KKT residual in task space
    std::vector<double> scale;               ///< what the residual is relative to
    std::vector<double> value_gap;           ///< how much the value could still drop
    std::vector<std::int8_t> level_ok;
    std::vector<index> fixed_rows, active_rows;
    std::vector<std::int8_t> ambiguous;      ///< an ambiguous rank decision at the level
    index band_rows_fixed = 0;               ///< band rows read as fixed (the second reading)
    index snapped_rows = 0;                  ///< near-active rows moved onto their bounds
    bool minimum_norm = false;               ///< the tie-break was checked

    void allocate(index k);
};

/// The workspace of one Certificate: M rows, n columns.
struct CertificateWorkspace {
    // every row's activity at the point checked (bounds, norms, A x, |A||x|, sizes)
    std::vector<double> lower, upper, norms, a, terms, size, v, WA;
    std::vector<index> side, level_side;
    std::vector<std::int8_t> fixed;
    // nested null space (held transposed: row j is basis vector j), unit rows at one
    // bound (oriented), the SVD's rows and right vectors, and their scratch
    std::vector<double> Zt, signed_rows, P, Vt, sig, Znew, house, reflect_proj;
    // the KKT residual: gradients, weights, masks, the held columns, the NNLS
    std::vector<double> g, zg, y, D, held, unit, mu, rho, step, dir, tmp_d, tmp_n;
    std::vector<std::int8_t> null, keep, passive, small;
    std::vector<double> face, face_s, face_res, nnls_s, nnls_w, ucols, jnorms, qr_work;
    std::vector<index> keep_index, fix_index, face_index, face_perm;
    // the descent walk and the snap
    std::vector<double> h, alphas, along, xp, ap, near_x, lsq, lsqV, rhs;
    std::vector<index> order;
    // the feasibility check's unit rows
    std::vector<double> fA, fb, flo, fup, fsw;

    void allocate(index M, index n);
};

/// The certificate prepared for one layout (the layout's equality flags give b as both
/// bounds of an equality row).
class Certificate {
public:
    Certificate(ActiveSetLayout layout, CertificateOptions options = {});
    ~Certificate();

    /// The verdict on x (n) for the stack's rows (A: M × n row-major, b, lower, upper,
    /// sw: M), the minimum-norm tie-break too when minimum_norm. The arrays are read,
    /// never written; their values must be finite where check_lexicographic requires it
    /// (the caller's boundary check).
    CertificateCode check(const double* A, const double* b, const double* lower,
                          const double* upper, const double* sw, const double* x,
                          bool minimum_norm);

    const CertificateResult& result() const { return result_; }
    const ActiveSetLayout& layout() const { return layout_; }
    const CertificateOptions& options() const { return options_; }

    // the phases (certificate*.cpp), public for the C++ tests' sake
    struct Stack {
        const double *A, *b, *lower, *upper, *sw;
    };
    /// one reading of x (fix_band: the band rows read as fixed) into out
    void read_once(const Stack& s, const double* x, bool fix_band, bool minimum_norm,
                   CertificateResult& out);
    /// the two readings of check_lexicographic's _read
    void read(const Stack& s, const double* x, bool minimum_norm, CertificateResult& out);
    /// x moved onto its near-active bounds (into ws.near_x); the count, 0 when none or
    /// the step is longer than tol max(1, ‖x‖)
    index snapped(const Stack& s, const double* x);

private:
    void activity(const Stack& s, const double* x);
    double kkt(const double* grad, bool with_b, index m_rows, double floor_scale, index level,
               CertificateResult& out, int& descents);
    void descent(int which, double* direction);
    double descent_drop(const Stack& s, index s0, index s1, const double* x, double x_norm,
                        const double* d, double limit);
    bool feasible(const Stack& s, index s0, index s1, const std::int8_t* small);
    void add_level(const Stack& s, index s0, index s1, index level, CertificateResult& out);
    void check_level(const Stack& s, const double* x, double x_norm, index level,
                     bool fix_band, CertificateResult& out);
    void right_svd(index m, index d);
    void project_rows(index m, index d, index row_stride, index col_stride);
    void right_svd_wide(index m, index d);
    void right_svd_tall(index m, index d);
    /// out = Vᵀ in (the coordinates of in, d, on the last right_svd's right vectors)
    void v_coords(const double* in, double* out) const;
    /// out = V coef (d)
    void v_combine(const double* coef, double* out) const;
    void fix_null_space(index m, double tol_r, index level, CertificateResult& out,
                        bool factor);

    ActiveSetLayout layout_;
    CertificateOptions options_;
    CertificateWorkspace ws_;
    CertificateResult result_, retry_, near_;
    std::unique_ptr<ActiveSetSolver> feasibility_;
    // the current reading's state: the null space's dimension, the signed rows
    index d_ = 0, n_signed_ = 0, fixed_count_ = 0;
    bool z_identity_ = true;      ///< Z = I (no row fixed yet in this reading)
    index band_ = 0;
    // the last kkt()'s parts the descents read
    double kkt_floor_ = 0.0;
    bool kkt_has_D_ = false, kkt_any_null_ = false;
    index kkt_keep_ = 0;
    /// rows of the last right_svd (keep_index[0..svd_rows_)) at null space dimension
    /// svd_d_ (−1: none): add_level reuses it when its fixed rows are the same
    index svd_rows_ = -1, svd_d_ = -1;
    /// the LQ reflectors (ws_.house) of the last right_svd: Vt holds its first
    /// reflectors_ rows, the others are the rows of Q they complete (0: Vt holds all)
    index reflectors_ = 0;
};

}  // namespace prioik
