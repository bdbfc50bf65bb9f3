// The active set's step: the equality-constrained least squares of a working set, its
// full-rank and unit-rows shortcuts, and the hard rows' multipliers.
#include <algorithm>
#include <cmath>

#include "active_set_internal.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


double row_size(const Ctx& c, index j, double ynorm, const double* x) {
    index col = c.ucol[j];
    if (col >= 0) return std::fabs(c.Bo(j, col)) * (std::fabs(x[col]) + 1.0);
    return c.rnorm[j] * ynorm;
}

int violated_side(double r, double lo, double up, double tol_lo, double tol_up) {
    if (r < lo - tol_lo) return -1;
    if (r > up + tol_up) return 1;
    return 0;
}

PRIOIK_VECTOR_CLONES
void bring(Ctx& c, index j) {
    double* Bj = c.B.row(j);
    index n = c.n;
    for (index t = c.nrot[j]; t < c.nf; ++t) {
        index q = c.posf[t];
        const double* v = c.Vf.row(t) + q;
        double* row = Bj + q;
        double f = c.betaf[t] * dot(row, v, n - q);
        if (f != 0.0)
            for (index k = 0; k < n - q; ++k) row[k] -= f * v[k];
    }
    c.nrot[j] = c.nf;
}

PRIOIK_VECTOR_CLONES
void lift(Ctx& c, const double* p, double* px) {
    for (index k = 0; k < c.col; ++k) px[k] = 0.0;
    for (index k = 0; k < c.n - c.col; ++k) px[c.col + k] = p[k];
    apply_q(px, c.n, dense::reflectors(c.Vf, c.n, c.betaf, c.posf, c.nf));
}

PRIOIK_VECTOR_CLONES
void reflect_vector(double* x, index d, index r, Mat V, const double* beta, const index* vpos,
                    bool transposed) {
    for (index i = 0; i < r; ++i) {
        index t = transposed ? i : r - 1 - i;
        index q = vpos != nullptr ? vpos[t] : t;
        const double* v = V.row(t) + q;
        double* xq = x + q;
        double f = beta[t] * dot(v, xq, d - q);
        if (f != 0.0)
            for (index k = 0; k < d - q; ++k) xq[k] -= f * v[k];
    }
}

PRIOIK_VECTOR_CLONES
void reflect_row(Mat T, index i, index q, index w, Mat V, double* beta, index nref,
                 index first, index last) {
    double* row = T.row(i) + q;
    index len = w - q;
    double exact = dot(row, row, len);
    double norm = std::sqrt(exact);
    double alpha = row[0] >= 0.0 ? -norm : norm;
    double* v = V.row(nref) + q;
    v[0] = row[0] - alpha;
    for (index k = 1; k < len; ++k) v[k] = row[k];
    double vtv = 2.0 * (exact - alpha * row[0]);
    double bt = vtv > 0.0 ? 2.0 / vtv : 0.0;
    beta[nref] = bt;
    row[0] = alpha;
    for (index k = 1; k < len; ++k) row[k] = 0.0;
    for (index r = first; r < last; ++r) {
        double* other = T.row(r) + q;
        double f = bt * dot(other, v, len);
        if (f != 0.0)
            for (index k = 0; k < len; ++k) other[k] -= f * v[k];
    }
}

PRIOIK_VECTOR_CLONES
void lq_multipliers(double* g, index d, index r, Mat T, Mat V, const double* beta,
                    const index* vpos, double* out) {
    reflect_vector(g, d, r, V, beta, vpos, true);
    for (index i = r - 1; i >= 0; --i) {
        double acc = g[i];
        for (index k = i + 1; k < r; ++k) acc -= T(k, i) * out[k];
        out[i] = acc / T(i, i);
    }
}

bool box_row_unresolved(double a, double xc, double ax, double lo, double up, double xn,
                        double primal_tol) {
    if (dense::X_PRECISION * xn < 0.5 * primal_tol) return false;
    double precision = dense::X_PRECISION * xn * std::fabs(a);
    double size = std::fabs(a) * (std::fabs(xc) + 1.0);
    for (double bound : {lo, up})
        if (std::isfinite(bound)) {
            double tol = tol_of(primal_tol, size, bound);
            if (precision > tol && std::fabs(ax - bound) <= precision + tol) return true;
        }
    return false;
}

namespace {

/// Swap entries i and j of the step's per-row arrays (T's rows, rhs, norms, rows, tgt).
void swap_step_rows(Ctx& c, index i, index j, index d) {
    swap_rows_upto(c.T, i, j, d);
    swap_entries(c.rhs, i, j);
    swap_entries(c.norms, i, j);
    swap_entries(c.rows, i, j);
    swap_entries(c.tgt, i, j);
}

/// The soft rows T[nh:nh + nw] on the directions the hr hard reflectors
/// leave (p[:hr] the hard part of the step), then p in the free coordinates.
PRIOIK_VECTOR_CLONES
void eqp_soft(Ctx& c, index nh, index nw, index hr, index d, double soft_tol, StepOut& o) {
    index nr = nh + nw;
    for (index i = nh; i < nr; ++i) {
        double acc = c.rhs[i];
        for (index k = 0; k < hr; ++k) acc -= c.T(i, k) * c.p[k];
        c.rhs[i] = acc;
        const double* tail = c.T.row(i) + hr;
        c.norms[i] = dot(tail, tail, d - hr);
    }
    index rs = 0;
    while (rs < nw && hr + rs < d) {
        index q = hr + rs, top = nh + rs, piv = top;
        double best = c.norms[top];
        for (index i = top + 1; i < nr; ++i)
            if (c.norms[i] > best) {
                best = c.norms[i];
                piv = i;
            }
        double exact = dot(c.T.row(piv) + q, c.T.row(piv) + q, d - q);
        if (!(std::sqrt(exact) > soft_tol) && soft_tol > 0.0)
            for (index i = top; i < nr; ++i) {
                const double* rest = c.T.row(i) + q;
                c.norms[i] = dot(rest, rest, d - q);
                if (c.norms[i] > exact) {
                    exact = c.norms[i];
                    piv = i;
                }
            }
        if (!(std::sqrt(exact) > soft_tol) || soft_tol <= 0.0) {
            if (exact > 0.0 && soft_tol > 0.0)
                o.margin = std::min(o.margin, soft_tol / std::sqrt(exact));
            break;
        }
        o.margin = std::min(o.margin, std::sqrt(exact) / soft_tol);
        if (piv != top) swap_step_rows(c, top, piv, d);
        c.vpos[o.nref] = q;
        reflect_row(c.T, top, q, d, c.V, c.beta, o.nref, top + 1, nr);
        for (index i = top + 1; i < nr; ++i) c.norms[i] -= c.T(i, q) * c.T(i, q);
        ++o.nref;
        ++rs;
    }
    if (rs > 0) {
        if (rs == nw) {
            for (index i = 0; i < rs; ++i) {
                double acc = c.rhs[nh + i];
                for (index k = 0; k < i; ++k) acc -= c.T(nh + i, hr + k) * c.p[hr + k];
                c.p[hr + i] = acc / c.T(nh + i, hr + i);
            }
        } else {
            for (index i = 0; i < nw; ++i)
                for (index k = 0; k < rs; ++k) c.Lw(i, k) = k <= i ? c.T(nh + i, hr + k) : 0.0;
            small_least_squares(c.Lw.ref(nw, rs), c.rhs + nh, nw, rs, 0.0, c.p + hr, c.lsq);
        }
    }
    reflect_vector(c.p, d, o.nref, c.V, c.beta, c.vpos, false);
    o.rs = rs;
}

/// The minimum-norm step keeping the nh working hard rows at their bounds (reach:
/// moving them onto them) and least squares over the nw working soft rows.
PRIOIK_VECTOR_CLONES
StepOut eqp_impl(Ctx& c, index nh, index nw, double soft_tol, bool reach) {
    index n = c.n, col = c.col, d = n - col, nr = nh + nw;
    StepOut o;
    for (index i = 0; i < nr; ++i) {
        const double* Bj = c.B.row(c.rows[i]);
        c.rhs[i] = (reach || i >= nh) ? c.tgt[i] - dot(Bj, c.y, n) : 0.0;
        for (index k = 0; k < d; ++k) c.T(i, k) = Bj[col + k];
    }
    for (index i = 0; i < nh; ++i) c.norms[i] = dot(c.T.row(i), c.T.row(i), d);
    index hr = 0;
    while (hr < nh && hr < d) {
        double best = -1.0;
        index piv = hr;
        for (index i = hr; i < nh; ++i) {
            double s = c.rnorm[c.rows[i]];
            double rel = s > 0.0 ? c.norms[i] / (s * s) : 0.0;
            if (rel > best) {
                best = rel;
                piv = i;
            }
        }
        const double* tail = c.T.row(piv) + hr;
        double exact = dot(tail, tail, d - hr);
        double s = c.rnorm[c.rows[piv]];
        if (!(exact > (c.rcond * s) * (c.rcond * s)) || s <= 0.0) break;
        if (piv != hr) swap_step_rows(c, hr, piv, d);
        c.vpos[o.nref] = hr;
        reflect_row(c.T, hr, hr, d, c.V, c.beta, o.nref, hr + 1, nr);
        for (index i = hr + 1; i < nh; ++i) c.norms[i] -= c.T(i, hr) * c.T(i, hr);
        ++o.nref;
        ++hr;
    }
    for (index k = 0; k < d; ++k) c.p[k] = 0.0;
    for (index i = 0; i < hr; ++i) {
        double acc = c.rhs[i];
        for (index k = 0; k < i; ++k) acc -= c.T(i, k) * c.p[k];
        c.p[i] = acc / c.T(i, i);
    }
    if (hr == nh) {
        index R = c.R;
        for (index i = 0; i < nw; ++i) {
            for (index k = 0; k < d; ++k) c.Ts(i, k) = c.T(nh + i, k);
            c.ts_rows[i] = static_cast<double>(c.rows[nh + i]);
            c.ts_rows[R + i] = c.tgt[nh + i];
        }
    }
    o.hr = hr;
    eqp_soft(c, nh, nw, hr, d, soft_tol, o);
    return o;
}

}  // namespace

StepOut eqp_general(Ctx& c, index nh, index nw, double soft_tol, bool reach) {
    return eqp_impl(c, nh, nw, soft_tol, reach);
}

PRIOIK_VECTOR_CLONES
StepOut eqp_append(Ctx& c, index nh, index nw, double soft_tol, index jb, double tb) {
    index n = c.n, col = c.col, d = n - col;
    StepOut o;
    o.hr = -1;
    if (nh + 1 >= d) return o;
    double* u = c.T.row(nh);
    for (index k = 0; k < d; ++k) u[k] = c.B(jb, col + k);
    reflect_vector(u, d, nh, c.V, c.beta, c.vpos, true);
    const double* tail = u + nh;
    double s = c.rnorm[jb];
    if (!(dot(tail, tail, d - nh) > (c.rcond * s) * (c.rcond * s)) || s <= 0.0) return o;
    c.vpos[nh] = nh;
    reflect_row(c.T, nh, nh, d, c.V, c.beta, nh, nh, nh);
    index hr = nh + 1;
    c.rows[nh] = jb;
    c.tgt[nh] = tb;
    c.rhs[nh] = 0.0;
    index R = c.R;
    const double* v = c.V.row(nh) + nh;
    double bt = c.beta[nh];
    for (index i = 0; i < nw; ++i) {
        double* ti = c.Ts.row(i);
        double f = bt * dot(v, ti + nh, d - nh);
        if (f != 0.0)
            for (index k = 0; k < d - nh; ++k) ti[nh + k] -= f * v[k];
        index j = static_cast<index>(c.ts_rows[i]);
        c.rows[hr + i] = j;
        c.tgt[hr + i] = c.ts_rows[R + i];
        c.rhs[hr + i] = c.ts_rows[R + i] - dot(c.B.row(j), c.y, n);
        double* Ti = c.T.row(hr + i);
        for (index k = 0; k < d; ++k) Ti[k] = ti[k];
    }
    for (index k = 0; k < d; ++k) c.p[k] = 0.0;
    o.hr = hr;
    o.nref = hr;
    o.margin = inf;
    eqp_soft(c, hr, nw, hr, d, soft_tol, o);
    return o;
}

PRIOIK_VECTOR_CLONES
double hard_multipliers(Ctx& c, index nh, index hr, index nw) {
    index d = c.n - c.col;
    soft_gradient(c, nh, nw, c.g);
    double gn = std::sqrt(dot(c.g, c.g, d));
    lq_multipliers(c.g, d, hr, c.T, c.V, c.beta, c.vpos, c.nu);
    return gn;
}

PRIOIK_VECTOR_CLONES
void soft_gradient(Ctx& c, index nh, index nw, double* g) {
    index d = c.n - c.col;
    for (index k = 0; k < d; ++k) g[k] = 0.0;
    for (index i = nh; i < nh + nw; ++i) {
        index j = c.rows[i];
        double res = dot(c.B.row(j), c.y, c.n) - c.tgt[i];
        if (res != 0.0) {
            const double* Bj = c.B.row(j) + c.col;
            for (index k = 0; k < d; ++k) g[k] += res * Bj[k];
        }
    }
}

PRIOIK_VECTOR_CLONES
void soft_gradient_x(Ctx& c, index nh, index nw, double* gx, double* g) {
    index n = c.n;
    for (index k = 0; k < n; ++k) gx[k] = 0.0;
    for (index i = nh; i < nh + nw; ++i) {
        index j = c.rows[i];
        double res = odot(c, j, c.xc) - c.tgt[i];
        if (res != 0.0) {
            index uc = c.ucol[j];
            if (uc >= 0) {
                gx[uc] += res * c.Bo(j, uc);
            } else {
                const double* Bj = c.Bo.row(j);
                for (index k = 0; k < n; ++k) gx[k] += res * Bj[k];
            }
        }
    }
    apply_qt(gx, n, dense::reflectors(c.Vf, n, c.betaf, c.posf, c.nf));
    for (index k = 0; k < n - c.col; ++k) g[k] = gx[c.col + k];
}

PRIOIK_VECTOR_CLONES
void freed_gain(Ctx& c, index nh, index hr, index nw, index rs, index i, double& un,
                double& gain) {
    double* w = c.px;
    double* v = c.rhs;
    Mat T = c.T;
    for (index k = 0; k < i; ++k) w[k] = 0.0;
    w[i] = 1.0 / T(i, i);
    for (index k = i + 1; k < hr; ++k) {
        double acc = 0.0;
        for (index t = i; t < k; ++t) acc -= T(k, t) * w[t];
        w[k] = acc / T(k, k);
    }
    un = std::sqrt(dot(w, w, hr));
    for (index r = 0; r < nw; ++r) v[r] = dot(T.row(nh + r), w, hr) / un;
    // Qᵀ v by the QR of the soft rows' factor (held transposed: Qᵀ v follows its rs
    // columns of nw in the scratch); its entries beyond rs are v's part outside its range
    small_least_squares(T.at(nh, hr).ref(nw, rs), v, nw, rs, 0.0, c.p + hr, c.lsq);
    const double* qtv = c.lsq + rs * nw;
    gain = std::sqrt(dot(qtv + rs, qtv + rs, nw - rs));
}

}  // namespace prioik::detail
