// The extended Jacobian's nested pivoted QR without the trust-region step
// (formulations/_extended_jacobian_kernel.py: solve_kernel_ws_unbounded), on views.
#include "active_set_linalg.hpp"

#include <algorithm>

namespace prioik::dense {
namespace {

/// One level with m ≥ d rows on its d free coordinates: column-pivoted QR of
/// B[s0:s0+m, col:n]; its least-squares solution into out[col:] when every pivot
/// passes tol (_pivoted_lstsq_if_full_rank). margin: the smallest pivot norm.
bool pivoted_lstsq_if_full_rank(Mat B, index n, index s0, index m, index col, const double* rhs,
                                double tol, double* out, double& margin, double* spare,
                                index* ispare) {
    index d = n - col;
    margin = inf;
    Mat Tt{spare, m};
    double* t = spare + d * m;
    double* norms = t + m;
    double* z = norms + d;
    index* perm = ispare;
    for (index i = 0; i < m; ++i) {
        const double* row = B.row(s0 + i);
        for (index j = 0; j < d; ++j) Tt(j, i) = row[col + j];
        t[i] = rhs[i];
    }
    for (index j = 0; j < d; ++j) {
        norms[j] = dot(Tt.row(j), Tt.row(j), m);
        perm[j] = j;
    }
    for (index j = 0; j < d; ++j) {
        index p = argmax_from(norms, j, d);
        if (p != j) {
            swap_rows(Tt, j, p, m);
            swap_at(norms, j, p);
            swap_at(perm, j, p);
        }
        double* cj = Tt.row(j) + j;
        index w = m - j;
        double exact = dot(cj, cj, w);
        if (!(std::sqrt(exact) > tol) || tol <= 0.0) return false;
        margin = std::min(margin, std::sqrt(exact));
        double norm = std::sqrt(exact);
        double c0 = cj[0];
        double alpha = c0 >= 0.0 ? -norm : norm;
        cj[0] = c0 - alpha;
        double vtv = 2.0 * (exact - alpha * c0);
        for (index k = j + 1; k < d; ++k) {
            double* ck = Tt.row(k) + j;
            double f = 2.0 * dot(ck, cj, w) / vtv;
            for (index i = 0; i < w; ++i) ck[i] -= f * cj[i];
            norms[k] -= ck[0] * ck[0];
        }
        double* tj = t + j;
        double f = 2.0 * dot(tj, cj, w) / vtv;
        for (index i = 0; i < w; ++i) tj[i] -= f * cj[i];
        cj[0] = alpha;
    }
    back_substitute(Tt, t, d, z, 0);
    for (index j = 0; j < d; ++j) out[col + perm[j]] = z[j];
    return true;
}

/// The deferred last level of unit rows: solved by unit_rows_solve when it applies
/// (true, col = n), else its rows brought through the reflectors (false).
bool deferred_unit_rows(const NestedQr& q, index lev, index s0, index mrows, index& col,
                        index nref, double unit_s, double tol) {
    index n = q.n;
    index d = n - col;
    index nu = n - mrows;
    if (mrows >= d && nu + std::max<index>(1, 2 * nu) <= q.m) {
        double* g = q.norms;
        for (index j = 0; j < n; ++j) {
            g[j] = 0.0;
            index i = static_cast<index>(q.x[j]);
            if (i >= 0) {
                double a = q.B(s0 + i, j);
                g[j] = a * q.c[s0 + i] / (unit_s * unit_s);
            }
        }
        index got = unit_rows_solve(q.x, g, n, col, q.y + col, nref, q.V, q.beta, q.pos, q.L,
                                    q.L.at(nu, 0), q.y);
        double margin = got > 0 ? unit_s * std::sqrt(UNIT_ROWS_GAP) : unit_s;
        if (got >= 0 && margin > AMBIGUITY * tol) {
            q.ranks[lev] = d;
            q.margins[lev] = margin / tol;
            col = n;
            return true;
        }
        for (index j = col; j < n; ++j) q.y[j] = 0.0;
    }
    for (index i = q.starts[q.k - 1]; i < q.m; ++i)
        apply_qt(q.B.row(i), n, nref, q.V, q.beta, q.pos);
    return false;
}

/// The row-pivoted LQ of one level's rows on the free coordinates (reflectors applied
/// to the rows below up to rot_end); returns the rank r.
index level_lq(const NestedQr& q, index lev, index s0, index mrows, index col, index rot_end,
               index& nref, double tol) {
    index n = q.n, d = n - col;
    Mat B = q.B;
    index r = 0;
    double kept_min = inf;
    while (r < mrows && r < d) {
        index p = argmax_from(q.norms, r, mrows);
        const double* tail = B.row(s0 + p) + col + r;
        double exact = dot(tail, tail, n - col - r);
        if (!(std::sqrt(exact) > tol) && tol > 0.0) {
            for (index i = r; i < mrows; ++i) {
                const double* rest = B.row(s0 + i) + col + r;
                q.norms[i] = dot(rest, rest, n - col - r);
            }
            p = argmax_from(q.norms, r, mrows);
            tail = B.row(s0 + p) + col + r;
            exact = dot(tail, tail, n - col - r);
        }
        if (!(std::sqrt(exact) > tol) || tol <= 0.0) {
            if (tol > 0.0 && exact > 0.0)
                q.margins[lev] = std::min(kept_min / tol, tol / std::sqrt(exact));
            break;
        }
        kept_min = std::min(kept_min, std::sqrt(exact));
        if (p != r) {
            swap_rows(B, s0 + r, s0 + p, n);
            swap_at(q.rhs, r, p);
            swap_at(q.norms, r, p);
            if (q.rowperm != nullptr) swap_at(q.rowperm, s0 + r, s0 + p);
        }
        index c0 = col + r;
        double norm = std::sqrt(exact);
        double alpha = B(s0 + r, c0) >= 0.0 ? -norm : norm;
        double* v = q.V.row(nref);
        v[c0] = B(s0 + r, c0) - alpha;
        double vtv = v[c0] * v[c0];
        for (index j = c0 + 1; j < n; ++j) {
            v[j] = B(s0 + r, j);
            vtv += v[j] * v[j];
        }
        double bt = vtv > 0.0 ? 2.0 / vtv : 0.0;
        q.beta[nref] = bt;
        q.pos[nref] = c0;
        B(s0 + r, c0) = alpha;
        for (index j = c0 + 1; j < n; ++j) B(s0 + r, j) = 0.0;
        const double* vq = v + c0;
        index w = n - c0;
        for (index i = s0 + r + 1; i < rot_end; ++i) {
            double* row = B.row(i) + c0;
            double dd = dot(row, vq, w);
            if (dd != 0.0) {
                double f = bt * dd;
                for (index j = 0; j < w; ++j) row[j] -= f * vq[j];
            }
        }
        for (index i = r + 1; i < mrows; ++i) q.norms[i] -= B(s0 + i, c0) * B(s0 + i, c0);
        ++nref;
        ++r;
    }
    q.ranks[lev] = r;
    if (tol > 0.0) q.margins[lev] = std::min(q.margins[lev], kept_min / tol);
    return r;
}

/// The level's unknowns y[col:col + r] from its LQ (forward substitution, or a small
/// least-squares solve when it conflicts or is damped).
void level_unknowns(const NestedQr& q, index lev, index s0, index mrows, index col, index r) {
    Mat B = q.B;
    double mu2 = 0.0;
    if (q.level_damping > 0.0 && q.singular_threshold > 0.0) {
        double sig = std::fabs(B(s0 + r - 1, col + r - 1));
        double eps_abs = q.singular_threshold * q.scales[lev];
        if (sig < eps_abs) mu2 = q.level_damping * (1.0 - (sig / eps_abs) * (sig / eps_abs));
    }
    if (r == mrows && mu2 == 0.0) {
        for (index i = 0; i < r; ++i) {
            double acc = q.rhs[i];
            for (index j = 0; j < i; ++j) acc -= B(s0 + i, col + j) * q.y[col + j];
            q.y[col + i] = acc / B(s0 + i, col + i);
        }
    } else {
        for (index i = 0; i < mrows; ++i)
            for (index j = 0; j < r; ++j) q.L(i, j) = j <= i ? B(s0 + i, col + j) : 0.0;
        small_lstsq(q.L, q.rhs, mrows, r, mu2, q.y, col, q.spare, q.spare + r * (mrows + r));
    }
    q.level_mu2[lev] = mu2;
}

}  // namespace

void nested_qr_solve(const NestedQr& q) {
    index M = q.m, n = q.n, k = q.k;
    Mat B = q.B;
    index nref = 0;
    for (index j = 0; j < n; ++j) q.y[j] = 0.0;
    index col = 0;
    index rot_end = M;
    double unit_s = -1.0;
    bool damped = q.level_damping > 0.0 && q.singular_threshold > 0.0;
    if (k > 0 && q.rcond > 0.0 && !damped && q.starts[k - 1] < M) {
        unit_s = unit_rows_of(B, n, q.starts[k - 1], M, q.x);
        if (unit_s > 0.0) rot_end = q.starts[k - 1];
    }
    for (index lev = 0; lev < k; ++lev) {
        index s0 = q.starts[lev], s1 = q.starts[lev + 1];
        index mrows = s1 - s0;
        q.ranks[lev] = 0;
        q.level_mu2[lev] = 0.0;
        q.margins[lev] = inf;
        if (mrows == 0 || col >= n) continue;
        double tol = q.rcond * q.scales[lev];
        if (lev == k - 1 && rot_end < M) {
            rot_end = M;
            if (deferred_unit_rows(q, lev, s0, mrows, col, nref, unit_s, tol)) continue;
        }
        for (index i = 0; i < mrows; ++i) {
            q.rhs[i] = q.c[s0 + i] - dot(B.row(s0 + i), q.y, col);
            const double* free = B.row(s0 + i) + col;
            q.norms[i] = dot(free, free, n - col);
        }
        index d = n - col;
        double margin = inf;
        if (mrows >= d && !damped &&
            pivoted_lstsq_if_full_rank(B, n, s0, mrows, col, q.rhs, tol, q.y, margin, q.spare,
                                       q.ispare)) {
            q.ranks[lev] = d;
            q.margins[lev] = margin / tol;
            col = n;
            continue;
        }
        q.margins[lev] = inf;
        index r = level_lq(q, lev, s0, mrows, col, rot_end, nref, tol);
        if (r == 0) continue;
        level_unknowns(q, lev, s0, mrows, col, r);
        col += r;
    }
    for (index j = 0; j < n; ++j) q.x[j] = q.y[j];
    apply_q(q.x, n, nref, q.V, q.beta, q.pos);
}

}  // namespace prioik::dense
