// solve_data: load and scale, then per level the warm try, the primal active-set
// iterations (step, ratio test, multipliers) and the fixing; the tie-break; the summary.
#include <algorithm>
#include <cmath>

#include "active_set_internal.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


namespace {

/// One level's iteration state.
struct Level {
    index lev = 0, s0 = 0, s1 = 0, hard_end = 0, d = 0;
    double scale = 0.0, soft_tol = 0.0;
    index nh = 0, nw = 0;
    StepOut st;
    double path_margin = inf;
    bool have_step = false, refuted = false, bland = false, proposed = false;
    bool stalled = false, settled = false, near_release = false;
    index joined = -1, stall = 0;
};

/// Whether every row's interval and √w are valid; eqr[j] = 1 where lo = up.
bool rows_valid(const Ctx& c, std::int8_t* flags) {
    index bad = 0;
    for (index j = 0; j < c.M; ++j) {
        bool e = c.row_eq[j] != 0;
        double lo = e ? c.b[j] : c.lower[j];
        double up = e ? c.b[j] : c.upper[j];
        double s = c.sw[j];
        bool ok = (lo <= up) & (lo < inf) & (up > -inf) & (s > 0.0) & (s < inf);
        bad += ok ? 0 : 1;
        flags[j] = lo == up ? 1 : 0;
    }
    return bad == 0;
}

/// The rows weighed into B and Bo, bounds, norms, equality flags, single columns;
/// false at the first value that is not valid.
PRIOIK_VECTOR_CLONES
bool load_rows(Ctx& c) {
    index M = c.M, n = c.n;
    if (!rows_valid(c, c.eqr)) return false;
    for (index j = 0; j < M; ++j) {
        double s = c.sw[j];
        double* Bj = c.B.row(j);
        double* Boj = c.Bo.row(j);
        const double* Aj = c.A.row(j);
        for (index k = 0; k < n; ++k) {
            double v = s * Aj[k];
            Bj[k] = v;
            Boj[k] = v;
        }
        c.ucol[j] = c.row_eq[j] ? -1 : one_column(Aj, n, c.ucol[j]);
        double nn = norm2_of_row(Bj, n, c.ucol[j]);
        c.nrot[j] = 0;
        bool e = c.row_eq[j] != 0;
        c.blo[j] = s * (e ? c.b[j] : c.lower[j]);
        c.bup[j] = s * (e ? c.b[j] : c.upper[j]);
        c.rnorm[j] = std::sqrt(nn);
        if (!std::isfinite(c.rnorm[j])) return false;
        c.state[j] = 0;
    }
    for (index j = M; j < M + n; ++j) {
        c.blo[j] = 0.0;
        c.bup[j] = 0.0;
        c.eqr[j] = 1;
        c.rnorm[j] = 1.0;
        c.state[j] = 0;
    }
    return true;
}

/// Whether a level is of extreme scale.
PRIOIK_VECTOR_CLONES
bool extreme_scale_rows(const Ctx& c) {
    for (index lev = 0; lev < c.k; ++lev) {
        double acc = 0.0;
        for (index i = c.starts[lev]; i < c.starts[lev + 1]; ++i) {
            double r = c.rnorm[i] / c.sw[i];
            acc += r * r;
        }
        if (dense::level_extreme(c.A, c.n, acc, c.starts[lev], c.starts[lev + 1])) return true;
    }
    return false;
}

/// The working rows: hard ones first, then the level's.
PRIOIK_VECTOR_CLONES
void gather(Ctx& c, Level& L) {
    index nh = 0;
    for (index j = 0; j < L.hard_end; ++j) {
        int st = c.state[j];
        if (st == -1 || st == 1) {
            c.rows[nh] = j;
            c.tgt[nh] = st == -1 ? c.blo[j] : c.bup[j];
            ++nh;
        }
    }
    index nw = 0;
    for (index j = L.s0; j < L.s1; ++j) {
        int st = c.state[j];
        if (st != 0) {
            c.rows[nh + nw] = j;
            c.tgt[nh + nw] = st == 1 ? c.bup[j] : c.blo[j];
            ++nw;
        }
    }
    L.nh = nh;
    L.nw = nw;
}

/// The side row j violates at xc (0: inside), at the primal tolerance.
int side_at(const Ctx& c, index j, double ynorm) {
    double r = odot(c, j, c.xc);
    double sz = row_size(c, j, ynorm, c.xc);
    return violated_side(r, c.blo[j], c.bup[j], tol_of(c.primal_tol, sz, c.blo[j]),
                         tol_of(c.primal_tol, sz, c.bup[j]));
}

/// The level's rows, scale and first states; false when the level is skipped, and
/// `stop` when the tie-break is not needed (no inequality row left).
bool level_setup(Ctx& c, Level& L, bool& stop) {
    index lev = L.lev, M = c.M, n = c.n;
    stop = false;
    if (lev < c.k) {
        L.s0 = c.starts[lev];
        L.s1 = c.starts[lev + 1];
        L.hard_end = L.s0;
    } else {
        bool alive = false;
        for (index j = 0; j < M; ++j)
            if (c.state[j] != 2 && !c.eqr[j] &&
                (std::isfinite(c.blo[j]) || std::isfinite(c.bup[j]))) {
                alive = true;
                break;
            }
        if (!alive) {
            for (index k = c.col; k < n; ++k) c.y[k] = 0.0;
            stop = true;
            return false;
        }
        L.s0 = M + c.col;
        L.s1 = M + n;
        L.hard_end = M;
        for (index j = L.s0; j < L.s1; ++j) {
            for (index k = 0; k < n; ++k) c.B(j, k) = 0.0;
            c.B(j, j - M) = 1.0;
            c.nrot[j] = c.nf;
        }
    }
    if (L.s1 == L.s0) return false;
    L.d = n - c.col;
    double acc = 0.0;
    for (index j = L.s0; j < L.s1; ++j) acc += c.rnorm[j] * c.rnorm[j];
    L.scale = std::sqrt(acc);
    L.soft_tol = c.rcond * L.scale;
    double ynorm = std::sqrt(dot(c.y, c.y, n));
    for (index j = L.s0; j < L.s1; ++j)
        c.state[j] = c.eqr[j] ? 3 : static_cast<std::int8_t>(side_at(c, j, ynorm));
    return true;
}

/// Move y and xc by the full step p (the warm try's), keeping the old ones in g, xs.
void take_full_step(Ctx& c, const Level& L) {
    for (index k = 0; k < L.d; ++k) {
        c.g[k] = c.y[c.col + k];
        c.y[c.col + k] += c.p[k];
    }
    lift(c, c.p, c.px);
    for (index k = 0; k < c.n; ++k) {
        c.xs[k] = c.xc[k];
        c.xc[k] += c.px[k];
    }
}

/// The warm try: the step of last time's working set; kept when every hard row stays
/// feasible at its end, else undone (the level starts cold, `refuted`).
PRIOIK_VECTOR_CLONES
void warm_try(Ctx& c, Level& L) {
    index lev = L.lev;
    for (index j = 0; j < L.s1; ++j) c.saved[j] = c.state[j];
    for (index j = 0; j < L.s1; ++j) {
        if (c.state[j] == 2 || c.eqr[j]) continue;
        int ws = c.warm_state[lev * c.R + j];
        if (ws == -1 && std::isfinite(c.blo[j]))
            c.state[j] = -1;
        else if (ws == 1 && std::isfinite(c.bup[j]))
            c.state[j] = 1;
        else if (j < L.hard_end)
            c.state[j] = 0;
    }
    gather(c, L);
    L.st = step(c, L.nh, L.nw, L.soft_tol, true, true);
    c.iters[lev] += 1;
    for (index i = L.st.hr; i < L.nh; ++i) c.state[c.rows[i]] = 0;
    take_full_step(c, L);
    double ynorm = std::sqrt(dot(c.y, c.y, c.n));
    bool feasible = true;
    for (index j = 0; j < L.hard_end; ++j) {
        if (c.state[j] != 0 || c.eqr[j]) continue;
        if (side_at(c, j, ynorm) != 0) {
            feasible = false;
            break;
        }
    }
    if (feasible) {
        L.path_margin = L.st.margin;
        L.have_step = L.st.hr == L.nh;
        for (index j = L.s0; j < L.s1; ++j)
            if (c.state[j] == 0) {
                c.state[j] = static_cast<std::int8_t>(side_at(c, j, ynorm));
                if (c.state[j] != 0) L.have_step = false;
            }
    } else {
        L.refuted = true;
        for (index k = 0; k < L.d; ++k) c.y[c.col + k] = c.g[k];
        for (index k = 0; k < c.n; ++k) c.xc[k] = c.xs[k];
        for (index j = 0; j < L.s1; ++j) c.state[j] = c.saved[j];
    }
}

/// The ratio test of the step p (length pn): the first non-working row it would take
/// out of its interval (blk, at alpha, on side bside).
PRIOIK_VECTOR_CLONES
void ratio_test(Ctx& c, const Level& L, double pn, double& alpha, index& blk, int& bside) {
    alpha = 1.0;
    blk = -1;
    bside = 0;
    if (!(pn > 0.0)) return;
    double block_eps = std::max(BLOCK_EPS, c.rcond);
    lift(c, c.p, c.px);
    for (index j = 0; j < L.s1; ++j) {
        if (c.state[j] != 0 || c.eqr[j] || (j >= L.hard_end && j < L.s0)) continue;
        double cp = odot(c, j, c.px);
        double thr = block_eps * c.rnorm[j] * pn;
        double a;
        int side;
        if (cp < -thr && std::isfinite(c.blo[j])) {
            a = (c.blo[j] - odot(c, j, c.xc)) / cp;
            side = -1;
        } else if (cp > thr && std::isfinite(c.bup[j])) {
            a = (c.bup[j] - odot(c, j, c.xc)) / cp;
            side = 1;
        } else {
            continue;
        }
        if (a < 0.0) a = 0.0;
        if (a < alpha) {
            alpha = a;
            blk = j;
            bside = side;
        }
    }
}

/// One iteration's step: the last factorization with the joined row appended, or a
/// fresh one; then the ratio test and the move. Returns true when a row blocked (the
/// iteration continues with it working).
bool iterate_step(Ctx& c, Level& L) {
    index lev = L.lev, d = L.d;
    bool appended = false;
    if (L.joined >= 0) {
        index jb = L.joined;
        bring(c, jb);
        StepOut a = eqp_append(c, L.nh, L.nw, L.soft_tol, jb,
                               c.state[jb] == -1 ? c.blo[jb] : c.bup[jb]);
        L.joined = -1;
        if (a.hr >= 0) {
            L.nh += 1;
            a.full = false;
            a.gn = -1.0;
            L.st = a;
            appended = true;
        }
    }
    if (!appended) {
        gather(c, L);
        bool held_rows = c.iters[lev] == 1 || (L.refuted && c.iters[lev] == 2);
        L.st = step(c, L.nh, L.nw, L.soft_tol, false, held_rows);
    }
    L.path_margin = std::min(L.path_margin, L.st.margin);
    for (index i = L.st.hr; i < L.nh; ++i) c.state[c.rows[i]] = 0;
    double pn = std::sqrt(dot(c.p, c.p, d));
    if (pn <= ZERO_STEP * std::sqrt(dot(c.y, c.y, c.n))) {
        for (index k = 0; k < d; ++k) c.p[k] = 0.0;
        pn = 0.0;
    }
    double alpha;
    index blk;
    int bside;
    ratio_test(c, L, pn, alpha, blk, bside);
    if (pn > 0.0 && alpha > DEGENERATE) {
        L.stall = 0;
        L.bland = false;
    } else {
        L.stall += 1;
    }
    if (pn > 0.0) {
        for (index k = 0; k < d; ++k) c.y[c.col + k] += alpha * c.p[k];
        for (index k = 0; k < c.n; ++k) c.xc[k] += alpha * c.px[k];
    }
    if (blk < 0) return false;
    c.state[blk] = static_cast<std::int8_t>(bside);
    L.bland = L.bland || alpha <= DEGENERATE;
    if (blk < L.hard_end && !L.st.full && L.st.gn < 0.0 && L.st.hr == L.nh) L.joined = blk;
    return true;
}

/// Soft rows on the wrong side of their bound: released or switched (true when any
/// changed); near_release noted.
PRIOIK_VECTOR_CLONES
bool release_wrong_side(Ctx& c, Level& L, double ynorm) {
    bool changed = false;
    L.near_release = false;
    for (index j = L.s0; j < L.s1; ++j) {
        int st = c.state[j];
        if (st != -1 && st != 1) continue;
        double r = odot(c, j, c.xc);
        double sz = row_size(c, j, ynorm, c.xc);
        double tl = tol_of(c.primal_tol * RELEASE, sz, c.blo[j]);
        double tu = tol_of(c.primal_tol * RELEASE, sz, c.bup[j]);
        if (st == -1 && r > c.blo[j] + tl) {
            c.state[j] = r > c.bup[j] + tu ? 1 : 0;
            changed = true;
        } else if (st == 1 && r < c.bup[j] - tu) {
            c.state[j] = r < c.blo[j] - tl ? -1 : 0;
            changed = true;
        } else if ((st == -1 ? r - c.blo[j] : c.bup[j] - r) >
                   dense::X_PRECISION * ynorm * c.rnorm[j]) {
            L.near_release = true;
        }
    }
    return changed;
}

/// The row to release among the wrong-signed ones so far.
void pick_release(bool bland, index j, double value, index& drop, double& worst) {
    if (bland) {
        if (drop < 0 || j < drop) drop = j;
        return;
    }
    if (value > worst) {
        drop = j;
        worst = value;
    }
}

/// The hard row to release by its multiplier (−1: none), gscale the dual threshold.
PRIOIK_VECTOR_CLONES
index pick_drop(Ctx& c, Level& L, double ynorm, double& gscale) {
    index nh = L.nh, nw = L.nw, hr = L.st.hr;
    double gn = L.st.gn >= 0.0 ? L.st.gn : hard_multipliers(c, nh, hr, nw);
    double tn = 0.0;
    for (index i = nh; i < nh + nw; ++i) tn += c.tgt[i] * c.tgt[i];
    double gfull = std::max(gn, L.scale * (L.scale * ynorm + std::sqrt(tn)));
    gscale = c.dual_tol * gfull;
    index drop = -1;
    double worst = 0.0;
    for (index i = 0; i < hr; ++i) {
        index j = c.rows[i];
        double wrong = (c.state[j] == -1 ? -c.nu[i] : c.nu[i]) * c.rnorm[j];
        if (wrong > gscale) pick_release(L.bland, j, wrong, drop, worst);
    }
    if (drop < 0 && L.st.gn < 0.0 && L.st.rs < nw) {
        double floor = DUAL_FLOOR * gfull;
        worst = 0.0;
        for (index i = 0; i < hr; ++i) {
            index j = c.rows[i];
            double wrong = (c.state[j] == -1 ? -c.nu[i] : c.nu[i]) * c.rnorm[j];
            if (!(wrong > floor)) continue;
            double un, gain;
            freed_gain(c, nh, hr, nw, L.st.rs, i, un, gain);
            if (!(gain > L.soft_tol)) continue;
            double move = std::fabs(c.nu[i]) / (un * gain);
            if (move * L.scale > gscale) pick_release(L.bland, j, move, drop, worst);
        }
    }
    return drop;
}

/// At a degenerate point's first release: the working set the multipliers need (true
/// when it moved the set).
bool propose_working_set(Ctx& c, Level& L, double ynorm, double gscale) {
    index m_at, extra;
    rows_at_bounds(c, L.hard_end, ynorm, m_at, extra);
    if (extra <= 0) return false;
    if (L.lev < c.k)
        soft_gradient_x(c, L.nh, L.nw, c.px, c.g);
    else
        soft_gradient(c, L.nh, L.nw, c.g);
    if (!nnls_working_set(c, m_at, L.d, gscale)) return false;
    bool moved = false;
    for (index i = 0; i < m_at; ++i) {
        index j = c.vpos[i];
        int want = c.rhs[i] != 0.0 ? (c.tq[i] < 0.0 ? -1 : 1) : 0;
        if (c.state[j] != want) {
            c.state[j] = static_cast<std::int8_t>(want);
            moved = true;
        }
    }
    return moved;
}

/// The primal active-set iterations of one level, until it settles, stalls or hits
/// the cap.
void iterations(Ctx& c, Level& L) {
    index lev = L.lev;
    while (true) {
        if (L.have_step) {
            L.have_step = false;
        } else {
            if (c.iters[lev] >= c.max_iter) {
                c.flags[lev] = FLAG_ITERATION_CAP;
                return;
            }
            c.iters[lev] += 1;
            if (iterate_step(c, L)) continue;
        }
        double ynorm = std::sqrt(dot(c.y, c.y, c.n));
        if (release_wrong_side(c, L, ynorm)) continue;
        if (L.st.hr == 0) {
            L.settled = true;
            return;
        }
        double gscale;
        index drop = pick_drop(c, L, ynorm, gscale);
        if (drop < 0) {
            L.settled = true;
            return;
        }
        if (L.stall > 2 * L.s1 + 10) {
            L.settled = true;
            L.stalled = true;
            return;
        }
        if (!L.proposed) {
            L.proposed = true;
            if (propose_working_set(c, L, ynorm, gscale)) continue;
        }
        c.state[drop] = 0;
    }
}

/// The level's margin and flags, and its working set kept for the next solve.
void record_level(Ctx& c, const Level& L) {
    index lev = L.lev;
    c.margins[lev] = L.st.margin;
    if (L.path_margin <= dense::AMBIGUITY && L.st.margin > dense::AMBIGUITY &&
        c.flags[lev] == FLAG_OK)
        c.flags[lev] = FLAG_AMBIGUOUS_PATH;
    if (L.settled && L.near_release && c.flags[lev] == FLAG_OK) c.flags[lev] = FLAG_NEAR_RELEASE;
    if (L.stalled && c.flags[lev] == FLAG_OK) c.flags[lev] = FLAG_STALLED;
    for (index j = 0; j < L.s1; ++j) {
        int st = c.state[j];
        bool held = st == -1 || st == 1;
        c.warm_state[lev * c.R + j] = static_cast<std::int8_t>(held ? st : 0);
        if (held && j < c.M) c.held[j] = static_cast<std::int8_t>(st);
    }
    c.warm_valid[lev] = 1;
}

}  // namespace

void fix_level(Ctx& c, index lev, index s0, index s1, double scale, double soft_tol,
               const StepOut& st, index nh, index nw, bool settled);

void solve_levels(Ctx& c) {
    for (index lev = 0; lev <= c.k; ++lev) {
        c.iters[lev] = 0;
        c.flags[lev] = FLAG_OK;
        c.ranks[lev] = 0;
        c.margins[lev] = inf;
        if (c.col >= c.n) continue;
        Level L;
        L.lev = lev;
        bool stop;
        if (!level_setup(c, L, stop)) {
            if (stop) break;
            continue;
        }
        if (c.use_warm && c.warm_valid[lev]) warm_try(c, L);
        iterations(c, L);
        record_level(c, L);
        if (lev == c.k) break;
        fix_level(c, lev, L.s0, L.s1, L.scale, L.soft_tol, L.st, L.nh, L.nw, L.settled);
    }
}

bool load_and_scale(Ctx& c) { return load_rows(c) && !extreme_scale_rows(c); }

}  // namespace prioik::detail
