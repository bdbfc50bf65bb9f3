// The warm start's equality-first try: the
// equality rows with the rows the last answer held, by the nested QR; its answer kept
// when proved the stack's, else the next guess.
#include <algorithm>
#include <cmath>

#include "active_set_equality_first.hpp"

#include "vector_clones.hpp"

namespace prioik::detail {


EqFirst::EqFirst(Ctx& c, ActiveSetWorkspace& ws) {
    index M = c.M, n = c.n, k = c.k;
    eflat = ws.eflat.data();
    eB = Mat{eflat, n};
    qr = &ws.equality_qr;
    V = Mat{qr->V.data(), n};
    beta = qr->beta.data();
    y = qr->y.data();
    pos = qr->pos.data();
    Lflat = ws.Lw.data();
    Lmat = Mat{Lflat, n};
    ec = ws.evec.data();
    scales = ec + M;
    mu2 = scales + k;
    emargins = mu2 + k;
    step_bound = emargins + k;
    index* ei = ws.eint.data();
    estarts = ei;
    eranks = ei + k + 1;
    index o = 2 * k + 1;
    ucol = ei + o;
    erow = ei + o + M;
    rowperm = ei + o + 2 * M;
    o += 3 * M;
    prow = ei + o;
    pside = ei + o + n;
    pinned = ei + o + 2 * n;
    hcol = ei + o + 3 * n;
    ecol = ei + o + 4 * n;
    qcol = ecol + M;
    fs = ws.efs.data();
    work = Lflat;
    ispare = ws.eispare.data();
}

namespace {

/// (‖a‖², its one non-zero column or −1).
double sparsity(const double* a, index n, index hint, index& column) {
    column = one_column(a, n, hint);
    return norm2_of_row(a, n, column);
}

/// The held rows, and whether they are taken as fixed coordinates (box rows on
/// distinct columns): fixedc (pside), the free columns (prow), their places (pinned).
void held_setup(Ctx& c, EqFirst& e, bool allow_fixed) {
    index n = c.n;
    index* fixedc = e.pside;
    index* fcol = e.prow;
    index* hlist = e.hcol;
    index* colmap = e.pinned;
    e.nheld = 0;
    e.last_held = -1;
    e.fixed = allow_fixed;
    for (index lev = 0; lev < c.k; ++lev)
        for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j)
            if (c.held[j] != 0) {
                if (c.eqr[j] || e.nheld >= n - 1)
                    e.fixed = false;
                else
                    hlist[e.nheld] = j;
                ++e.nheld;
                e.last_held = lev;
            }
    e.n2 = n;
    if (e.nheld == 0) e.fixed = false;
    if (e.fixed) {
        for (index cc = 0; cc < n; ++cc) fixedc[cc] = 0;
        for (index i = 0; i < e.nheld; ++i) {
            index j = hlist[i];
            index uc;
            sparsity(c.A.row(j), n, e.ucol[j], uc);
            e.ucol[j] = uc;
            if (uc < 0 || c.sw[j] == 0.0 || fixedc[uc] != 0) {
                e.fixed = false;
                break;
            }
            fixedc[uc] = 1;
            c.x[uc] = (c.held[j] > 0 ? c.upper[j] : c.lower[j]) / c.A(j, uc);
        }
    }
    if (e.fixed) {
        e.n2 = 0;
        for (index cc = 0; cc < n; ++cc)
            if (fixedc[cc] == 0) {
                fcol[e.n2] = cc;
                colmap[cc] = e.n2;
                ++e.n2;
            }
    }
    // the rows, reflectors and scratch of the QR: on the n2 free coordinates when fixed
    e.eB = Mat{e.eflat, e.n2};
    e.V = Mat{e.qr->V.data(), e.n2};
    e.Lmat = Mat{e.Lflat, e.n2};
}

/// One equality row of the reduced QR (held columns moved to its target): false when
/// the level refuses the fixed coordinates (a row on them alone above a held row).
bool fixed_equality_row(Ctx& c, EqFirst& e, index lev, index j, double& nn) {
    index n = c.n, n2 = e.n2;
    double s = c.sw[j];
    const double* Aj = c.A.row(j);
    nn = dot(Aj, Aj, n) * (s * s);
    index nz = count_nonzero(Aj, n);
    e.ucol[j] = -2;
    e.ecol[j] = one_column_hint(Aj, n, nz, e.ecol[j]);
    double t = c.row_eq[j] ? c.b[j] : c.lower[j];
    index ecl = e.ecol[j];
    if (ecl >= 0) {
        if (e.pside[ecl] != 0) {
            t -= Aj[ecl] * c.x[ecl];
            nz = 0;
        }
    } else {
        for (index i = 0; i < e.nheld; ++i) {
            index cc = e.ucol[e.hcol[i]];
            double a = Aj[cc];
            if (a != 0.0) {
                t -= a * c.x[cc];
                nz -= 1;
            }
        }
    }
    if (nz == 0) return lev > e.last_held;
    double* row = e.eflat + e.m * n2;
    if (ecl >= 0) {
        for (index q = 0; q < n2; ++q) row[q] = 0.0;
        row[e.pinned[ecl]] = s * Aj[ecl];
        e.qcol[e.m] = e.pinned[ecl];
    } else {
        for (index q = 0; q < n2; ++q) row[q] = s * Aj[e.prow[q]];
        e.qcol[e.m] = -1;
    }
    e.ec[e.m] = s * t;
    e.erow[e.m] = j;
    e.rowperm[e.m] = e.m;
    ++e.m;
    return true;
}

/// One row of the QR with the held rows as equalities (an equality row, or a held row
/// at its bound); returns s² ‖a_j‖².
double equality_row(Ctx& c, EqFirst& e, index j) {
    index n = c.n;
    double s = c.sw[j];
    const double* Aj = c.A.row(j);
    double* row = e.eB.row(e.m);
    for (index q = 0; q < n; ++q) row[q] = s * Aj[q];
    index column;
    if (c.eqr[j]) {
        e.ec[e.m] = s * (c.row_eq[j] ? c.b[j] : c.lower[j]);
        e.ucol[j] = -2;
        column = e.ecol[j] = one_column(Aj, n, e.ecol[j]);
    } else {
        e.ec[e.m] = s * (c.held[j] > 0 ? c.upper[j] : c.lower[j]);
        column = e.ucol[j] = one_column(Aj, n, e.ucol[j]);
    }
    double nn = norm2_of_row(row, n, column);
    e.qcol[e.m] = column;
    e.erow[e.m] = j;
    e.rowperm[e.m] = e.m;
    ++e.m;
    return nn;
}

/// The QR's rows, level by level, and the levels' scales: 0, −2 (a level of extreme
/// scale) or FIXED_REFUSED.
index build_rows(Ctx& c, EqFirst& e) {
    index n = c.n;
    e.m = 0;
    e.estarts[0] = 0;
    for (index lev = 0; lev < c.k; ++lev) {
        double acc = 0.0;
        for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j) {
            double s = c.sw[j];
            double nn;
            if (e.fixed && c.eqr[j]) {
                if (!fixed_equality_row(c, e, lev, j, nn)) return FIXED_REFUSED;
            } else if (e.fixed && c.held[j] != 0) {
                nn = s * c.A(j, e.ucol[j]);
                nn *= nn;
            } else if (!e.fixed && (c.eqr[j] || c.held[j] != 0)) {
                nn = equality_row(c, e, j);
            } else {
                index uc;
                nn = sparsity(c.A.row(j), n, e.ucol[j], uc) * (s * s);
                e.ucol[j] = uc;
            }
            acc += nn;
        }
        if (dense::level_extreme(c.A, n, acc, c.starts[lev], c.starts[lev + 1])) return -2;
        e.scales[lev] = std::sqrt(acc);
        e.step_bound[lev] = 0.0;
        e.estarts[lev + 1] = e.m;
    }
    return 0;
}

/// The nested QR of the rows built (on the free coordinates when fixed), x written.
void solve_rows(Ctx& c, EqFirst& e) {
    index n = c.n, n2 = e.n2;
    NestedQRWorkspace& ws = *e.qr;
    ws.n = n2;      // sized for n columns, used at the free coordinates' count
    ws.M = e.m;
    NestedQRParameters params;
    params.rcond = c.rcond;
    params.row_columns = e.qcol;
    NestedQROutput out{c.x, e.eranks, e.mu2, e.emargins,
                       (e.fixed || e.nheld > 0) ? e.rowperm : nullptr};
    nested_qr(e.eB.ref(e.m, n2), e.ec, e.estarts, c.k, e.scales, params, false, ws, out);
    if (!e.fixed) return;
    index at = n2;
    for (index cc = n - 1; cc >= 0; --cc)
        if (e.pside[cc] == 0) c.x[cc] = c.x[--at];
    for (index i = 0; i < e.nheld; ++i) {
        index j = e.hcol[i];
        index uc = e.ucol[j];
        c.x[uc] = (c.held[j] > 0 ? c.upper[j] : c.lower[j]) / c.A(j, uc);
    }
}

/// The QR's rank decisions read: −1 when clear and every level down to a held one is
/// met exactly, else −2 or FIXED_REFUSED.
index check_ranks(const Ctx& c, const EqFirst& e) {
    for (index lev = 0; lev < c.k; ++lev) {
        if (e.emargins[lev] <= dense::AMBIGUITY) return -2;
        index count = e.estarts[lev + 1] - e.estarts[lev];
        if (e.fixed) {
            if (lev <= e.last_held && e.eranks[lev] != count) return FIXED_REFUSED;
        } else if (e.nheld > 0 && count > 0) {
            for (index r = e.estarts[lev]; r < e.estarts[lev + 1]; ++r)
                if (e.ucol[e.erow[r]] != -2) {
                    if (e.eranks[lev] != count) return -2;
                    break;
                }
        }
    }
    return -1;
}

/// The inequality rows at x*: held ones on their bound, the others inside (else the
/// most violated as the next guess, verdict −3), box rows resolved; −1 when all hold.
index check_rows(Ctx& c, EqFirst& e, double xn, index& add, int& side) {
    index n = c.n;
    double* x = c.x;
    if (e.nheld > 0 && !e.fixed)
        for (index j = 0; j < c.M; ++j) {
            index uc = e.ucol[j];
            if (c.held[j] != 0 && uc >= 0) {
                double bound = c.held[j] > 0 ? c.upper[j] : c.lower[j];
                if (std::fabs(c.A(j, uc) * x[uc] - bound) <=
                    dense::X_PRECISION * xn * std::fabs(c.A(j, uc)))
                    x[uc] = bound / c.A(j, uc);
            }
        }
    double worst = 0.0;
    add = -1;
    side = 0;
    for (index j = 0; j < c.M; ++j) {
        index uc = e.ucol[j];
        if (uc == -2) continue;
        double lo = c.lower[j], up = c.upper[j];
        double r = uc >= 0 ? c.A(j, uc) * x[uc] : dot(c.A.row(j), x, n);
        bool held_row = c.held[j] != 0;
        double size = 0.0;
        if (held_row || r < lo || r > up)
            size = uc >= 0 ? std::fabs(c.A(j, uc)) * (std::fabs(x[uc]) + 1.0)
                           : std::sqrt(dot(c.A.row(j), c.A.row(j), n)) * xn;
        if (held_row) {
            double bound = c.held[j] > 0 ? up : lo;
            double s = c.sw[j];
            if (!(std::fabs(s * (r - bound)) <= tol_of(c.primal_tol, s * size, s * bound)))
                return -2;
        } else if (r < lo || r > up) {
            double v = (r < lo ? lo - r : r - up) / std::max(size, 1e-300);
            if (v > worst) {
                worst = v;
                add = j;
                side = r < lo ? -1 : 1;
            }
            continue;
        }
        if (uc >= 0) {
            double s = c.sw[j];
            if (box_row_unresolved(s * c.A(j, uc), x[uc], s * r, s * lo, s * up, xn,
                                   c.primal_tol))
                return -2;
        }
    }
    return add >= 0 ? -3 : -1;
}

/// The answer's levels' violations, ranks and margins.
void write_levels(Ctx& c, const EqFirst& e) {
    index n = c.n;
    const double* x = c.x;
    for (index lev = 0; lev < c.k; ++lev) {
        double acc = 0.0;
        for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j) {
            double v;
            if (e.ucol[j] == -2) {
                index ecl = e.ecol[j];
                double ax = ecl >= 0 ? c.A(j, ecl) * x[ecl] : dot(c.A.row(j), x, n);
                v = c.sw[j] * (ax - (c.row_eq[j] ? c.b[j] : c.lower[j]));
            } else if (c.held[j] == 0) {
                continue;
            } else {
                index uc = e.ucol[j];
                double r = uc >= 0 ? c.A(j, uc) * x[uc] : dot(c.A.row(j), x, n);
                v = c.sw[j] * (r < c.lower[j] ? c.lower[j] - r
                                              : (r > c.upper[j] ? r - c.upper[j] : 0.0));
            }
            acc += v * v;
        }
        c.w2[lev] = acc;
        c.res[lev] = std::sqrt(acc);
        c.ranks[lev] = e.eranks[lev];
        c.margins[lev] = e.emargins[lev];
        if (e.fixed)
            for (index j = c.starts[lev]; j < c.starts[lev + 1]; ++j)
                if (c.held[j] != 0) c.ranks[lev] += 1;
    }
}

bool rows_valid_eq(const Ctx& c) {
    index bad = 0;
    for (index j = 0; j < c.M; ++j) {
        bool eq = c.row_eq[j] != 0;
        double lo = eq ? c.b[j] : c.lower[j];
        double up = eq ? c.b[j] : c.upper[j];
        double s = c.sw[j];
        bool ok = (lo <= up) & (lo < inf) & (up > -inf) & (s > 0.0) & (s < inf);
        bad += ok ? 0 : 1;
        c.eqr[j] = lo == up ? 1 : 0;
    }
    return bad == 0;
}

}  // namespace

/// Verdict −1 (x* is the answer, written), −3 with a next guess
/// (row, side; side 0 a release), FIXED_REFUSED, or −2.
PRIOIK_VECTOR_CLONES
index equality_first_try(Ctx& c, EqFirst& e, bool allow_fixed, index& row, int& side) {
    row = -1;
    side = 0;
    if (!rows_valid_eq(c)) return -2;
    held_setup(c, e, allow_fixed);
    index built = build_rows(c, e);
    if (built != 0) return built;
    solve_rows(c, e);
    double xx = dot(c.x, c.x, c.n);
    if (!(xx <= dense::PRECISION_LIMIT_NORM * dense::PRECISION_LIMIT_NORM)) return -2;
    index ranks = check_ranks(c, e);
    if (ranks != -1) return ranks;
    double xn = std::sqrt(xx);
    index add;
    int add_side;
    index verdict = check_rows(c, e, xn, add, add_side);
    if (verdict == -2) return -2;
    if (verdict == -3) {
        row = add;
        side = add_side;
        return -3;
    }
    if (e.fixed || e.nheld > 0) {
        index release = e.fixed ? fixed_columns_optimal(c, e, c.x) : held_rows_optimal(c, e, c.x);
        if (release != -1) {
            row = release;
            return release >= 0 ? -3 : -2;
        }
    }
    write_levels(c, e);
    return -1;
}

namespace {

/// The row, not held, that first leaves its interval on the segment from xref to x;
/// xref moves to the blocking point.
PRIOIK_VECTOR_CLONES
void first_blocking(Ctx& c, double* xref, index& row, int& side) {
    index n = c.n;
    double best = 2.0;
    for (index j = 0; j < c.M; ++j) {
        if (c.eqr[j] || c.held[j] != 0) continue;
        double r1 = dot(c.A.row(j), c.x, n);
        double bound;
        int s;
        if (r1 < c.lower[j]) {
            bound = c.lower[j];
            s = -1;
        } else if (r1 > c.upper[j]) {
            bound = c.upper[j];
            s = 1;
        } else {
            continue;
        }
        double r0 = dot(c.A.row(j), xref, n);
        double t = r1 != r0 ? (bound - r0) / (r1 - r0) : 0.0;
        t = std::min(std::max(t, 0.0), 1.0);
        if (t < best) {
            best = t;
            row = j;
            side = s;
        }
    }
    if (best <= 1.0)
        for (index k = 0; k < n; ++k) xref[k] += best * (c.x[k] - xref[k]);
}

}  // namespace

SolveCode equality_first_data(Ctx& c, ActiveSetWorkspace& ws) {
    ActiveSetResult& out = *c.out;
    out.equality_first = 0.0;
    if (!c.use_warm || out.next_try == 0.0) return SolveCode::not_tried;
    EqFirst e(c, ws);
    double* xref = c.xs;
    bool have_ref = false, kept = out.next_try == 2.0, guessed = false, allow_fixed = true;
    index attempt = 0;
    while (attempt < GUESSES) {
        index row;
        int side;
        index verdict = equality_first_try(c, e, allow_fixed, row, side);
        if (verdict == FIXED_REFUSED) {
            allow_fixed = false;
            continue;
        }
        ++attempt;
        if (verdict == -1) break;
        if (verdict == -2 || attempt == GUESSES) {
            out.equality_first = kept ? -2.0 : -1.0;
            return SolveCode::not_tried;
        }
        if (side == 0) {
            for (index k = 0; k < c.n; ++k) xref[k] = c.x[k];
            have_ref = true;
        } else if (have_ref) {
            first_blocking(c, xref, row, side);
        }
        c.held[row] = static_cast<std::int8_t>(side);
        guessed = true;
    }
    if (guessed) {
        out.next_try = 1.0;
        for (index j = 0; j < c.M; ++j)
            if (c.held[j] != 0) {
                out.next_try = 2.0;
                break;
            }
    }
    double total = 0.0;
    for (index lev = 0; lev < c.k; ++lev) {
        total += c.w2[lev];
        c.iters[lev] = 0;
        c.flags[lev] = FLAG_OK;
    }
    c.iters[c.k] = 0;
    c.flags[c.k] = FLAG_OK;
    c.ranks[c.k] = 0;
    c.margins[c.k] = inf;
    out.equality_first = 1.0;
    return summary(c, total, 0);
}

}  // namespace prioik::detail
