// Dense Householder primitives and the extended Jacobian's nested pivoted QR, as the
// active set uses them: row-major views over caller-owned storage, nothing allocated.
// Each function states the numba kernel function it computes
// (formulations/_extended_jacobian_kernel.py), operation for operation.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace prioik::dense {

using index = std::int64_t;

constexpr double inf = std::numeric_limits<double>::infinity();

/// hierarchy.linalg's shared rank rule: a pivot within this factor of its threshold is
/// an ambiguous decision (AMBIGUITY), a clear one within NEAR_AMBIGUITY times that band
/// is certified; x's coordinates are known to X_PRECISION ‖x‖; beyond
/// PRECISION_LIMIT_NORM float64 may limit a level (DEFAULT_CERTIFICATE_TOL / X_PRECISION)
constexpr double AMBIGUITY = 1e3;
constexpr double NEAR_AMBIGUITY = 10.0;
constexpr double X_PRECISION = 16.0 * std::numeric_limits<double>::epsilon();
constexpr double PRECISION_LIMIT_NORM = 1e-8 / X_PRECISION;

/// A row-major matrix view: element (i, j) at p[i * ld + j].
struct Mat {
    double* p = nullptr;
    index ld = 0;
    double* row(index i) const { return p + i * ld; }
    double& operator()(index i, index j) const { return p[i * ld + j]; }
    /// the view from row i, column j on (the same leading dimension)
    Mat at(index i, index j) const { return Mat{p + i * ld + j, ld}; }
};

/// ``a · b`` over ``len`` entries, summed in order.
inline double dot(const double* a, const double* b, index len) {
    double acc = 0.0;
    for (index j = 0; j < len; ++j) acc += a[j] * b[j];
    return acc;
}

template <class T>
inline void swap_at(T* a, index i, index j) {
    T tmp = a[i];
    a[i] = a[j];
    a[j] = tmp;
}

/// Exchange M[i, :w] and M[j, :w].
inline void swap_rows(Mat M, index i, index j, index w) {
    double* a = M.row(i);
    double* b = M.row(j);
    for (index c = 0; c < w; ++c) std::swap(a[c], b[c]);
}

/// Index of the largest of values[start:stop] (the first on ties).
inline index argmax_from(const double* values, index start, index stop) {
    index p = start;
    double best = values[start];
    for (index i = start + 1; i < stop; ++i)
        if (values[i] > best) {
            best = values[i];
            p = i;
        }
    return p;
}

/// v[:n] = Qᵀ v (transposed: H_0 first) or Q v, Q = H_0 … H_{nf−1}, reflector t in
/// V[t, pos[t]:n], beta[t] (_apply_reflectors).
inline void apply_reflectors(double* v, index n, index nf, Mat V, const double* beta,
                             const index* pos, bool transposed) {
    for (index i = 0; i < nf; ++i) {
        index t = transposed ? i : nf - 1 - i;
        index q = pos[t];
        const double* vt = V.row(t) + q;
        double* vq = v + q;
        double f = beta[t] * dot(vt, vq, n - q);
        if (f != 0.0)
            for (index c = 0; c < n - q; ++c) vq[c] -= f * vt[c];
    }
}

inline void apply_qt(double* v, index n, index nf, Mat V, const double* beta,
                     const index* pos) {
    apply_reflectors(v, n, nf, V, beta, pos, true);
}

inline void apply_q(double* v, index n, index nf, Mat V, const double* beta,
                    const index* pos) {
    apply_reflectors(v, n, nf, V, beta, pos, false);
}

/// One Householder step of a QR held transposed (Tt row k is column k, of length w0
/// = rows of the problem; `ncols` columns): _reflect_column.
inline void reflect_column(Mat Tt, index ncols, index len, index j, double* t, double exact) {
    double* cj = Tt.row(j) + j;
    double norm = std::sqrt(exact);
    double c0 = cj[0];
    double alpha = c0 >= 0.0 ? -norm : norm;
    cj[0] = c0 - alpha;
    double vtv = 2.0 * (exact - alpha * c0);
    index w = len - j;
    for (index k = j + 1; k < ncols; ++k) {
        double* ck = Tt.row(k) + j;
        double f = 2.0 * dot(ck, cj, w) / vtv;
        for (index i = 0; i < w; ++i) ck[i] -= f * cj[i];
    }
    double* tj = t + j;
    double f = 2.0 * dot(tj, cj, w) / vtv;
    for (index i = 0; i < w; ++i) tj[i] -= f * cj[i];
    cj[0] = alpha;
}

/// R z = t[:r], R upper triangular held transposed, into out[col:col + r].
inline void back_substitute(Mat Tt, const double* t, index r, double* out, index col) {
    for (index j = r - 1; j >= 0; --j) {
        double acc = t[j];
        for (index k = j + 1; k < r; ++k) acc -= Tt(k, j) * out[col + k];
        out[col + j] = acc / Tt(j, j);
    }
}

/// min ‖L[:m, :r] z − rhs‖² + mu2 ‖z‖² by Householder QR of [L; √mu2 I] held
/// transposed, into out[col:col + r]; scratch flat (≥ r (m + r)) and tbuf (≥ m + r),
/// tbuf left holding Qᵀ rhs (_small_lstsq_ws).
inline void small_lstsq(Mat L, const double* rhs, index m, index r, double mu2, double* out,
                        index col, double* flat, double* tbuf) {
    index rows = mu2 > 0.0 ? m + r : m;
    Mat Tt{flat, rows};
    double* t = tbuf;
    for (index j = 0; j < r; ++j)
        for (index i = 0; i < rows; ++i) Tt(j, i) = 0.0;
    for (index i = 0; i < rows; ++i) t[i] = 0.0;
    for (index i = 0; i < m; ++i) {
        for (index j = 0; j < r; ++j) Tt(j, i) = L(i, j);
        t[i] = rhs[i];
    }
    if (mu2 > 0.0) {
        double s = std::sqrt(mu2);
        for (index j = 0; j < r; ++j) Tt(j, m + j) = s;
    }
    for (index j = 0; j < r; ++j) {
        const double* tail = Tt.row(j) + j;
        double exact = dot(tail, tail, rows - j);
        if (exact > 0.0) reflect_column(Tt, r, rows, j, t, exact);
    }
    back_substitute(Tt, t, r, out, col);
}

/// the smallest eigenvalue of I − Z_U Z_Uᵀ the unit-rows step requires (_UNIT_ROWS_GAP)
constexpr double UNIT_ROWS_GAP = 1e-3;

/// G[:m, :m] = L Lᵀ in place (lower triangle); false at a pivot that is not positive.
inline bool cholesky_lower(Mat G, index m) {
    for (index a = 0; a < m; ++a)
        for (index b = 0; b <= a; ++b) {
            double acc = G(a, b);
            for (index c = 0; c < b; ++c) acc -= G(a, c) * G(b, c);
            if (a == b) {
                if (!(acc > 0.0)) return false;
                G(a, a) = std::sqrt(acc);
            } else {
                G(a, b) = acc / G(b, b);
            }
        }
    return true;
}

/// t = (L Lᵀ)⁻¹ t in place.
inline void cholesky_solve(Mat L, double* t, index m) {
    for (index a = 0; a < m; ++a) {
        double acc = t[a];
        for (index c = 0; c < a; ++c) acc -= L(a, c) * t[c];
        t[a] = acc / L(a, a);
    }
    for (index a = m - 1; a >= 0; --a) {
        double acc = t[a];
        for (index c = a + 1; c < m; ++c) acc -= L(c, a) * t[c];
        t[a] = acc / L(a, a);
    }
}

/// Z[i] = Qᵀ e_{cols[i]} (rows of length n) for i < m, and g = Qᵀ g when g is given
/// (_free_directions).
template <class Col>
inline void free_directions(const Col* cols, index m, Mat Z, index n, index nf, Mat Vf,
                            const double* betaf, const index* posf, double* g) {
    for (index i = 0; i < m; ++i) {
        double* Zi = Z.row(i);
        for (index k = 0; k < n; ++k) Zi[k] = 0.0;
        Zi[static_cast<index>(cols[i])] = 1.0;
    }
    for (index t = 0; t < nf; ++t) {
        index q = posf[t];
        const double* vt = Vf.row(t) + q;
        double bt = betaf[t];
        index w = n - q;
        for (index i = 0; i < m; ++i) {
            double* zq = Z.row(i) + q;
            double f = bt * dot(vt, zq, w);
            if (f != 0.0)
                for (index c = 0; c < w; ++c) zq[c] -= f * vt[c];
        }
        if (g != nullptr) {
            double* gq = g + q;
            double f = bt * dot(vt, gq, w);
            if (f != 0.0)
                for (index c = 0; c < w; ++c) gq[c] -= f * vt[c];
        }
    }
}

/// Z[i, :n − col] = Z[i, col:n] for i < m.
inline void drop_fixed(Mat Z, index m, index n, index col) {
    if (col > 0)
        for (index i = 0; i < m; ++i) {
            double* Zi = Z.row(i);
            for (index k = 0; k < n - col; ++k) Zi[k] = Zi[col + k];
        }
}

/// v = (I − Z_Uᵀ Z_U)⁻¹ v in place (Woodbury, L of I − Z_U Z_Uᵀ in G); scratch t (nu).
inline void woodbury_apply(double* v, Mat Zu, Mat G, index nu, index d, double* t) {
    for (index a = 0; a < nu; ++a) t[a] = dot(Zu.row(a), v, d);
    cholesky_solve(G, t, nu);
    for (index a = 0; a < nu; ++a) {
        double ta = t[a];
        const double* Za = Zu.row(a);
        for (index c = 0; c < d; ++c) v[c] += ta * Za[c];
    }
}

/// Whether rows B[s0:s1] (n columns) are unit rows: their magnitude, else −1; cover[c]
/// the row (from s0) on column c, −1 where none (_unit_rows_of).
template <class Cover>
inline double unit_rows_of(Mat B, index n, index s0, index s1, Cover* cover) {
    for (index c = 0; c < n; ++c) cover[c] = -1;
    double s = -1.0;
    for (index i = 0; i < s1 - s0; ++i) {
        const double* row = B.row(s0 + i);
        index nz = 0, at = 0;
        for (index c = 0; c < n; ++c) {
            bool nonzero = row[c] != 0.0;
            nz += nonzero ? 1 : 0;
            at += nonzero ? c : 0;
        }
        if (nz != 1 || cover[at] >= 0) return -1.0;
        double a = std::fabs(row[at]);
        if (s < 0.0)
            s = a;
        else if (a != s)
            return -1.0;
        cover[at] = static_cast<Cover>(i);
    }
    return s;
}

/// The least-squares step of a level of unit rows on the free coordinates
/// (_unit_rows_solve): writes p[:n − col]; returns |U| or −1. yfix: null, or y[:col].
template <class Cover>
inline index unit_rows_solve(const Cover* cover, double* g, index n, index col, double* p,
                             index nf, Mat Vf, const double* betaf, const index* posf, Mat Zu,
                             Mat G, const double* yfix) {
    index d = n - col;
    index nu = 0;
    double* ucols = G.row(0);
    for (index u = 0; u < n; ++u)
        if (cover[u] < 0) ucols[nu++] = static_cast<double>(u);
    free_directions(ucols, nu, Zu, n, nf, Vf, betaf, posf, g);
    for (index c = 0; c < d; ++c) p[c] = g[col + c];
    if (yfix != nullptr && col > 0)
        for (index i = 0; i < nu; ++i) {
            double xu = dot(Zu.row(i), yfix, col);
            const double* Zi = Zu.row(i) + col;
            for (index c = 0; c < d; ++c) p[c] += xu * Zi[c];
        }
    drop_fixed(Zu, nu, n, col);
    if (nu == 0) return 0;
    for (index a = 0; a < nu; ++a)
        for (index b = 0; b <= a; ++b) {
            double v = (a == b ? 1.0 : 0.0) - dot(Zu.row(a), Zu.row(b), d);
            G(a, b) = v;
            G(nu + a, b) = a == b ? v - UNIT_ROWS_GAP : v;
        }
    if (!cholesky_lower(G.at(nu, 0), nu)) return -1;
    cholesky_lower(G, nu);
    woodbury_apply(p, Zu, G, nu, d, g);
    return nu;
}

/// Floats of the nested QR's spare scratch (spare_size).
inline index nested_qr_spare_size(index M, index n) { return n * (M + n) + M + 2 * n; }

/// ‖A_i‖_F² beyond SCALE_HIGH², or below SCALE_LOW² with a non-zero entry
/// (_level_extreme): the caller equilibrates the level.
inline bool level_extreme(Mat A, index n, double lev_sq, index s0, index s1) {
    constexpr double high = 1e100, low = 1e-100;
    if (!(lev_sq <= high * high)) return true;
    if (lev_sq < low * low)
        for (index i = s0; i < s1; ++i)
            for (index c = 0; c < n; ++c)
                if (A(i, c) != 0.0) return true;
    return false;
}

/// The arguments of the nested pivoted QR (solve_kernel_ws without the trust-region
/// step): B (m × n, leading dimension ld, overwritten), c (m targets), starts (k + 1),
/// scales (k), outputs x (n), ranks, level_mu2, margins (k); scratch V (n × n, ld n),
/// beta, pos, y (n), norms, rhs (≥ max(m, n)), L (m × n), spare
/// (nested_qr_spare_size), ispare (n); rowperm: null or m entries permuted as B's rows.
struct NestedQr {
    Mat B;
    index m = 0, n = 0, k = 0;
    double* c = nullptr;
    const index* starts = nullptr;
    const double* scales = nullptr;
    double rcond = 0.0, level_damping = 0.0, singular_threshold = 0.0;
    double* x = nullptr;
    index* ranks = nullptr;
    double* level_mu2 = nullptr;
    double* margins = nullptr;
    Mat V;
    double* beta = nullptr;
    index* pos = nullptr;
    double* y = nullptr;
    double* norms = nullptr;
    Mat L;
    double* rhs = nullptr;
    index* rowperm = nullptr;
    double* spare = nullptr;
    index* ispare = nullptr;
};

/// Solve one stack of equality levels by the nested pivoted QR (solve_kernel_ws,
/// unbounded): x, ranks, level_mu2, margins written.
void nested_qr_solve(const NestedQr& q);

}  // namespace prioik::dense
