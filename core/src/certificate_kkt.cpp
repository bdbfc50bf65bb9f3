// A level's KKT residual in task space and the descent directions it stands for
// (certificate.hpp; hierarchy.analysis._check_lexicographic's kkt), and the walk along a
// descent direction that verifies a drop of the level's value (_descent_drop).
#include <algorithm>
#include <cmath>
#include <limits>

#include "certificate_linalg.hpp"
#include "prioik/certificate.hpp"

namespace prioik {

using cert::robust_norm;

namespace {

constexpr double kSigmaFloor = 1e-6;

/// how many of a descent's best points descent_drop checks (_DESCENT_TRIES)
constexpr int kDescentTries = 4;
constexpr double kInfinity = std::numeric_limits<double>::infinity();

cert::FaceSpace face_space(CertificateWorkspace& w, index n) {
    return cert::FaceSpace{w.face.data(), n, w.face_s.data(), w.face_res.data(),
                           w.nnls_w.data(), w.mu.data(), w.nnls_s.data(), w.qr_work.data(),
                           w.face_index.data(), w.face_perm.data(),
                           reinterpret_cast<signed char*>(w.passive.data())};
}

/// out = −Σ_j coef_j Zt_j (−Z coef) over the d rows of Zt
void minus_z_times(const double* Zt, index d, index n, const double* coef, double* out) {
    for (index c = 0; c < n; ++c) out[c] = 0.0;
    for (index j = 0; j < d; ++j) {
        const double f = coef[j];
        const double* z = Zt + j * n;
        for (index c = 0; c < n; ++c) out[c] -= f * z[c];
    }
}

}  // namespace

double Certificate::kkt(const double* grad, bool with_b, index m, double floor_scale,
                        index level, CertificateResult& out, int& descents) {
    descents = 0;
    const index n = layout_.n, d = d_;
    if (d == 0) return 0.0;
    auto& w = ws_;
    for (index j = 0; j < d; ++j) w.y[j] = w.zg[j] = dot(w.Zt.data() + j * n, grad, n);
    kkt_has_D_ = with_b;
    kkt_any_null_ = false;
    if (with_b) {
        double b2 = 0.0;
        for (index i = 0; i < m; ++i) {
            const double* row = w.WA.data() + w.keep_index[i] * n;
            b2 += dot(row, row, n);
        }
        const double bn = std::sqrt(b2);
        const double floor = kSigmaFloor * (bn != 0.0 ? bn : floor_scale);
        if (floor == 0.0) return 0.0;     // a level of zero rows: nothing x can change
        kkt_floor_ = floor;
        if (m) {
            right_svd(m, d);
            svd_rows_ = m;
            svd_d_ = d;
        } else {
            for (index j = 0; j < d; ++j) {
                for (index c = 0; c < d; ++c) w.Vt[j * n + c] = c == j ? 1.0 : 0.0;
                w.sig[j] = 0.0;
            }
            reflectors_ = 0;
        }
        // the solvers' rank rule: rcond times the whole level's ‖√W A_i‖_F
        const double threshold = options_.rcond * std::max(bn, floor_scale);
        bool ambiguous = false;
        for (index j = 0; j < d; ++j) {
            const double sg = w.sig[j];
            ambiguous = ambiguous || (sg > threshold / kAmbiguity && sg <= threshold * kAmbiguity);
            w.null[j] = sg <= threshold;
            kkt_any_null_ = kkt_any_null_ || w.null[j];
            w.D[j] = 1.0 / std::max(sg, floor);
            if (bn > 0 && w.null[j]) w.D[j] = 1.0 / bn;
        }
        if (ambiguous && threshold > 0) out.ambiguous[level] = 1;
        v_coords(w.zg.data(), w.tmp_d.data());
        for (index j = 0; j < d; ++j) w.y[j] = w.null[j] ? 0.0 : w.D[j] * w.tmp_d[j];
    }
    kkt_keep_ = 0;
    if (n_signed_ == 0) {
        descents = 1;
        return robust_norm(w.y.data(), d);
    }
    // the rows held at one bound: Zᵀ c_s, kept when they keep a direction in Z, read
    // through D Vᵀ and made unit columns (the same cone, a well-scaled NNLS)
    index p = 0;
    for (index s = 0; s < n_signed_; ++s) {
        double* hs = w.held.data() + s * n;
        const double* row = w.signed_rows.data() + s * n;
        for (index j = 0; j < d; ++j) hs[j] = dot(w.Zt.data() + j * n, row, n);
        bool keep = std::sqrt(dot(hs, hs, d)) > options_.rcond;
        double* u = w.unit.data() + p * n;
        if (with_b) {
            v_coords(hs, u);
            for (index j = 0; j < d; ++j) u[j] *= w.D[j];
        } else {
            for (index j = 0; j < d; ++j) u[j] = hs[j];
        }
        const double norm = std::sqrt(dot(u, u, d));
        keep = keep && norm > 0;
        w.keep[s] = keep;
        if (!keep) continue;
        for (index j = 0; j < d; ++j) u[j] /= norm;
        ++p;
    }
    kkt_keep_ = p;
    for (index j = 0; j < d; ++j) w.rho[j] = -w.y[j];
    cert::FaceSpace f = face_space(w, n);
    const double res = cert::nnls(w.unit.data(), n, d, p, w.rho.data(), f);
    descents = with_b && kkt_any_null_ ? 3 : 2;
    return res;
}

void Certificate::descent(int which, double* direction) {
    const index n = layout_.n, d = d_;
    auto& w = ws_;
    if (which == 0) {
        // the steepest in the residual's metric, −Z V D ρ at the NNLS optimum
        for (index j = 0; j < d; ++j) w.rho[j] = w.y[j];
        if (n_signed_)
            for (index t = 0; t < kkt_keep_; ++t) {
                const double* u = w.unit.data() + t * n;
                for (index j = 0; j < d; ++j) w.rho[j] += u[j] * w.mu[t];
            }
        if (!kkt_has_D_) return minus_z_times(w.Zt.data(), d, n, w.rho.data(), direction);
        for (index j = 0; j < d; ++j) w.step[j] = w.D[j] * w.rho[j];
    } else if (which == 1) {
        // the gradient projected off the held rows' span (range basis at 1e-15)
        index q = 0;
        for (index s = 0; s < n_signed_; ++s) {
            if (!w.keep[s]) continue;
            std::copy(w.held.begin() + s * n, w.held.begin() + s * n + d,
                      w.face.begin() + q * n);
            ++q;
        }
        double frob2 = 0.0;
        for (index t = 0; t < q; ++t) frob2 += dot(w.face.data() + t * n, w.face.data() + t * n, d);
        const double frob = std::sqrt(frob2);
        // zg off the span of the columns whose pivots exceed 1e-15 ‖face‖_F
        cert::pivoted_least_squares(w.face.data(), q, d, n, w.zg.data(), 0.0, 1e-15 * frob,
                                    nullptr, w.rho.data(), w.qr_work.data(),
                                    w.face_perm.data());
        return minus_z_times(w.Zt.data(), d, n, w.rho.data(), direction);
    } else {
        // the null coordinates weighted as the floored ones: the multipliers cancel the
        // gradient there alone
        v_coords(w.zg.data(), w.tmp_d.data());
        for (index j = 0; j < d; ++j) {
            w.tmp_n[j] = w.null[j] ? 1.0 / kkt_floor_ : w.D[j];
            w.tmp_d[j] = w.null[j] ? 0.0 : w.tmp_n[j] * w.tmp_d[j];
        }
        index q = 0;
        for (index s = 0; s < n_signed_; ++s) {
            if (!w.keep[s]) continue;
            const double* hs = w.held.data() + s * n;
            double* c = w.ucols.data() + q * n;
            v_coords(hs, c);
            for (index j = 0; j < d; ++j) c[j] *= w.tmp_n[j];
            const double len = std::sqrt(dot(c, c, d));
            if (!(len > 0)) continue;
            for (index j = 0; j < d; ++j) c[j] /= len;
            ++q;
        }
        for (index j = 0; j < d; ++j) w.rho[j] = -w.tmp_d[j];
        cert::FaceSpace f = face_space(w, n);
        cert::nnls(w.ucols.data(), n, d, q, w.rho.data(), f);
        for (index j = 0; j < d; ++j) w.rho[j] = w.tmp_d[j];
        for (index t = 0; t < q; ++t) {
            const double* c = w.ucols.data() + t * n;
            for (index j = 0; j < d; ++j) w.rho[j] += c[j] * w.mu[t];
        }
        for (index j = 0; j < d; ++j) w.step[j] = w.tmp_n[j] * w.rho[j];
    }
    // −Z V step
    v_combine(w.step.data(), w.tmp_d.data());
    minus_z_times(w.Zt.data(), d, n, w.tmp_d.data(), direction);
}

void Certificate::v_coords(const double* in, double* out) const {
    const index n = layout_.n, d = d_, r = reflectors_;
    const auto& w = ws_;
    if (r > 0) {    // rows r..d−1 of Vt are those of Q: (Q in)'s entries
        std::copy(in, in + d, out);
        cert::reflect_vector(w.house.data(), r, d, out);
    }
    for (index j = 0; j < (r > 0 ? r : d); ++j) out[j] = dot(w.Vt.data() + j * n, in, d);
}

void Certificate::v_combine(const double* coef, double* out) const {
    const index n = layout_.n, d = d_, r = reflectors_;
    const auto& w = ws_;
    for (index c = 0; c < d; ++c) out[c] = c >= r ? coef[c] : 0.0;
    if (r > 0) cert::reflect_row(w.house.data(), r, d, out);    // Qᵀ [0; coef_r..d−1]
    for (index j = 0; j < (r > 0 ? r : d); ++j) {
        const double* vj = w.Vt.data() + j * n;
        for (index c = 0; c < d; ++c) out[c] += coef[j] * vj[c];
    }
}

double Certificate::descent_drop(const Stack& s, index s0, index s1, const double* x,
                                 double x_norm, const double* dir, double limit) {
    const index n = layout_.n;
    auto& w = ws_;
    for (index r = 0; r < s1; ++r) w.h[r] = dot(s.A + r * n, dir, n);
    double slope = 0.0;
    for (index r = s0; r < s1; ++r) slope += s.sw[r] * s.sw[r] * w.v[r] * w.h[r];
    if (!(slope < 0)) return 0.0;
    const double d_norm = std::sqrt(dot(dir, dir, n));
    double cap = d_norm > 0 ? std::max(1.0, x_norm) / d_norm : kInfinity;
    auto at_u = [&](index r) { return w.fixed[r] || w.side[r] == 1; };
    auto at_l = [&](index r) { return w.fixed[r] || w.side[r] == -1; };
    auto rounding = [&](index r) { return cert::kXPrecision * (w.size[r] + std::fabs(w.a[r])); };
    for (index r = 0; r < s0; ++r) {
        const double room_u = at_u(r) ? rounding(r) : std::max(w.upper[r] - w.a[r], 0.0);
        const double room_l = at_l(r) ? rounding(r) : std::max(w.a[r] - w.lower[r], 0.0);
        const double hh = w.h[r];
        const double ratio = hh > 0 ? room_u / hh : hh < 0 ? room_l / -hh : kInfinity;
        if (ratio < cap) cap = ratio;
    }
    if (!(cap > 0 && -2.0 * slope * cap > limit)) return 0.0;
    auto value_at = [&](auto row_value) {
        double total = 0.0;
        for (index r = s0; r < s1; ++r) {
            const double val = row_value(r);
            const double viol = s.sw[r] * (val - std::min(std::max(val, w.lower[r]), w.upper[r]));
            total += viol * viol;
        }
        return total;
    };
    double curve = 0.0;
    for (index r = s0; r < s1; ++r)
        if (w.v[r] != 0.0) curve += (s.sw[r] * w.h[r]) * (s.sw[r] * w.h[r]);
    const double top = curve > 0 ? std::min(cap, -slope / curve) : cap;
    index count = 0;
    if (cap > top) w.alphas[count++] = cap;
    double half = 1.0;
    for (int t = 0; t < 24; ++t, half *= 0.5) w.alphas[count++] = top * half;
    bool any_finite = false;
    for (index j = 0; j < count; ++j) {
        const double alpha = w.alphas[j];
        w.along[j] = value_at([&](index r) { return w.a[r] + w.h[r] * alpha; });
        any_finite = any_finite || std::isfinite(w.along[j]);
        w.order[j] = j;
    }
    if (!any_finite) return 0.0;
    double best = 0.0;      // the level's value at x
    for (index r = s0; r < s1; ++r) best += (s.sw[r] * w.v[r]) * (s.sw[r] * w.v[r]);
    auto key = [&](index j) { return std::isfinite(w.along[j]) ? w.along[j] : kInfinity; };
    for (index t = 1; t < count; ++t) {          // a stable insertion sort (≤ 25 points)
        const index j = w.order[t];
        index u = t;
        for (; u > 0 && key(j) < key(w.order[u - 1]); --u) w.order[u] = w.order[u - 1];
        w.order[u] = j;
    }
    for (index t = 0; t < std::min<index>(kDescentTries, count); ++t) {
        const index j = w.order[t];
        if (!(w.along[j] < best)) break;
        for (index c = 0; c < n; ++c) w.xp[c] = x[c] + w.alphas[j] * dir[c];
        for (index r = 0; r < s1; ++r) w.ap[r] = dot(s.A + r * n, w.xp.data(), n);
        bool holds = true;
        for (index r = 0; r < s0 && holds; ++r) {
            const double ap = w.ap[r], a = w.a[r];
            if (w.fixed[r]) {
                holds = std::fabs(ap - a) <= rounding(r);
            } else {
                const double top_h = std::max(w.upper[r], a) + (at_u(r) ? rounding(r) : 0.0);
                const double bottom_h = std::min(w.lower[r], a) - (at_l(r) ? rounding(r) : 0.0);
                holds = ap <= top_h && ap >= bottom_h;
            }
        }
        if (!holds) continue;
        return std::max(best - value_at([&](index r) { return w.ap[r]; }), 0.0);
    }
    return 0.0;
}

}  // namespace prioik
