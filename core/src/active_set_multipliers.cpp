// The equality-first try's optimality test: the held rows' multipliers at every level
// below them (held as rows, or as fixed columns).
#include <algorithm>
#include <cmath>

#include "active_set_equality_first.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


PRIOIK_VECTOR_CLONES
double add_level_gradient(const Ctx& c, const EqFirst& e, index s0, index s1, const double* x,
                          double* g) {
    index n = c.n;
    double tn = 0.0;
    for (index j = s0; j < s1; ++j) {
        if (e.ucol[j] != -2) continue;
        double s = c.sw[j];
        double t = c.row_eq[j] ? c.b[j] : c.lower[j];
        index ec = e.ecol[j];
        if (ec >= 0) {
            double r = s * s * (c.A(j, ec) * x[ec] - t);
            g[ec] += r * c.A(j, ec);
        } else {
            double r = s * s * (dot(c.A.row(j), x, n) - t);
            if (r != 0.0) {
                const double* Aj = c.A.row(j);
                for (index k = 0; k < n; ++k) g[k] += r * Aj[k];
            }
        }
        tn += s * s * t * t;
    }
    return tn;
}

namespace {

/// The weighted residual of equality row j at x.
double eq_residual(const Ctx& c, const EqFirst& e, index j, const double* x, double& t) {
    double s = c.sw[j];
    t = c.row_eq[j] ? c.b[j] : c.lower[j];
    index ec = e.ecol[j];
    return s * ((ec >= 0 ? c.A(j, ec) * x[ec] : dot(c.A.row(j), x, c.n)) - t);
}

/// The pivot rows of the QR's levels (prow) and the first level the QR left in
/// another form (complete) and the coordinates fixed above it (ctri); the held pivots'
/// sides (pside) and the first level holding one.
void held_pivots(const Ctx& c, EqFirst& e, index& complete, index& ctri, index& first_held,
                 index& ncol) {
    index col = 0, n = c.n, k = c.k;
    complete = k;
    ctri = -1;
    first_held = k;
    for (index lev = 0; lev < k; ++lev) {
        index e0 = e.estarts[lev];
        index m = e.estarts[lev + 1] - e0;
        if (m > 0 && col < n && m >= n - col && complete == k) {
            complete = lev;
            ctri = col;
        }
        for (index i = 0; i < e.eranks[lev]; ++i) {
            index p = col + i;
            e.prow[p] = e0 + i;
            index j = e.erow[e.rowperm[e0 + i]];
            e.pside[p] = e.ucol[j] != -2 ? c.held[j] : 0;
            if (e.pside[p] != 0 && first_held == k) first_held = lev;
        }
        col += e.eranks[lev];
    }
    ncol = col;
    if (ctri < 0) ctri = ncol;
}

/// z_h = C⁻¹ e_h of each held pivot h (rows of Z), cn its pivot row's norm; −2 when a
/// held pivot lies where the QR is not triangular, else the count.
PRIOIK_VECTOR_CLONES
index held_inverse_columns(const Ctx& c, EqFirst& e, Mat Z, double* cn, index ctri, index ncol) {
    index nh = 0;
    for (index h = 0; h < ncol; ++h) {
        if (e.pside[h] == 0) continue;
        if (h >= ctri) return -2;
        double* z = Z.row(nh);
        for (index p = 0; p < h; ++p) z[p] = 0.0;
        const double* row = e.eB.row(e.prow[h]);
        z[h] = 1.0 / row[h];
        cn[nh] = std::sqrt(dot(row, row, h + 1));
        for (index p = h + 1; p < ctri; ++p) {
            row = e.eB.row(e.prow[p]);
            z[p] = -dot(row + h, z + h, p - h) / row[p];
        }
        e.hcol[nh] = h;
        e.pinned[nh] = 0;
        ++nh;
    }
    (void)c;
    return nh;
}

}  // namespace

PRIOIK_VECTOR_CLONES
index held_rows_optimal(const Ctx& c, EqFirst& e, const double* x) {
    index n = c.n, k = c.k;
    Mat Z = e.Lmat;
    const double* y = e.y;
    double* beta = e.beta;
    double* g = e.fs + 2 * c.R;
    double* cn = e.fs + 3 * c.R;
    index complete, ctri, first_held, ncol;
    held_pivots(c, e, complete, ctri, first_held, ncol);
    if (first_held == k) return -1;
    double xn = std::sqrt(dot(x, x, n));
    index nh = held_inverse_columns(c, e, Z, cn, ctri, ncol);
    if (nh < 0) return -2;
    index npinned = 0;
    index col = 0;
    for (index lev = 0; lev <= k; ++lev) {
        if (lev > first_held && npinned == nh) break;
        index colv;
        const double* gh;
        double scale;
        if (lev < k) {
            colv = col;
            col += e.eranks[lev];
            if (lev <= first_held || e.estarts[lev + 1] == e.estarts[lev]) continue;
            if (e.ucol[e.erow[e.estarts[lev]]] != -2) continue;
            if (lev > complete) return -2;
            for (index q = 0; q < n; ++q) g[q] = 0.0;
            double tn = 0.0;
            if (lev < k - 1) {
                for (index i = e.estarts[lev]; i < e.estarts[lev + 1]; ++i) {
                    index j = e.erow[e.rowperm[i]];
                    double t;
                    double r = eq_residual(c, e, j, x, t);
                    tn += c.sw[j] * c.sw[j] * t * t;
                    if (r != 0.0) {
                        const double* Bi = e.eB.row(i);
                        for (index q = 0; q < colv; ++q) g[q] += r * Bi[q];
                    }
                }
            } else {
                tn = add_level_gradient(c, e, c.starts[lev], c.starts[lev + 1], x, g);
                apply_qt(g, n, dense::reflectors(e.V, n, beta, e.pos, colv));
            }
            gh = g;
            scale = std::max(std::sqrt(dot(g, g, colv)),
                             e.scales[lev] * (e.scales[lev] * xn + std::sqrt(tn)));
        } else {
            if (complete < k) return -2;
            colv = ncol;
            gh = y;
            scale = std::sqrt(dot(y, y, ncol));
        }
        double worst = DUAL_FLOOR * scale;
        index release = -1;
        for (index i = 0; i < nh; ++i) {
            index h = e.hcol[i];
            if (h >= colv || e.pinned[i] != 0) continue;
            double wrong = e.pside[h] * dot(Z.row(i) + h, gh + h, colv - h) * cn[i];
            if (wrong > worst) {
                worst = wrong;
                release = h;
            } else if (-wrong > c.dual_tol * scale) {
                e.pinned[i] = 1;
                ++npinned;
            }
        }
        if (release >= 0) return e.erow[e.rowperm[e.prow[release]]];
    }
    return -1;
}

namespace {

/// The gradient of level lev below the held rows on the reduced QR's rotated free
/// coordinates (gf[:colv]) and on the held columns (gc); false when the level has no
/// gradient to read (met, or inequality rows only); -2 in code when unreadable.
PRIOIK_VECTOR_CLONES
bool fixed_level_gradient(const Ctx& c, EqFirst& e, index lev, index colv, const double* x,
                          double xn, index complete, double& scale, index& code) {
    index n = c.n, n2 = e.n2, M = c.M, k = c.k;
    double* gf = e.fs + 3 * c.R;
    double* g = e.fs + 2 * c.R;
    double* beta = e.beta;
    double* rs = e.work + n;
    double* gc = e.work + n + M;
    double tn = 0.0, rr = 0.0;
    bool some = false;
    for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j) {
        if (e.ucol[j] != -2) continue;
        some = true;
        double t;
        double r = eq_residual(c, e, j, x, t);
        rs[j] = r;
        rr += r * r;
        tn += c.sw[j] * c.sw[j] * t * t;
    }
    if (!some) return false;
    if (std::sqrt(rr) <= dense::X_PRECISION * (e.scales[lev] * xn + std::sqrt(tn))) return false;
    if (lev > complete) {
        code = -2;
        return false;
    }
    double gn;
    if (lev < k - 1) {
        for (index q = 0; q < colv; ++q) gf[q] = 0.0;
        for (index i = e.estarts[lev]; i < e.estarts[lev + 1]; ++i) {
            double r = rs[e.erow[e.rowperm[i]]];
            if (r != 0.0) {
                const double* Ri = e.eB.row(i);
                for (index q = 0; q < colv; ++q) gf[q] += r * Ri[q];
            }
        }
        gn = dot(gf, gf, colv);
        for (index i = 0; i < e.nheld; ++i) {
            index col = e.ucol[e.hcol[i]];
            double acc = 0.0;
            for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j)
                if (e.ucol[j] == -2) acc += rs[j] * c.sw[j] * c.A(j, col);
            gc[i] = acc;
            gn += acc * acc;
        }
    } else {
        for (index q = 0; q < n; ++q) g[q] = 0.0;
        add_level_gradient(c, e, c.starts[lev], c.starts[lev + 1], x, g);
        index q = 0;
        for (index cc = 0; cc < n; ++cc)
            if (e.pside[cc] == 0) gf[q++] = g[cc];
        gn = dot(g, g, n);
        apply_qt(gf, n2, dense::reflectors(e.V, n2, beta, e.pos, colv));
        for (index i = 0; i < e.nheld; ++i) gc[i] = g[e.ucol[e.hcol[i]]];
    }
    scale = std::max(std::sqrt(gn), e.scales[lev] * (e.scales[lev] * xn + std::sqrt(tn)));
    return true;
}

}  // namespace

PRIOIK_VECTOR_CLONES
index fixed_columns_optimal(const Ctx& c, EqFirst& e, const double* x) {
    index n = c.n, n2 = e.n2, M = c.M, k = c.k;
    const double* y = e.y;
    double* gf = e.fs + 3 * c.R;
    double* mu = e.work;
    double* gc = e.work + n + M;
    index* prowj = e.ispare;
    index col = 0, complete = k;
    for (index lev = 0; lev < k; ++lev) {
        index e0 = e.estarts[lev];
        index m = e.estarts[lev + 1] - e0;
        if (m > 0 && col < n2 && m >= n2 - col && complete == k) complete = lev;
        for (index i = 0; i < e.eranks[lev]; ++i) {
            e.prow[col + i] = e0 + i;
            prowj[col + i] = e.erow[e.rowperm[e0 + i]];
        }
        col += e.eranks[lev];
    }
    index ncol = col;
    for (index i = 0; i < e.nheld; ++i) e.pinned[i] = 0;
    index npinned = 0;
    double xn = std::sqrt(dot(x, x, n));
    col = 0;
    for (index lev = 0; lev <= k; ++lev) {
        if (lev > e.last_held && npinned == e.nheld) break;
        index colv;
        const double* gh;
        double scale;
        if (lev < k) {
            colv = col;
            col += e.eranks[lev];
            if (lev <= e.last_held) continue;
            index code = 0;
            if (!fixed_level_gradient(c, e, lev, colv, x, xn, complete, scale, code)) {
                if (code == -2) return -2;
                continue;
            }
            gh = gf;
        } else {
            if (complete < k) return -2;
            colv = ncol;
            gh = y;
            for (index i = 0; i < e.nheld; ++i) gc[i] = x[e.ucol[e.hcol[i]]];
            scale = xn;
        }
        for (index q = 0; q < colv; ++q) mu[q] = gh[q];
        for (index pp = 0; pp < colv; ++pp) {
            index p = colv - 1 - pp;
            const double* Cp = e.eB.row(e.prow[p]);
            double mp = mu[p] / Cp[p];
            mu[p] = mp;
            for (index q = 0; q < p; ++q) mu[q] -= Cp[q] * mp;
        }
        double worst = DUAL_FLOOR * scale;
        index release = -1;
        for (index i = 0; i < e.nheld; ++i) {
            if (e.pinned[i] != 0) continue;
            index j = e.hcol[i];
            index cj = e.ucol[j];
            double nu = gc[i];
            for (index p = 0; p < colv; ++p) {
                index jp = prowj[p];
                nu -= mu[p] * c.sw[jp] * c.A(jp, cj);
            }
            double wrong = c.held[j] * (c.A(j, cj) > 0.0 ? nu : -nu);
            if (wrong > worst) {
                worst = wrong;
                release = j;
            } else if (-wrong > c.dual_tol * scale) {
                e.pinned[i] = 1;
                ++npinned;
            }
        }
        if (release >= 0) return release;
    }
    return -1;
}

}  // namespace prioik::detail
