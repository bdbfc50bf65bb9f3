// The certificate's readings (certificate.hpp): the workspace, the check (the extreme-
// scale test, the two readings, the snap), the snap's least-norm step and the
// feasibility check of the slack rows.
#include "prioik/certificate.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "certificate_linalg.hpp"

namespace prioik {

using cert::kEps;
using cert::robust_norm;

namespace {

/// rows inside their interval within this of a bound (relative to the activity rule's
/// size plus |bound|) are the near-active rows the snap moves onto it (_NEAR_ACTIVE)
constexpr double kNearActive = 1e-6;
/// the scales beyond which a level is equilibrated (EQUILIBRATE_BELOW, _ABOVE)
constexpr double kEquilibrateBelow = 1e-100, kEquilibrateAbove = 1e100;
/// HiGHS's primal feasibility tolerance of the Python oracle's LP, on unit rows
constexpr double kFeasibilityTol = 1e-10;

}  // namespace

void CertificateResult::allocate(index k) {
    for (auto* v : {&residual, &projected_gradient, &scale, &value_gap}) v->assign(k + 1, 0.0);
    level_ok.assign(k + 1, 0);
    ambiguous.assign(k + 1, 0);
    fixed_rows.assign(k + 1, 0);
    active_rows.assign(k + 1, 0);
}

void CertificateWorkspace::allocate(index M, index n) {
    const index R = std::max<index>(M, 1), N = std::max<index>(n, 1);
    for (auto* v : {&lower, &upper, &norms, &a, &terms, &size, &v, &mu, &rhs, &h, &ap,
                    &face_s, &nnls_s})
        v->assign(R, 0.0);
    for (auto* v : {&fb, &flo, &fup, &fsw}) v->assign(2 * R, 0.0);
    for (auto* v : {&WA, &signed_rows, &held, &unit, &face, &ucols}) v->assign(R * N, 0.0);
    fA.assign(2 * R * N, 0.0);
    P.assign(R * N + N * N, 0.0);
    lsq.assign(R * N, 0.0);
    for (auto* v : {&Zt, &Vt, &Znew, &lsqV}) v->assign(N * N, 0.0);
    house.assign(N * (std::max(R, N) + 1), 0.0);   // ≤ n reflectors of ≤ max(M, n) + 1
    reflect_proj.assign(2 * N, 0.0);
    qr_work.assign(N + 2 * R, 0.0);
    for (auto* v : {&sig, &g, &zg, &y, &D, &rho, &step, &dir, &tmp_d, &tmp_n, &xp, &near_x,
                    &face_res})
        v->assign(N, 0.0);
    nnls_w.assign(R + N, 0.0);
    jnorms.assign(std::max(R, N), 0.0);
    alphas.assign(32, 0.0);
    along.assign(32, 0.0);
    order.assign(32, 0);
    side.assign(R, 0);
    level_side.assign(R, 0);
    keep_index.assign(R, 0);
    face_index.assign(R, 0);
    fix_index.assign(R, 0);
    face_perm.assign(R, 0);
    for (auto* v : {&fixed, &keep, &passive, &null, &small}) v->assign(std::max(R, N), 0);
}

Certificate::Certificate(ActiveSetLayout layout, CertificateOptions options)
    : layout_(std::move(layout)), options_(options) {
    if (layout_.k < 1 || layout_.n < 1 || static_cast<index>(layout_.starts.size()) != layout_.k + 1 ||
        static_cast<index>(layout_.row_eq.size()) != layout_.M || layout_.starts[layout_.k] != layout_.M)
        throw std::invalid_argument("certificate: the layout's starts and row_eq disagree");
    for (index i = 0; i < layout_.k; ++i)
        if (layout_.starts[0] != 0 || layout_.starts[i] > layout_.starts[i + 1])
            throw std::invalid_argument("certificate: the layout's starts must rise from 0");
    ws_.allocate(layout_.M, layout_.n);
    for (auto* r : {&result_, &retry_, &near_}) r->allocate(layout_.k);
    // the feasibility check's solver: two levels of the M unit rows, the rows kept at
    // their values first, then the others (certificate.hpp)
    ActiveSetLayout two;
    two.M = 2 * layout_.M;
    two.n = layout_.n;
    two.k = 2;
    two.starts = {0, layout_.M, 2 * layout_.M};
    two.row_eq.assign(2 * layout_.M, 0);
    ActiveSetOptions tight;
    tight.primal_tol = 1e-12;
    tight.warm_start = false;
    feasibility_ = std::make_unique<ActiveSetSolver>(std::move(two), tight);
}

Certificate::~Certificate() = default;

CertificateCode Certificate::check(const double* A, const double* b, const double* lower,
                                   const double* upper, const double* sw, const double* x,
                                   bool minimum_norm) {
    const index n = layout_.n, M = layout_.M;
    for (index i = 0; i < layout_.k; ++i) {
        double peak = 0.0;
        for (index j = layout_.starts[i] * n; j < layout_.starts[i + 1] * n; ++j)
            peak = std::max(peak, std::fabs(A[j]));
        if (peak > 0 && !(peak >= kEquilibrateBelow && peak <= kEquilibrateAbove))
            return CertificateCode::extreme_scale;
    }
    for (index r = 0; r < M; ++r)
        for (index c = 0; c < n; ++c) ws_.WA[r * n + c] = sw[r] * A[r * n + c];
    const Stack s{A, b, lower, upper, sw};
    read(s, x, minimum_norm, result_);
    result_.snapped_rows = 0;
    bool finite = true;
    for (index c = 0; c < n; ++c) finite = finite && std::isfinite(x[c]);
    if (result_.ok || !finite) return CertificateCode::checked;
    const index count = snapped(s, x);
    if (count == 0) return CertificateCode::checked;
    read(s, ws_.near_x.data(), minimum_norm, near_);
    if (!near_.ok) return CertificateCode::checked;
    const index levels = layout_.k + (minimum_norm ? 1 : 0);
    for (index i = 0; i < levels; ++i)
        if (!(std::fabs(result_.residual[i] - near_.residual[i]) <= options_.tol * near_.scale[i]))
            return CertificateCode::checked;
    result_ = near_;
    result_.snapped_rows = count;
    return CertificateCode::checked;
}

void Certificate::read(const Stack& s, const double* x, bool minimum_norm,
                       CertificateResult& out) {
    read_once(s, x, false, minimum_norm, out);
    if (!out.ok && out.band_rows_fixed) {
        read_once(s, x, true, minimum_norm, retry_);
        if (retry_.ok) {
            out = retry_;
            return;
        }
    }
    out.band_rows_fixed = 0;
}

index Certificate::snapped(const Stack& s, const double* x) {
    const index n = layout_.n, M = layout_.M;
    const double tol = options_.tol;
    activity(s, x);
    auto& w = ws_;
    index count = 0, m = 0;
    // the snapped rows first (row t of the least squares at lsq's column t), then the
    // rows kept where they are; lsq holds the matrix's columns (n × m, stride M)
    for (int pass = 0; pass < 2; ++pass) {
        for (index r = 0; r < M; ++r) {
            const double lo = w.lower[r], up = w.upper[r], a = w.a[r], v = w.v[r];
            const bool inside = w.side[r] == 0 && v == 0.0;
            const bool near_up = inside && std::isfinite(up) &&
                                 up - a <= kNearActive * (w.size[r] + std::fabs(up));
            const bool near_lo = inside && std::isfinite(lo) &&
                                 a - lo <= kNearActive * (w.size[r] + std::fabs(lo));
            double rhs;
            if (pass == 0) {
                if (!(near_up || near_lo)) continue;
                const double target = near_up && (!near_lo || up - a <= a - lo) ? up : lo;
                rhs = target - a;
                ++count;
            } else {
                const bool met = std::fabs(v) <= tol * (w.size[r] + std::fabs(a - v));
                const index sd = w.side[r];
                if (!(sd == 1 || sd == -1 || (sd == 2 && met))) continue;
                rhs = 0.0;
            }
            for (index c = 0; c < n; ++c) w.lsq[c * M + m] = s.A[r * n + c];
            w.rhs[m++] = rhs;
        }
        if (pass == 0 && count == 0) return 0;
    }
    // the least-norm solution (lstsq's rank rule: σ > eps max(m, n) σ_max)
    for (index c = 0; c < n; ++c)
        for (index j = 0; j < n; ++j) w.lsqV[c * n + j] = c == j ? 1.0 : 0.0;
    cert::jacobi_rows(w.lsq.data(), n, m, M, w.lsqV.data(), n, n, w.jnorms.data());
    double top = 0.0;
    for (index c = 0; c < n; ++c) {
        w.tmp_n[c] = std::sqrt(dot(w.lsq.data() + c * M, w.lsq.data() + c * M, m));
        top = std::max(top, w.tmp_n[c]);
    }
    const double threshold = kEps * static_cast<double>(std::max(m, n)) * top;
    for (index c = 0; c < n; ++c) w.step[c] = 0.0;
    for (index c = 0; c < n; ++c) {
        const double sigma = w.tmp_n[c];
        if (!(sigma > threshold) || !(top > 0)) continue;
        const double coef = dot(w.lsq.data() + c * M, w.rhs.data(), m) / (sigma * sigma);
        for (index j = 0; j < n; ++j) w.step[j] += w.lsqV[c * n + j] * coef;
    }
    const double step = robust_norm(w.step.data(), n);
    if (!(step <= tol * std::max(1.0, robust_norm(x, n)))) return 0;
    for (index c = 0; c < n; ++c) w.near_x[c] = x[c] + w.step[c];
    return count;
}

bool Certificate::feasible(const Stack& s, index s0, index s1, const std::int8_t* small) {
    const index n = layout_.n, M = layout_.M;
    auto& w = ws_;
    constexpr double inf = std::numeric_limits<double>::infinity();
    // row r of the stack is row r of level 0 when kept at its value, else row M + r of
    // level 1; the other copy is a zero row without bounds
    for (index r = 0; r < 2 * M; ++r) {
        w.fsw[r] = 1.0;
        w.fb[r] = 0.0;
        w.flo[r] = -inf;
        w.fup[r] = inf;
        std::fill(w.fA.begin() + r * n, w.fA.begin() + (r + 1) * n, 0.0);
    }
    for (index r = 0; r < s1; ++r) {
        const double a = w.a[r];
        double lo = w.lower[r], up = w.upper[r];
        const bool fix = r < s0 ? w.fixed[r] != 0
                                : (!small[r - s0] && !(a >= lo && a <= up));
        if (fix) lo = up = a;
        const index at = fix ? r : M + r;
        double norm = w.norms[r];
        if (norm == 0.0) norm = 1.0;
        for (index c = 0; c < n; ++c) w.fA[at * n + c] = s.A[r * n + c] / norm;
        w.flo[at] = lo / norm;
        w.fup[at] = up / norm;
    }
    const SolveCode code = feasibility_->solve(w.fA.data(), w.fb.data(), w.flo.data(),
                                               w.fup.data(), w.fsw.data());
    if (code == SolveCode::not_solved) return false;
    const double* y = feasibility_->result().x.data();
    for (index c = 0; c < n; ++c)
        if (!std::isfinite(y[c])) return false;
    for (index r = 0; r < 2 * M; ++r) {
        if (r % M >= s1) continue;
        const double* row = w.fA.data() + r * n;
        double val = 0.0, terms = 0.0;
        for (index c = 0; c < n; ++c) {
            val += row[c] * y[c];
            terms += std::fabs(row[c]) * std::fabs(y[c]);
        }
        const double outside = std::max(std::max(w.flo[r] - val, val - w.fup[r]), 0.0);
        if (!(outside <= kFeasibilityTol + cert::kXPrecision * terms)) return false;
    }
    return true;
}

}  // namespace prioik
