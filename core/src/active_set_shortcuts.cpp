// The step's shortcuts: a level of full column rank by one column-pivoted QR, a level
// of unit rows by Woodbury, and the choice among them and the general step.
#include <algorithm>
#include <cmath>

#include "active_set_internal.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


namespace {

/// The rows' fixing reflectors applied transposed, all rows at once, into W (n × nw).
PRIOIK_VECTOR_CLONES
void rotate_transposed(Ctx& c, index nw, Mat W, index r0, double* w) {
    index n = c.n;
    for (index tf = r0; tf < c.nf; ++tf) {
        index q = c.posf[tf];
        const double* v = c.Vf.row(tf);
        for (index i = 0; i < nw; ++i) w[i] = 0.0;
        for (index k = q; k < n; ++k) {
            double vc = v[k];
            const double* Wc = W.row(k);
            for (index i = 0; i < nw; ++i) w[i] += vc * Wc[i];
        }
        double bt = c.betaf[tf];
        for (index i = 0; i < nw; ++i) w[i] *= bt;
        for (index k = q; k < n; ++k) {
            double vc = v[k];
            double* Wc = W.row(k);
            for (index i = 0; i < nw; ++i) Wc[i] -= vc * w[i];
        }
    }
}

/// The step of nw ≥ d working soft rows and no hard row, of full column rank on the d
/// free coordinates: p by one column-pivoted QR; its margin, or −1.
PRIOIK_VECTOR_CLONES
double full_rank_step(Ctx& c, index nw, double soft_tol) {
    index n = c.n, col = c.col, d = n - col;
    const index* rows = c.rows;
    index r0 = c.nrot[rows[0]];
    for (index i = 1; i < nw; ++i)
        if (c.nrot[rows[i]] != r0) return -1.0;
    Mat W{c.flat, nw};
    for (index i = 0; i < nw; ++i) {
        const double* Bj = c.B.row(rows[i]);
        for (index k = 0; k < n; ++k) W(k, i) = Bj[k];
    }
    double* norms = c.norms;
    double* t = c.rhs;
    rotate_transposed(c, nw, W, r0, norms);
    for (index i = 0; i < nw; ++i) t[i] = c.tgt[i];
    for (index k = 0; k < n; ++k) {
        double yk = c.y[k];
        const double* Wk = W.row(k);
        for (index i = 0; i < nw; ++i) t[i] -= yk * Wk[i];
    }
    Mat Tt = W.at(col, 0);
    for (index i = 0; i < nw; ++i)      // the rows on the free coordinates, kept for the
        for (index k = 0; k < d; ++k)   // refinement below (T: R × n scratch)
            c.T(i, k) = Tt(k, i);
    for (index k = 0; k < d; ++k) {
        norms[k] = dot(Tt.row(k), Tt.row(k), nw);
        c.perm[k] = k;
    }
    double margin = inf;
    for (index j = 0; j < d; ++j) {
        index piv = j;
        double best = norms[j];
        for (index k = j + 1; k < d; ++k)
            if (norms[k] > best) {
                best = norms[k];
                piv = k;
            }
        if (piv != j) {
            swap_rows_upto(Tt, j, piv, nw);
            swap_entries(norms, j, piv);
            swap_entries(c.perm, j, piv);
        }
        double* cj = Tt.row(j) + j;
        index wn = nw - j;
        double exact = dot(cj, cj, wn);
        if (!(std::sqrt(exact) > soft_tol) || soft_tol <= 0.0) return -1.0;
        margin = std::min(margin, std::sqrt(exact) / soft_tol);
        double norm = std::sqrt(exact);
        double c0 = cj[0];
        double alpha = c0 >= 0.0 ? -norm : norm;
        cj[0] = c0 - alpha;
        double vtv = 2.0 * (exact - alpha * c0);
        for (index k = j + 1; k < d; ++k) {
            double* ck = Tt.row(k) + j;
            double f = 2.0 * dot(ck, cj, wn) / vtv;
            for (index i = 0; i < wn; ++i) ck[i] -= f * cj[i];
            norms[k] -= ck[0] * ck[0];
        }
        double* tj = t + j;
        double f = 2.0 * dot(tj, cj, wn) / vtv;
        for (index i = 0; i < wn; ++i) tj[i] -= f * cj[i];
        cj[0] = alpha;
    }
    for (index j = d - 1; j >= 0; --j) {
        double acc = t[j];
        for (index k = j + 1; k < d; ++k) acc -= Tt(k, j) * norms[k];
        norms[j] = acc / Tt(j, j);
    }
    for (index j = 0; j < d; ++j) c.p[c.perm[j]] = norms[j];
    // one step of refinement by the corrected semi-normal equations (householder.hpp's
    // refine_step): the residual of the rows, formed row by row, in t
    for (index i = 0; i < nw; ++i) {
        double acc = c.tgt[i];
        for (index k = 0; k < col; ++k) acc -= c.y[k] * W(k, i);
        const double* Ti = c.T.row(i);
        for (index k = 0; k < d; ++k) acc -= Ti[k] * (c.y[col + k] + c.p[k]);
        t[i] = acc;
    }
    for (index j = 0; j < d; ++j) {
        double acc = 0.0;
        index pj = c.perm[j];
        for (index i = 0; i < nw; ++i) acc += c.T(i, pj) * t[i];
        norms[j] = acc;
    }
    csne_correction(Tt.ref(d, nw), norms, d);
    for (index j = 0; j < d; ++j) c.p[c.perm[j]] += norms[j];
    return margin;
}

/// The unit-rows step's hard rows (box rows) by the Schur complement of the normal
/// equations (the second half of unit_rows_step); false when their free directions
/// are not well conditioned. Writes p, nu; gn = ‖g‖.
PRIOIK_VECTOR_CLONES
bool unit_rows_hard(Ctx& c, index nh, index nu_cols, double s, bool reach, double& gn) {
    index n = c.n, col = c.col, d = n - col;
    Mat Zu = c.T, G = c.Lw;
    double* z = c.flat + n;
    double* t = c.flat + 2 * n;
    Mat Zh = Zu.at(nu_cols, 0);
    Mat W = Zu.at(nu_cols + nh, 0);
    index* cols = c.iscratch;
    for (index i = 0; i < nh; ++i) cols[i] = c.ucol[c.rows[i]];
    free_directions(cols, nh, Zh.ref(nh, n), dense::reflectors(c.Vf, n, c.betaf, c.posf, c.nf),
                    nullptr);
    drop_fixed(Zh.ref(nh, n), nh, col);
    for (index i = 0; i < nh; ++i) {
        for (index k = 0; k < d; ++k) W(i, k) = Zh(i, k);
        woodbury_apply(W.row(i), Zu.ref(c.R, n), G.ref(c.R, n), nu_cols, d, t);
    }
    Mat K = G.at(2 * nu_cols, 0);
    Mat S = G.at(2 * nu_cols + nh, 0);
    for (index a = 0; a < nh; ++a)
        for (index b = 0; b <= a; ++b) {
            K(a, b) = dot(Zh.row(a), Zh.row(b), d) - (a == b ? kUnitRowsGap : 0.0);
            S(a, b) = dot(Zh.row(a), W.row(b), d);
        }
    if (!cholesky_lower(K.ref(nh, n), nh)) return false;
    if (!cholesky_lower(S.ref(nh, n), nh)) return false;
    for (index i = 0; i < nh; ++i) {
        index j = c.rows[i];
        index uc = c.ucol[j];
        double a = c.Bo(j, uc);
        double rho = reach ? (c.tgt[i] - a * c.xc[uc]) / a : 0.0;
        t[i] = dot(Zh.row(i), c.p, d) - rho;
    }
    cholesky_solve(S.ref(nh, n), t, nh);
    for (index k = 0; k < d; ++k) z[k] = 0.0;
    for (index i = 0; i < nh; ++i) {
        double li = t[i];
        const double* Wi = W.row(i);
        const double* Zi = Zh.row(i);
        for (index k = 0; k < d; ++k) {
            c.p[k] -= li * Wi[k];
            z[k] += li * Zi[k];
        }
        index j = c.rows[i];
        c.nu[i] = -s * s * li / c.Bo(j, c.ucol[j]);
    }
    gn = s * s * std::sqrt(dot(z, z, d));
    return true;
}

/// The step of nw working unit rows under nh working box rows; its
/// margin (and ‖g‖ in gn), or −1.
PRIOIK_VECTOR_CLONES
double unit_rows_step(Ctx& c, index nh, index nw, double soft_tol, bool reach, double& gn) {
    index n = c.n, col = c.col, d = n - col, R = c.R;
    gn = -1.0;
    if (!(soft_tol > 0.0)) return -1.0;
    index s0 = c.rows[nh];
    if (c.rows[nh + nw - 1] - s0 != nw - 1) return -1.0;
    if (nh >= d) return -1.0;
    for (index i = 0; i < nh; ++i)
        if (c.ucol[c.rows[i]] < 0) return -1.0;
    index* colrow = c.perm;
    double s = unit_rows_of(c.Bo.ref(R, n), s0, s0 + nw, colrow);
    if (s < 0.0) return -1.0;
    index nun = 0;
    for (index k = 0; k < n; ++k)
        if (colrow[k] < 0) ++nun;
    if (nun + 2 * nh > R || 2 * nun + 2 * nh > R) return -1.0;
    double* g = c.flat;
    for (index k = 0; k < n; ++k) {
        g[k] = 0.0;
        index i = colrow[k];
        if (i >= 0) {
            double a = c.Bo(s0 + i, k);
            g[k] = a * (c.tgt[nh + i] - a * c.xc[k]) / (s * s);
        }
    }
    index nu_cols = unit_rows_solve(colrow, g, col, c.p,
                                    dense::reflectors(c.Vf, n, c.betaf, c.posf, c.nf),
                                    c.T.ref(R, n), c.Lw.ref(R, n), nullptr, c.iscratch);
    if (nu_cols < 0) return -1.0;
    double margin = nu_cols > 0 ? s * std::sqrt(kUnitRowsGap) : s;
    if (!(margin > dense::AMBIGUITY * soft_tol)) return -1.0;
    if (nh == 0) {
        gn = 0.0;
        return margin / soft_tol;
    }
    if (!unit_rows_hard(c, nh, nu_cols, s, reach, gn)) {
        gn = -1.0;
        return -1.0;
    }
    return margin / soft_tol;
}

}  // namespace

StepOut eqp_general(Ctx& c, index nh, index nw, double soft_tol, bool reach);

StepOut step(Ctx& c, index nh, index nw, double soft_tol, bool reach, bool held_rows_step) {
    index d = c.n - c.col;
    if (nw >= d && (nh == 0 || held_rows_step)) {
        double gn;
        double margin = unit_rows_step(c, nh, nw, soft_tol, reach, gn);
        if (margin >= 0.0) {
            StepOut o;
            o.hr = nh;
            o.rs = d - nh;
            o.nref = 0;
            o.full = true;
            o.margin = margin;
            o.gn = gn;
            return o;
        }
        if (nh == 0) {
            margin = full_rank_step(c, nw, soft_tol);
            if (margin >= 0.0) {
                StepOut o;
                o.hr = 0;
                o.rs = d;
                o.full = true;
                o.margin = margin;
                return o;
            }
        }
    }
    for (index i = 0; i < nh + nw; ++i) bring(c, c.rows[i]);
    return eqp_general(c, nh, nw, soft_tol, reach);
}

}  // namespace prioik::detail
