// A degenerate point's working set: the hard rows at their bounds
// and the non-negative least squares on their multipliers.
#include <cmath>

#include "active_set_internal.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


PRIOIK_VECTOR_CLONES
void rows_at_bounds(Ctx& c, index hard_end, double ynorm, index& m, index& extra) {
    index d = c.n - c.col;
    Mat E = c.Lw;
    index* cand = c.vpos;
    double* side = c.tq;
    double* inP = c.rhs;
    m = 0;
    extra = 0;
    for (index j = 0; j < hard_end; ++j) {
        int st = c.state[j];
        if (c.eqr[j] || st == 2) continue;
        bool working = st == -1 || st == 1;
        if (!working) {
            double r = odot(c, j, c.xc);
            double sz = row_size(c, j, ynorm, c.xc);
            if (std::isfinite(c.blo[j]) &&
                std::fabs(r - c.blo[j]) <= tol_of(c.primal_tol, sz, c.blo[j]))
                st = -1;
            else if (std::isfinite(c.bup[j]) &&
                     std::fabs(r - c.bup[j]) <= tol_of(c.primal_tol, sz, c.bup[j]))
                st = 1;
            else
                continue;
            ++extra;
        }
        bring(c, j);
        double sg = st == -1 ? 1.0 : -1.0;
        for (index k = 0; k < d; ++k) E(m, k) = sg * c.B(j, c.col + k);
        cand[m] = j;
        side[m] = st;
        inP[m] = working ? 1.0 : 0.0;
        ++m;
    }
}

namespace {

/// Row p of the LQ T[:p] (reflector t in V[t, t:d]): row copied, the p reflectors
/// applied, its own reflector made when what is left exceeds floor.
PRIOIK_VECTOR_CLONES
bool lq_append(Ctx& c, index p, const double* row, index d, double floor) {
    double* u = c.T.row(p);
    for (index k = 0; k < d; ++k) u[k] = row[k];
    reflect_vector(u, d, p, c.V, c.beta, nullptr, true);
    const double* tail = u + p;
    if (!(dot(tail, tail, d - p) > floor * floor)) return false;
    reflect_row(c.T, p, p, d, c.V, c.beta, p, p + 1, p + 1);
    return true;
}

}  // namespace

PRIOIK_VECTOR_CLONES
bool nnls_working_set(Ctx& c, index m, index d, double gscale) {
    Mat E = c.Lw;
    const double* g = c.g;
    const index* cand = c.vpos;
    double* inP = c.rhs;
    double* z = c.nu;
    double* h = c.px;
    double* r = c.p;
    index* order = c.perm;
    bool refactor = true;
    bool working = true;
    index p = 0;
    for (index it = 0; it < 2 * m + 2; ++it) {
        if (refactor) {
            refactor = false;
            p = 0;
            for (index i = 0; i < m; ++i)
                if (inP[i] != 0.0) {
                    if (p >= d || !lq_append(c, p, E.row(i), d, c.rcond * c.rnorm[cand[i]]))
                        return false;
                    order[p++] = i;
                }
        }
        for (index k = 0; k < d; ++k) h[k] = g[k];
        lq_multipliers(h, d, p, c.T, c.V, c.beta, nullptr, z);
        double worst = gscale;
        index out = -1;
        for (index i = 0; i < p; ++i) {
            double wrong = -z[i] * c.rnorm[cand[order[i]]];
            if (wrong > worst) {
                worst = wrong;
                out = order[i];
            }
        }
        if (out >= 0) {
            if (working) {
                working = false;
                for (index i = 0; i < p; ++i)
                    if (-z[i] * c.rnorm[cand[order[i]]] > gscale) inP[order[i]] = 0.0;
            } else {
                inP[out] = 0.0;
            }
            refactor = true;
            continue;
        }
        for (index k = 0; k < p; ++k) r[k] = 0.0;
        for (index k = p; k < d; ++k) r[k] = h[k];
        reflect_vector(r, d, p, c.V, c.beta, nullptr, false);
        double best = gscale;
        index enter = -1;
        if (p < d)
            for (index i = 0; i < m; ++i) {
                if (inP[i] != 0.0) continue;
                double ee = dot(E.row(i), E.row(i), d);
                if (!(ee > 0.0)) continue;
                double want = dot(E.row(i), r, d) * c.rnorm[cand[i]] / ee;
                if (want > best) {
                    best = want;
                    enter = i;
                }
            }
        if (enter < 0) return true;
        inP[enter] = 1.0;
        working = false;
        if (!lq_append(c, p, E.row(enter), d, c.rcond * c.rnorm[cand[enter]])) return false;
        order[p++] = enter;
    }
    return false;
}

}  // namespace prioik::detail
