// ActiveSetSolver: the workspace allocated per layout, and the entry points.
#include "prioik/active_set.hpp"

#include <algorithm>
#include <stdexcept>
#include <utility>

#include "active_set_internal.hpp"
#include "prioik/extended_jacobian.hpp"

namespace prioik {

namespace detail {
SolveCode equality_first_data(Ctx& c, ActiveSetWorkspace& ws);
}

namespace {

/// Holds a solver's busy flag for one call (ConcurrentUse when another call holds it).
class Exclusive {
public:
    explicit Exclusive(std::atomic<bool>& busy) : busy_(busy) {
        if (busy_.exchange(true))
            throw ConcurrentUse("a prepared active set was called from a second thread during "
                                "a solve (use one solver per thread)");
    }
    ~Exclusive() { busy_.store(false); }
    Exclusive(const Exclusive&) = delete;
    Exclusive& operator=(const Exclusive&) = delete;

private:
    std::atomic<bool>& busy_;
};

}  // namespace

void ActiveSetWorkspace::allocate(index M, index n, index k) {
    index R = M + n;
    for (auto* v : {&B, &Bo, &T, &flat, &Ts}) v->assign(R * n, 0.0);
    Lw.assign(std::max(R * n, 2 * n + M), 0.0);
    V.assign(n * n, 0.0);
    Vf.assign(n * n, 0.0);
    ts_rows.assign(2 * R, 0.0);
    lsq.assign(small_least_squares_scratch(R, n), 0.0);
    for (auto* v : {&blo, &bup, &rnorm, &rhs, &norms, &tgt, &nu, &tq, &beta, &betaf, &y, &p,
                    &g, &px, &xc, &xs})
        v->assign(R, 0.0);
    for (auto* v : {&rows, &vpos, &nrot, &ucol}) v->assign(R, 0);
    posf.assign(n, 0);
    perm.assign(n, 0);
    iscratch.assign(n, 0);
    for (auto* v : {&state, &saved, &eqr}) v->assign(R, 0);
    held.assign(M, 0);
    eflat.assign(M * n, 0.0);
    evec.assign(M + 4 * k, 0.0);
    efs.assign(4 * R, 0.0);
    equality_qr = NestedQRWorkspace(M, n);
    eint.assign(2 * k + 1 + 5 * M + 4 * n, 0);
    eispare.assign(n, 0);
    warm_state.assign((k + 1) * R, 0);
    warm_valid.assign(k + 1, 0);
}

ActiveSetSolver::ActiveSetSolver(ActiveSetLayout layout, ActiveSetOptions options)
    : layout_(std::move(layout)), options_(options) {
    index M = layout_.M, n = layout_.n, k = layout_.k;
    if (n <= 0 || k <= 0 || M <= 0 || static_cast<index>(layout_.starts.size()) != k + 1 ||
        static_cast<index>(layout_.row_eq.size()) != M || layout_.starts[0] != 0 ||
        layout_.starts[k] != M)
        throw std::invalid_argument("active set layout: starts must be k + 1 offsets from 0 "
                                    "to M > 0, row_eq M flags, n > 0");
    for (index i = 0; i < k; ++i)
        if (layout_.starts[i] > layout_.starts[i + 1])
            throw std::invalid_argument("active set layout: starts must not decrease");
    ws_.allocate(M, n, k);
    result_.x.assign(n, 0.0);
    result_.w2.assign(k, 0.0);
    result_.res.assign(k, 0.0);
    result_.margins.assign(k + 1, 0.0);
    result_.iterations.assign(k + 1, 0);
    result_.flags.assign(k + 1, 0);
    result_.ranks.assign(k + 1, 0);
    result_.over.assign(k + 1, 0);
}

void ActiveSetSolver::reset() {
    std::fill(ws_.warm_valid.begin(), ws_.warm_valid.end(), 0);
    result_.equality_first = 0.0;
    result_.next_try = 0.0;
}

SolveCode ActiveSetSolver::solve(const double* A, const double* b, const double* lower,
                                 const double* upper, const double* sw) {
    Exclusive hold(busy_);
    detail::Ctx c(*this, A, b, lower, upper, sw);
    c.use_warm = options_.warm_start && result_.equality_first != -1.0;
    if (!detail::load_and_scale(c)) return SolveCode::not_solved;
    result_.equality_first = 0.0;
    std::fill(ws_.held.begin(), ws_.held.end(), 0);
    for (index j = 0; j < c.n; ++j) {
        c.y[j] = 0.0;
        c.xc[j] = 0.0;
    }
    detail::solve_levels(c);
    return detail::finish_solve(c);
}

SolveCode ActiveSetSolver::equality_first(const double* A, const double* b, const double* lower,
                                          const double* upper, const double* sw) {
    Exclusive hold(busy_);
    detail::Ctx c(*this, A, b, lower, upper, sw);
    c.use_warm = options_.warm_start;
    return detail::equality_first_data(c, ws_);
}

namespace detail {

Ctx::Ctx(ActiveSetSolver& s, const double* A_, const double* b_, const double* lower_,
         const double* upper_, const double* sw_) {
    const ActiveSetLayout& L = s.layout();
    const ActiveSetOptions& o = s.options();
    ActiveSetWorkspace& w = s.workspace();
    ActiveSetResult& r = s.result();
    M = L.M;
    n = L.n;
    k = L.k;
    R = M + n;
    A = Mat{const_cast<double*>(A_), n};
    b = b_;
    lower = lower_;
    upper = upper_;
    sw = sw_;
    starts = L.starts.data();
    row_eq = L.row_eq.data();
    rcond = o.rcond;
    primal_tol = o.primal_tol;
    dual_tol = o.dual_tol;
    max_iter = o.max_iter;
    B = Mat{w.B.data(), n};
    Bo = Mat{w.Bo.data(), n};
    T = Mat{w.T.data(), n};
    Lw = Mat{w.Lw.data(), n};
    V = Mat{w.V.data(), n};
    Vf = Mat{w.Vf.data(), n};
    Ts = Mat{w.Ts.data(), n};
    flat = w.flat.data();
    lsq = w.lsq.data();
    ts_rows = w.ts_rows.data();
    blo = w.blo.data();
    bup = w.bup.data();
    rnorm = w.rnorm.data();
    rhs = w.rhs.data();
    norms = w.norms.data();
    tgt = w.tgt.data();
    nu = w.nu.data();
    tq = w.tq.data();
    beta = w.beta.data();
    betaf = w.betaf.data();
    y = w.y.data();
    p = w.p.data();
    g = w.g.data();
    px = w.px.data();
    xc = w.xc.data();
    xs = w.xs.data();
    rows = w.rows.data();
    vpos = w.vpos.data();
    posf = w.posf.data();
    nrot = w.nrot.data();
    ucol = w.ucol.data();
    perm = w.perm.data();
    iscratch = w.iscratch.data();
    state = w.state.data();
    saved = w.saved.data();
    eqr = w.eqr.data();
    held = w.held.data();
    warm_state = w.warm_state.data();
    warm_valid = w.warm_valid.data();
    x = r.x.data();
    w2 = r.w2.data();
    res = r.res.data();
    margins = r.margins.data();
    iters = r.iterations.data();
    flags = r.flags.data();
    ranks = r.ranks.data();
    over = r.over.data();
    out = &r;
}

}  // namespace detail
}  // namespace prioik
