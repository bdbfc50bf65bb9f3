// The certificate's dense steps (certificate*.cpp): robust norms, one-sided Jacobi
// rotations, a row-pivoted LQ and its reflectors, a least squares on a face of
// columns and the non-negative least squares. Every function works on its caller's
// memory (the Certificate's workspace) and allocates nothing.
#pragma once

#include "prioik/householder.hpp"

namespace prioik::cert {

constexpr double kEps = 2.220446049250313e-16;
/// float64 rounding through orthogonal transformations (hierarchy.linalg.X_PRECISION)
constexpr double kXPrecision = 16 * kEps;

/// ‖a‖₂ over n entries without the squares' overflow or underflow (level_scale)
double robust_norm(const double* a, Index n);

/// Orthogonalise the `count` rows of R (each `len` long, row i at R + i stride) by plane
/// rotations until every pair is orthogonal to rounding (one-sided Jacobi, Hestenes),
/// applying each rotation to the rows of acc (acc_len long, acc_stride) when not null;
/// norms: count scratch entries (the rows' squared norms).
void jacobi_rows(double* R, Index count, Index len, Index stride, double* acc, Index acc_len,
                 Index acc_stride, double* norms);

/// The row-pivoted Householder LQ of the `count` rows of R (each `len` long, count ≤ len,
/// stride): Π R = [L 0] H_{count−1} ⋯ H_0, L lower triangular written into R's first
/// count columns (the rows in pivot order, the entries right of the diagonal zeroed),
/// reflector k's vector (entries k..len−1) and its 2 / vᵀv into house row k (len + 1
/// long); row k of Π R is R's row perm[k] when perm is not null. norms: count scratch.
void lq_rows(double* R, Index count, Index len, Index stride, double* house, double* norms,
             Index* perm);

/// The row vector u (len) times H_{count−1} ⋯ H_0 (lq_rows's reflectors), in place.
void reflect_row(const double* house, Index count, Index len, double* u);

/// The column vector u (len) replaced by H_{count−1} ⋯ H_0 u (lq_rows's reflectors).
void reflect_vector(const double* house, Index count, Index len, double* u);

/// The `len` rows of Z (each `width` long, stride) replaced by H_{count−1} ⋯ H_0 Z
/// (lq_rows's reflectors acting on the row index); proj: 2 width scratch entries.
void reflect_rows(const double* house, Index count, Index len, double* Z, Index width,
                  Index stride, double* proj);

/// Least squares on q columns of length d held as the rows of F (stride fs; overwritten
/// by the factorization) by a column-pivoted Householder QR, stopped at the first pivot
/// |R_kk| ≤ max(abs_tol, rel_tol |R_00|) (the rank r returned): the solution on the r
/// pivot columns into s (q, by column; zero on the others) when s is not null, and the
/// residual y − Q_r Q_rᵀ y (the projection of y off their span) into res. work: d + 2q
/// scratch, perm: q.
Index pivoted_least_squares(double* F, Index q, Index d, Index fs, const double* y,
                            double rel_tol, double abs_tol, double* s, double* res,
                            double* work, Index* perm);

/// The workspace of face_solve and nnls (each at least the sizes noted).
struct FaceSpace {
    double* face;      // q × d rows (stride fstride): a face's columns
    Index fstride;
    double* s;         // p: a face's solution
    double* res;       // d: its residual
    double* w;         // p: the gradient Mᵀ r
    double* mu;        // p: the multipliers
    double* tmp;       // p
    double* work;      // d + 2p: the QR's scratch
    Index* index;      // p: the face's columns
    Index* perm;       // p: the QR's pivots
    signed char* passive;  // p
};

/// min ‖M s − y‖ over the columns `cols` (count q) of M (p columns of length d, column j
/// held in row j, stride mstride) by pivoted_least_squares with lstsq's rank rule
/// (a pivot > eps max(d, q) times the first): the solution into f.s (at the columns'
/// positions, others left), the projected residual y − Q Qᵀ y into f.res.
void face_solve(const double* M, Index mstride, Index d, const Index* cols, Index q,
                const double* y, FaceSpace& f);

/// min ‖M μ − y‖ over μ ≥ 0 (Lawson & Hanson, hierarchy.linalg.nonnegative_least_squares
/// step for step): μ into f.mu, the residual norm returned.
double nnls(const double* M, Index mstride, Index d, Index p, const double* y, FaceSpace& f);

}  // namespace prioik::cert
