// The fixing of a level's violated and equality rows, and the end of a solve: x, the
// box-row pass, the next try's kind, the levels' violations and the summary.
#include <algorithm>
#include <cmath>

#include "active_set_internal.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


namespace {

/// The last step's reflectors (no hard row held, every held row fixed) taken as the
/// fixing ones; returns the rows they fix.
PRIOIK_VECTOR_CLONES
index reuse_step_reflectors(Ctx& c, index s0, index s1, index rs) {
    index n = c.n, d = n - c.col;
    for (index t = 0; t < rs; ++t) {
        index q = c.col + c.vpos[t];
        double* vf = c.Vf.row(c.nf) + q;
        const double* vt = c.V.row(t) + c.vpos[t];
        for (index k = 0; k < d - c.vpos[t]; ++k) vf[k] = vt[k];
        double bt = c.beta[t];
        c.betaf[c.nf] = bt;
        c.posf[c.nf] = q;
        double* yq = c.y + q;
        double f = bt * dot(yq, vf, n - q);
        for (index k = 0; k < n - q; ++k) yq[k] -= f * vf[k];
        ++c.nf;
    }
    c.col += rs;
    for (index j = s0; j < s1; ++j)
        if (c.state[j] == 5) c.state[j] = 2;
    return rs;
}

/// The row-pivoted LQ of the rows[rf:nfix] to fix on the free coordinates; each pivot
/// a fixing reflector that rotates y; returns the rows fixed.
PRIOIK_VECTOR_CLONES
index fixing_lq(Ctx& c, index lev, index rf, index nfix, double soft_tol) {
    index n = c.n;
    for (index i = 0; i < nfix; ++i) {
        index j = c.rows[i];
        bring(c, j);
        c.norms[i] = dot(c.B.row(j) + c.col, c.B.row(j) + c.col, n - c.col);
    }
    while (rf < nfix && c.col < n) {
        index col = c.col, w = n - col;
        index piv = rf;
        double best = c.norms[rf];
        for (index i = rf + 1; i < nfix; ++i)
            if (c.norms[i] > best) {
                best = c.norms[i];
                piv = i;
            }
        double* tail = c.B.row(c.rows[piv]) + col;
        double exact = dot(tail, tail, w);
        if (!(std::sqrt(exact) > soft_tol) && soft_tol > 0.0) {
            for (index i = rf; i < nfix; ++i) {
                const double* r = c.B.row(c.rows[i]) + col;
                c.norms[i] = dot(r, r, w);
                if (c.norms[i] > exact) {
                    exact = c.norms[i];
                    piv = i;
                }
            }
            tail = c.B.row(c.rows[piv]) + col;
        }
        if (!(std::sqrt(exact) > soft_tol) || soft_tol <= 0.0) {
            if (exact > 0.0 && soft_tol > 0.0)
                c.margins[lev] = std::min(c.margins[lev], soft_tol / std::sqrt(exact));
            break;
        }
        c.margins[lev] = std::min(c.margins[lev], std::sqrt(exact) / soft_tol);
        index jp = c.rows[piv];
        if (piv != rf) {
            swap_entries(c.rows, rf, piv);
            swap_entries(c.norms, rf, piv);
        }
        double norm = std::sqrt(exact);
        double alpha = tail[0] >= 0.0 ? -norm : norm;
        double* vf = c.Vf.row(c.nf) + col;
        vf[0] = tail[0] - alpha;
        for (index k = 1; k < w; ++k) vf[k] = tail[k];
        double vtv = 2.0 * (exact - alpha * tail[0]);
        double bt = vtv > 0.0 ? 2.0 / vtv : 0.0;
        c.betaf[c.nf] = bt;
        c.posf[c.nf] = col;
        tail[0] = alpha;
        for (index k = 1; k < w; ++k) tail[k] = 0.0;
        for (index i = rf + 1; i < nfix; ++i) {
            double* other = c.B.row(c.rows[i]) + col;
            double f = bt * dot(other, vf, w);
            if (f != 0.0)
                for (index k = 0; k < w; ++k) other[k] -= f * vf[k];
            c.nrot[c.rows[i]] = c.nf + 1;
        }
        double* yq = c.y + col;
        double f = bt * dot(yq, vf, w);
        for (index k = 0; k < w; ++k) yq[k] -= f * vf[k];
        for (index i = rf + 1; i < nfix; ++i)
            c.norms[i] -= c.B(c.rows[i], col) * c.B(c.rows[i], col);
        c.state[jp] = 2;
        ++c.nf;
        ++c.col;
        ++rf;
    }
    return rf;
}

}  // namespace

void fix_level(Ctx& c, index lev, index s0, index s1, double scale, double soft_tol,
               const StepOut& st, index nh, index nw, bool settled) {
    double ynorm = std::sqrt(dot(c.y, c.y, c.n));
    double tn = 0.0;
    for (index i = nh; i < nh + nw; ++i) tn += c.tgt[i] * c.tgt[i];
    double dscale = c.dual_tol * scale * (scale * ynorm + std::sqrt(tn));
    index nfix = 0;
    bool held_off = false;
    for (index j = s0; j < s1; ++j) {
        int s = c.state[j];
        bool fix = c.eqr[j] != 0;
        if (s == -1 || s == 1) {
            double tb = s == -1 ? c.blo[j] : c.bup[j];
            double off = std::fabs(odot(c, j, c.xc) - tb);
            double sz = row_size(c, j, ynorm, c.xc);
            bool beyond = off > tol_of(c.primal_tol, sz, tb);
            fix = beyond && off * c.rnorm[j] > dscale;
            if (beyond && !fix) held_off = true;
        }
        if (fix) {
            c.rows[nfix++] = j;
            c.state[j] = 5;
        }
    }
    if (held_off && c.flags[lev] == FLAG_OK) c.flags[lev] = FLAG_HELD_OFF_BOUND;
    index rf = 0;
    if (settled && st.full && nfix == nw) {
        c.ranks[lev] = c.n - c.col;
        c.col = c.n;
        for (index i = 0; i < nfix; ++i) c.state[c.rows[i]] = 2;
        return;
    }
    if (settled && st.hr == 0 && nfix == nw) {
        nfix = 0;
        rf = reuse_step_reflectors(c, s0, s1, st.rs);
    }
    rf = fixing_lq(c, lev, rf, nfix, soft_tol);
    c.ranks[lev] = rf;
    for (index i = 0; i < nfix; ++i) c.state[c.rows[i]] = 2;
}

SolveCode summary(Ctx& c, double total, index unresolved) {
    index k = c.k, n = c.n;
    ActiveSetResult& out = *c.out;
    double xn = std::sqrt(dot(c.x, c.x, n));
    if (!(xn <= 1e150)) {
        double top = 0.0;
        for (index j = 0; j < n; ++j) top = std::max(top, std::fabs(c.x[j]));
        if (top <= 1e308) {
            double acc = 0.0;
            for (index j = 0; j < n; ++j) acc += (c.x[j] / top) * (c.x[j] / top);
            xn = top * std::sqrt(acc);
        }
    }
    out.x_norm = xn;
    index infeasible = 0;
    for (index lev = 0; lev < k; ++lev) {
        bool over = c.res[lev] > c.primal_tol * std::max(1.0, xn);
        c.over[lev] = over ? 1 : 0;
        infeasible += over ? 1 : 0;
    }
    bool large = xn > dense::PRECISION_LIMIT_NORM;
    out.large = large;
    double capped = 0.0;
    for (index lev = 0; lev <= k; ++lev)
        if (c.flags[lev] == FLAG_ITERATION_CAP) capped = 1.0;
    out.cap_or_nonfinite = (std::isfinite(xn) && std::isfinite(total)) ? capped : -1.0;
    index ambiguous = 0;
    for (index lev = 0; lev <= k; ++lev) {
        double m = c.margins[lev];
        if (c.flags[lev] == FLAG_OK && dense::AMBIGUITY < m &&
            m <= dense::NEAR_AMBIGUITY * dense::AMBIGUITY)
            c.flags[lev] = FLAG_NEAR_AMBIGUOUS;
        if (m <= dense::AMBIGUITY ||
            (c.flags[lev] != FLAG_OK && c.flags[lev] != FLAG_ITERATION_CAP))
            ++ambiguous;
    }
    out.ambiguous = ambiguous;
    out.unresolved = unresolved;
    if (out.cap_or_nonfinite != 0.0 || ambiguous || unresolved || large) return SolveCode::other;
    return infeasible ? SolveCode::infeasible : SolveCode::clean;
}

namespace {

/// Held box rows off their bound by x's precision put on it; the box rows x's
/// precision cannot resolve, counted.
PRIOIK_VECTOR_CLONES
index box_row_pass(Ctx& c) {
    double xn = std::sqrt(dot(c.x, c.x, c.n));
    index unresolved = 0;
    for (index j = 0; j < c.M; ++j) {
        index col = c.ucol[j];
        if (col < 0) continue;
        double a = c.Bo(j, col);
        double precision = dense::X_PRECISION * xn * std::fabs(a);
        if (c.state[j] == 1 || c.state[j] == -1) {
            double bound = c.state[j] == 1 ? c.bup[j] : c.blo[j];
            if (std::fabs(a * c.x[col] - bound) <= precision) c.x[col] = bound / a;
        }
        if (box_row_unresolved(a, c.x[col], a * c.x[col], c.blo[j], c.bup[j], xn,
                               c.primal_tol))
            ++unresolved;
    }
    return unresolved;
}

/// The next warm solve's try: 0 when a row ended fixed at a violation,
/// 1 when no row was held, 2 when some were.
double keep_held(const Ctx& c) {
    bool some = false;
    for (index j = 0; j < c.M; ++j) {
        int st = c.state[j];
        if (st != 0 && st != 1 && st != -1 && !c.eqr[j]) return 0.0;
        if (c.held[j] != 0) some = true;
    }
    return some ? 2.0 : 1.0;
}

}  // namespace

SolveCode finish_solve(Ctx& c) {
    index n = c.n;
    for (index j = 0; j < n; ++j) c.x[j] = c.y[j];
    apply_q(c.x, n, dense::reflectors(c.Vf, n, c.betaf, c.posf, c.nf));
    index unresolved = box_row_pass(c);
    c.out->next_try = keep_held(c);
    double total = 0.0;
    for (index lev = 0; lev < c.k; ++lev) {
        double acc = 0.0;
        for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j) {
            double ax = c.sw[j] * dot(c.A.row(j), c.x, n);
            double e;
            if (c.row_eq[j]) {
                e = ax - c.sw[j] * c.b[j];
            } else {
                double lo = c.sw[j] * c.lower[j], up = c.sw[j] * c.upper[j];
                e = ax < lo ? lo - ax : (ax > up ? ax - up : 0.0);
            }
            acc += e * e;
        }
        c.w2[lev] = acc;
        c.res[lev] = std::sqrt(acc);
        total += acc;
    }
    return summary(c, total, unresolved);
}

}  // namespace prioik::detail
