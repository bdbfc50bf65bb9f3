// The certificate's reading of one point, level by level (certificate.hpp;
// hierarchy.analysis._check_lexicographic): the rows' activity, a level's KKT residual
// and verdict, the slack rows' check, the band, and the rows a level adds above the
// next (fixed rows into the null space, rows at one bound into the signed rows).
#include <algorithm>
#include <cmath>

#include "certificate_linalg.hpp"
#include "prioik/certificate.hpp"

namespace prioik {

using cert::robust_norm;

namespace {

/// rows beyond a bound by more than this (relative to the activity rule's size) and
/// within the activity tolerance are the band (_BAND_FLOOR)
constexpr double kBandFloor = 1e-12;
/// rows violated by at most this (relative to their size) may be a solver's slack
/// (_NEARLY_FEASIBLE)
constexpr double kNearlyFeasible = 1e-6;
/// singular values of a level's active rows floored at this of their norm
/// (CERTIFICATE_SIGMA_FLOOR)
constexpr double kSigmaFloor = 1e-6;

constexpr double kDefaultTol = 1e-8;

/// B Z of fewer columns than this is rotated as it is (right_svd_tall): its sweeps cost
/// less than the two reductions
constexpr index kPreconditionFrom = 16;

double precision(double tol) { return cert::kXPrecision * std::max(1.0, tol / kDefaultTol); }

/// _rounding: how far rounding alone may leave a level's weighted rows from where they
/// belong — precision(tol) times the larger of the level's scale (its terms) and
/// ‖x‖ ‖√W_i A_i‖_F (coordinates known to X_PRECISION ‖x‖, however small the level's
/// columns where x is large)
double level_rounding(double tol, double scale, double x_norm, double level_norm) {
    return precision(tol) * std::max(scale, x_norm * level_norm);
}

/// _level_passes: the residual against the level's scale, and its square (what the
/// value could still gain) against the value, unless it is at the level's rounding
bool level_passes(double res, double scale, double violation, double tol, double rounding) {
    if (!(std::isfinite(res) && res <= tol * std::max(scale, 1e-300))) return false;
    return res * res <= tol * std::max(1.0, violation * violation) || res <= rounding;
}

bool ambiguous_decision(const double* values, index count, double tol) {
    if (!(tol > 0)) return false;
    for (index j = 0; j < count; ++j)
        if (values[j] > tol / kAmbiguity && values[j] <= tol * kAmbiguity) return true;
    return false;
}

}  // namespace

void Certificate::activity(const Stack& s, const double* x) {
    const index n = layout_.n, M = layout_.M;
    const double tol = options_.tol;
    auto& w = ws_;
    for (index r = 0; r < M; ++r) {
        const bool eq = layout_.row_eq[r] != 0;
        const double lo = eq ? s.b[r] : s.lower[r], up = eq ? s.b[r] : s.upper[r];
        const double* row = s.A + r * n;
        w.lower[r] = lo;
        w.upper[r] = up;
        w.norms[r] = std::sqrt(dot(row, row, n));
        double a = 0.0, terms = 0.0;
        for (index c = 0; c < n; ++c) {
            a += row[c] * x[c];
            terms += std::fabs(row[c]) * std::fabs(x[c]);
        }
        w.a[r] = a;
        w.terms[r] = terms;
        w.size[r] = terms + w.norms[r];
        // row_activity_from_values
        w.v[r] = a - std::min(std::max(a, lo), up);
        const double eps_u = tol * (w.size[r] + (std::isfinite(up) ? std::fabs(up) : 0.0));
        const double eps_l = tol * (w.size[r] + (std::isfinite(lo) ? std::fabs(lo) : 0.0));
        const bool at_u = std::isfinite(up) && std::fabs(a - up) <= eps_u;
        const bool at_l = std::isfinite(lo) && std::fabs(a - lo) <= eps_l;
        const bool violated = a > up + eps_u || a < lo - eps_l;
        index side = 0;
        if (at_u) side = 1;
        if (at_l) side = -1;
        if ((at_u && at_l) || violated || lo == up) side = 2;
        w.side[r] = side;
    }
}

void Certificate::read_once(const Stack& s, const double* x, bool fix_band,
                            bool minimum_norm, CertificateResult& out) {
    const index n = layout_.n, k = layout_.k;
    auto& w = ws_;
    out.allocate(k);     // (the sizes it has: assign writes in place)
    out.minimum_norm = minimum_norm;
    out.band_rows_fixed = 0;
    out.snapped_rows = 0;
    bool finite = true;
    for (index c = 0; c < n; ++c) finite = finite && std::isfinite(x[c]);
    const double xn = robust_norm(x, n);
    if (!finite) {       // every level fails (the Python oracle's NaN residuals)
        for (index i = 0; i <= k; ++i) {
            out.residual[i] = out.projected_gradient[i] = out.scale[i] = NAN;
        }
        out.ok = false;
        out.failing_level = 0;
        return;
    }
    activity(s, x);
    for (index c = 0; c < n * n; ++c) w.Zt[c] = 0.0;
    for (index c = 0; c < n; ++c) w.Zt[c * n + c] = 1.0;
    d_ = n;
    z_identity_ = true;
    n_signed_ = fixed_count_ = band_ = 0;
    for (index r = 0; r < layout_.M; ++r) w.fixed[r] = 0;
    for (index i = 0; i < k; ++i) check_level(s, x, xn, i, fix_band, out);
    out.band_rows_fixed = band_;
    out.ok = true;
    out.failing_level = -1;
    for (index i = 0; i < k; ++i)
        if (!out.level_ok[i]) {
            out.ok = false;
            out.failing_level = i;
            break;
        }
    if (!minimum_norm) return;
    int descents = 0;
    const double scale = std::max(1.0, xn);
    const double res = kkt(x, false, 0, 1.0, k, out, descents);
    out.residual[k] = xn;
    out.projected_gradient[k] = res;
    out.scale[k] = scale;
    out.level_ok[k] = std::isfinite(res) && res <= options_.tol * scale;
    out.fixed_rows[k] = fixed_count_;
    out.active_rows[k] = n_signed_;
    if (out.ok && !out.level_ok[k]) {
        out.ok = false;
        out.failing_level = k;
    }
}

void Certificate::check_level(const Stack& s, const double* x, double x_norm, index level,
                              bool fix_band, CertificateResult& out) {
    const index n = layout_.n;
    const index s0 = layout_.starts[level], s1 = layout_.starts[level + 1], mi = s1 - s0;
    const double tol = options_.tol;
    auto& w = ws_;
    index* side = w.level_side.data();
    const double* v = w.v.data() + s0;
    svd_rows_ = -1;
    const double* sw = s.sw + s0;
    index m_b = 0;
    for (index r = 0; r < mi; ++r) {
        side[r] = w.side[s0 + r];
        if (side[r] == 2 || v[r] != 0.0) w.keep_index[m_b++] = s0 + r;
    }
    for (index c = 0; c < n; ++c) w.g[c] = 0.0;
    double reach_top = 0.0;
    for (index r = 0; r < mi; ++r) {
        const double f = sw[r] * v[r];
        const double* row = w.WA.data() + (s0 + r) * n;
        for (index c = 0; c < n; ++c) w.g[c] += row[c] * f;
        reach_top = std::max(reach_top, sw[r] * w.norms[s0 + r]);
    }
    const double an = robust_norm(w.WA.data() + s0 * n, mi * n);
    // a row's target counts in proportion to its norm against the level's largest
    for (index r = 0; r < mi; ++r) {
        const double reach = sw[r] * w.norms[s0 + r];
        const double share = reach_top > 0 ? reach / reach_top : reach;
        w.rhs[r] = sw[r] * (w.terms[s0 + r] + std::fabs(w.a[s0 + r] - v[r]) * share);
    }
    const double scale = robust_norm(w.rhs.data(), mi) + an;
    int descents = 0;
    double res = kkt(w.g.data(), true, m_b, an, level, out, descents);
    for (index r = 0; r < mi; ++r) w.rhs[r] = sw[r] * v[r];
    const double violation = robust_norm(w.rhs.data(), mi);
    const double rounding = level_rounding(tol, scale, x_norm, an);
    bool ok = level_passes(res, scale, violation, tol, rounding);
    double gap = res * res;
    if (ok && res > 0) {
        // walk the descent directions: a verified drop beyond the tolerance rejects x
        const double limit = tol * std::max(1.0, violation * violation) +
                             8 * rounding * (2 * violation + 2 * rounding);
        if (violation * violation > limit) {
            for (int which = 0; which < descents; ++which) {
                descent(which, w.dir.data());
                const double drop = descent_drop(s, s0, s1, x, x_norm, w.dir.data(), limit);
                if (drop > limit) {
                    ok = false;
                    gap = std::max(gap, drop);
                    break;
                }
            }
        }
    }
    std::int8_t* small = w.small.data();
    bool any_slack = false;
    if (ok) {
        bool alone = true;
        for (index r = 0; r < mi; ++r) {
            const double av = std::fabs(v[r]), sz = w.size[s0 + r];
            const bool nearly = av > kBandFloor * sz && av <= kNearlyFeasible * sz;
            if (av > kBandFloor * sz && !nearly && w.norms[s0 + r] > 0) alone = false;
        }
        double extra2 = 0.0;
        bool reread = false;
        for (index r = 0; r < mi; ++r) {
            const double av = std::fabs(v[r]), sz = w.size[s0 + r];
            const bool nearly = av > kBandFloor * sz && av <= kNearlyFeasible * sz;
            const bool two_sided = w.lower[s0 + r] != w.upper[s0 + r];
            small[r] = nearly && (two_sided || alone);
            if (small[r]) {
                extra2 += (sw[r] * v[r]) * (sw[r] * v[r]);
                reread = reread || (alone && side[r] == 2 && two_sided);
            }
        }
        const double extra = std::sqrt(extra2);
        if ((extra > tol * scale || reread) && feasible(s, s0, s1, small)) {
            if (extra > tol * scale) {
                res = extra;
                ok = false;
            }
            if (alone) {
                any_slack = true;
                for (index r = 0; r < mi; ++r) {
                    small[r] = small[r] && w.lower[s0 + r] != w.upper[s0 + r];
                    if (small[r]) side[r] = v[r] > 0 ? 1 : -1;
                }
            }
        }
    }
    out.residual[level] = violation;
    out.projected_gradient[level] = res;
    out.scale[level] = scale;
    out.level_ok[level] = ok;
    out.fixed_rows[level] = fixed_count_;
    out.active_rows[level] = n_signed_;
    out.value_gap[level] = gap;
    if (violation > tol * scale) {
        // a level left violated beyond the tolerance may hold rows at a small violation
        for (index r = 0; r < mi; ++r) {
            const bool in_band = (side[r] == 1 || side[r] == -1) &&
                                 std::fabs(v[r]) > kBandFloor * w.size[s0 + r] &&
                                 !(any_slack && small[r]);
            if (!in_band) continue;
            ++band_;
            if (fix_band) side[r] = 2;
        }
    }
    add_level(s, s0, s1, level, out);
}

void Certificate::add_level(const Stack& s, index s0, index s1, index level,
                            CertificateResult& out) {
    const index n = layout_.n, mi = s1 - s0;
    auto& w = ws_;
    const index* side = w.level_side.data();
    index m = 0;
    double f2 = 0.0;
    for (index r = 0; r < mi; ++r) {
        w.fixed[s0 + r] = side[r] == 2;
        if (side[r] != 2) continue;
        w.fix_index[m++] = s0 + r;
        const double* row = w.WA.data() + (s0 + r) * n;
        f2 += dot(row, row, n);
    }
    if (m) {
        const double tol_r = options_.rcond * std::sqrt(f2);
        if (d_ && tol_r > 0) {
            // the level's KKT step factored these rows already when they were its
            // active rows (the same matrix: its singular values and vectors serve)
            const bool same = svd_rows_ == m && svd_d_ == d_ &&
                              std::equal(w.fix_index.begin(), w.fix_index.begin() + m,
                                         w.keep_index.begin());
            std::copy(w.fix_index.begin(), w.fix_index.begin() + m, w.keep_index.begin());
            fix_null_space(m, tol_r, level, out, !same);
        }
        fixed_count_ += m;
    }
    svd_rows_ = -1;
    for (index r = 0; r < mi; ++r) {
        const double norm = w.norms[s0 + r];
        if (!((side[r] == 1 || side[r] == -1) && norm > 0)) continue;
        const double* row = s.A + (s0 + r) * n;
        double* dst = w.signed_rows.data() + n_signed_ * n;
        for (index c = 0; c < n; ++c) dst[c] = (static_cast<double>(side[r]) * row[c]) / norm;
        ++n_signed_;
    }
}

void Certificate::fix_null_space(index m, double tol_r, index level, CertificateResult& out,
                                 bool factor) {
    const index n = layout_.n, d = d_;
    auto& w = ws_;
    if (factor) right_svd(m, d);
    if (ambiguous_decision(w.sig.data(), d, tol_r)) out.ambiguous[level] = 1;
    // the directions of σ ≤ tol_r: Vt's rows times Zt, the rows the LQ's reflectors
    // complete (σ = 0) as those reflectors applied to Zt
    const index explicit_rows = reflectors_ > 0 ? reflectors_ : d;
    index kept = 0;
    for (index j = 0; j < explicit_rows; ++j) {
        if (w.sig[j] > tol_r) continue;
        double* dst = w.Znew.data() + kept * n;
        for (index c = 0; c < n; ++c) dst[c] = 0.0;
        const double* vj = w.Vt.data() + j * n;
        for (index t = 0; t < d; ++t) {
            const double f = vj[t];
            const double* z = w.Zt.data() + t * n;
            for (index c = 0; c < n; ++c) dst[c] += f * z[c];
        }
        ++kept;
    }
    if (reflectors_ > 0) {
        cert::reflect_rows(w.house.data(), reflectors_, d, w.Zt.data(), n, n, w.reflect_proj.data());
        std::copy(w.Zt.begin() + reflectors_ * n, w.Zt.begin() + d * n,
                  w.Znew.begin() + kept * n);
        kept += d - reflectors_;
    }
    std::copy(w.Znew.begin(), w.Znew.begin() + kept * n, w.Zt.begin());
    d_ = kept;
    z_identity_ = false;
}

void Certificate::right_svd(index m, index d) {
    // the right singular vectors (Vt's rows) and values (sig, d) of B Z, B the WA rows
    // keep_index[0..m), by one-sided Jacobi rotations preconditioned by Householder
    // reductions (Drmač & Veselić 2008; right_svd_wide, right_svd_tall)
    const index n = layout_.n, M = std::max<index>(layout_.M, 1);
    if (m < d) {
        project_rows(m, d, n, 1);     // P's rows: B Z's rows
        right_svd_wide(m, d);
    } else {
        project_rows(m, d, 1, M);     // P's rows: B Z's columns
        right_svd_tall(m, d);
    }
}

void Certificate::project_rows(index m, index d, index row_stride, index col_stride) {
    // P[i row_stride + j col_stride] = (B Z)_ij, B the WA rows keep_index[0..m)
    const index n = layout_.n;
    auto& w = ws_;
    double* P = w.P.data();
    for (index i = 0; i < m; ++i) {
        const double* row = w.WA.data() + w.keep_index[i] * n;
        double* out = P + i * row_stride;
        if (z_identity_) {        // Z = I (no row fixed yet): B's own entries
            for (index j = 0; j < d; ++j) out[j * col_stride] = row[j];
        } else {
            for (index j = 0; j < d; ++j) out[j * col_stride] = dot(row, w.Zt.data() + j * n, n);
        }
    }
}

void Certificate::right_svd_wide(index m, index d) {
    // P's m rows (stride n, d long) reduced by the row-pivoted LQ Π P = [L 0] Q; Jacobi
    // rotations G orthogonalise the rows of Lᵀ (L = Yᵀ G, Y's rows orthogonal), so Vt's
    // first m rows are [G 0] Q (held in Vt) and its others (σ = 0) the rows m..d−1 of Q,
    // read through the reflectors (v_coords, v_combine, fix_null_space)
    const index n = layout_.n, M = std::max<index>(layout_.M, 1);
    auto& w = ws_;
    double* P = w.P.data();
    cert::lq_rows(P, m, d, n, w.house.data(), w.jnorms.data(), nullptr);
    double* Lt = P + M * n;     // Lᵀ (m × m)
    for (index i = 0; i < m; ++i)
        for (index j = 0; j < m; ++j) Lt[i * m + j] = j >= i ? P[j * n + i] : 0.0;
    for (index i = 0; i < m; ++i)
        for (index c = 0; c < d; ++c) w.Vt[i * n + c] = c == i ? 1.0 : 0.0;
    cert::jacobi_rows(Lt, m, m, m, w.Vt.data(), m, n, w.jnorms.data());
    for (index i = 0; i < m; ++i) {
        w.sig[i] = std::sqrt(dot(Lt + i * m, Lt + i * m, m));
        cert::reflect_row(w.house.data(), m, d, w.Vt.data() + i * n);
    }
    for (index j = m; j < d; ++j) w.sig[j] = 0.0;
    reflectors_ = m;
}

void Certificate::right_svd_tall(index m, index d) {
    // P's d rows (stride M, m long: B Z's columns) reduced by the row-pivoted LQ
    // Π P = [L 0] Q, so B Z = Qᵀ [R; 0] Π with R = Lᵀ (a column-pivoted QR); R's own
    // row LQ R = L₂ Q₂ and rotations G orthogonalising the rows of L₂ᵀ give R's right
    // singular vectors G Q₂, and B Z's are G Q₂ Π
    const index n = layout_.n, M = std::max<index>(layout_.M, 1);
    auto& w = ws_;
    double* P = w.P.data();
    reflectors_ = 0;
    for (index i = 0; i < d; ++i)
        for (index c = 0; c < d; ++c) w.Vt[i * n + c] = c == i ? 1.0 : 0.0;
    if (d < kPreconditionFrom) {    // a few columns: the rotations of P's rows alone
        cert::jacobi_rows(P, d, m, M, w.Vt.data(), d, n, w.jnorms.data());
        for (index j = 0; j < d; ++j) w.sig[j] = std::sqrt(dot(P + j * M, P + j * M, m));
        return;
    }
    index* perm = w.face_perm.data();
    cert::lq_rows(P, d, m, M, w.house.data(), w.jnorms.data(), perm);
    double* R = w.Znew.data();  // R = Lᵀ (d × d, stride n)
    for (index i = 0; i < d; ++i)
        for (index j = 0; j < d; ++j) R[i * n + j] = j >= i ? P[j * M + i] : 0.0;
    cert::lq_rows(R, d, d, n, w.house.data(), w.jnorms.data(), nullptr);
    double* Lt = P + M * n;     // L₂ᵀ (d × d)
    for (index i = 0; i < d; ++i)
        for (index j = 0; j < d; ++j) Lt[i * d + j] = j >= i ? R[j * n + i] : 0.0;
    cert::jacobi_rows(Lt, d, d, d, w.Vt.data(), d, n, w.jnorms.data());
    for (index i = 0; i < d; ++i) {
        w.sig[i] = std::sqrt(dot(Lt + i * d, Lt + i * d, d));
        double* v = w.Vt.data() + i * n;
        cert::reflect_row(w.house.data(), d, d, v);
        std::copy(v, v + d, w.tmp_n.begin());
        for (index k = 0; k < d; ++k) v[perm[k]] = w.tmp_n[k];
    }
}

}  // namespace prioik
