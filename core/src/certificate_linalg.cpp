// The certificate's dense steps (certificate_linalg.hpp).
#include "certificate_linalg.hpp"

#include <algorithm>
#include <cmath>

namespace prioik::cert {

double robust_norm(const double* a, Index n) {
    double sum = 0.0;
    for (Index j = 0; j < n; ++j) sum += a[j] * a[j];
    const double norm = std::sqrt(sum);
    if (norm > 1e-150 && norm < 1e150) return norm;
    double peak = 0.0;
    for (Index j = 0; j < n; ++j) {
        const double m = std::fabs(a[j]);
        if (!(m <= peak)) peak = m;     // (NaN propagates)
    }
    if (peak == 0.0 || !std::isfinite(peak)) return peak;
    sum = 0.0;
    for (Index j = 0; j < n; ++j) sum += (a[j] / peak) * (a[j] / peak);
    return peak * std::sqrt(sum);
}

namespace {

void rotate(double* p, double* q, Index len, double c, double s) {
    for (Index t = 0; t < len; ++t) {
        const double a = p[t], b = q[t];
        p[t] = c * a - s * b;
        q[t] = s * a + c * b;
    }
}

}  // namespace

void jacobi_rows(double* R, Index count, Index len, Index stride, double* acc, Index acc_len,
                 Index acc_stride) {
    constexpr int kSweeps = 60;
    for (int sweep = 0; sweep < kSweeps; ++sweep) {
        bool rotated = false;
        for (Index i = 0; i + 1 < count; ++i) {
            double* p = R + i * stride;
            for (Index j = i + 1; j < count; ++j) {
                double* q = R + j * stride;
                const double alpha = dot(p, p, len), beta = dot(q, q, len);
                const double gamma = dot(p, q, len);
                if (!(std::fabs(gamma) > kEps * std::sqrt(alpha) * std::sqrt(beta))) continue;
                if (alpha == 0.0 || beta == 0.0) continue;
                // the rotation that makes rows i and j orthogonal (Rutishauser's form)
                const double zeta = (beta - alpha) / (2.0 * gamma);
                const double t = (zeta >= 0 ? 1.0 : -1.0) /
                                 (std::fabs(zeta) + std::sqrt(1.0 + zeta * zeta));
                const double c = 1.0 / std::sqrt(1.0 + t * t), s = c * t;
                rotate(p, q, len, c, s);
                if (acc != nullptr) rotate(acc + i * acc_stride, acc + j * acc_stride, acc_len, c, s);
                rotated = true;
            }
        }
        if (!rotated) return;
    }
}

void complete_basis(const double* U, Index r, Index d, Index stride, double* out,
                    double* house) {
    // house row t (d + 1 long): reflector t's vector (entries t..d−1), then its beta
    const Index hs = d + 1;
    for (Index t = 0; t < r; ++t)
        for (Index c = 0; c < d; ++c) house[t * hs + c] = U[t * stride + c];
    for (Index t = 0; t < r; ++t) {
        double* v = house + t * hs;
        for (Index s = 0; s < t; ++s) {      // reflectors 0..t−1 on column t (row t)
            const double* w = house + s * hs;
            double proj = 0.0;
            for (Index c = s; c < d; ++c) proj += w[c] * v[c];
            proj *= w[d];
            for (Index c = s; c < d; ++c) v[c] -= proj * w[c];
        }
        for (Index c = 0; c < t; ++c) v[c] = 0.0;
        double norm = 0.0;
        for (Index c = t; c < d; ++c) norm += v[c] * v[c];
        norm = std::sqrt(norm);
        const double alpha = v[t] >= 0 ? -norm : norm;
        v[t] -= alpha;
        double vv = 0.0;
        for (Index c = t; c < d; ++c) vv += v[c] * v[c];
        v[d] = vv > 0 ? 2.0 / vv : 0.0;
    }
    // Q e_j = H_0 H_1 … H_{r−1} e_j for j = r..d−1
    for (Index j = r; j < d; ++j) {
        double* q = out + j * stride;
        for (Index c = 0; c < d; ++c) q[c] = c == j ? 1.0 : 0.0;
        for (Index s = r - 1; s >= 0; --s) {
            const double* w = house + s * hs;
            double proj = 0.0;
            for (Index c = s; c < d; ++c) proj += w[c] * q[c];
            proj *= w[d];
            for (Index c = s; c < d; ++c) q[c] -= proj * w[c];
        }
    }
}

void face_solve(const double* M, Index mstride, Index d, const Index* cols, Index q,
                const double* y, FaceSpace& f) {
    for (Index t = 0; t < q; ++t) {
        const double* col = M + cols[t] * mstride;
        double* row = f.face + t * f.fstride;
        for (Index c = 0; c < d; ++c) row[c] = col[c];
        double* v = f.V + t * f.vstride;
        for (Index c = 0; c < q; ++c) v[c] = c == t ? 1.0 : 0.0;
    }
    jacobi_rows(f.face, q, d, f.fstride, f.V, q, f.vstride);
    double top = 0.0;
    for (Index t = 0; t < q; ++t) {
        f.tmp[t] = std::sqrt(dot(f.face + t * f.fstride, f.face + t * f.fstride, d));
        top = std::max(top, f.tmp[t]);
    }
    const double threshold = kEps * static_cast<double>(std::max(d, q)) * top;
    for (Index t = 0; t < q; ++t) f.s[cols[t]] = 0.0;
    for (Index c = 0; c < d; ++c) f.res[c] = y[c];
    if (!(top > 0.0)) return;
    for (Index t = 0; t < q; ++t) {
        const double sigma = f.tmp[t];
        if (!(sigma > threshold)) continue;
        const double* u = f.face + t * f.fstride;
        const double coef = dot(u, y, d) / (sigma * sigma);
        const double* v = f.V + t * f.vstride;
        for (Index c = 0; c < q; ++c) f.s[cols[c]] += v[c] * coef;
        for (Index c = 0; c < d; ++c) f.res[c] -= u[c] * coef;
    }
}

double nnls(const double* M, Index mstride, Index d, Index p, const double* y, FaceSpace& f) {
    for (Index j = 0; j < p; ++j) f.mu[j] = 0.0;
    if (p == 0 || d == 0) return robust_norm(y, d);
    const Index cap = 3 * p + 10;
    if (p > 1) {
        for (Index j = 0; j < p; ++j) f.index[j] = j;
        face_solve(M, mstride, d, f.index, p, y, f);
        double lowest = kInf;
        for (Index j = 0; j < p; ++j) lowest = std::min(lowest, f.s[j]);
        if (lowest > 0) {
            for (Index j = 0; j < p; ++j) f.mu[j] = f.s[j];
            return robust_norm(f.res, d);
        }
    }
    double colsum = 0.0;
    for (Index j = 0; j < p; ++j) {
        double s = 0.0;
        for (Index c = 0; c < d; ++c) s += std::fabs(M[j * mstride + c]);
        colsum = std::max(colsum, s);
    }
    const double tol = 10.0 * kEps * static_cast<double>(std::max(d, p)) *
                       std::max(colsum, 1e-300) * std::max(robust_norm(y, d), 1e-300);
    const double* res = f.res;   // a face's residual (face_solve)
    for (Index j = 0; j < p; ++j) f.passive[j] = 0;
    double* r = f.w + p;   // d entries after w (the caller sized w at p + d)
    for (Index c = 0; c < d; ++c) r[c] = y[c];
    for (Index j = 0; j < p; ++j) f.w[j] = dot(M + j * mstride, r, d);
    Index it = 0;
    while (it < cap) {
        Index best = -1;
        double top = -kInf;
        for (Index j = 0; j < p; ++j)
            if (!f.passive[j] && f.w[j] > top) { top = f.w[j]; best = j; }
        if (best < 0 || !(top > tol)) break;
        f.passive[best] = 1;
        while (it < cap) {
            Index q = 0;
            for (Index j = 0; j < p; ++j) if (f.passive[j]) f.index[q++] = j;
            if (q == 0) break;
            ++it;
            for (Index j = 0; j < p; ++j) f.s[j] = 0.0;
            face_solve(M, mstride, d, f.index, q, y, f);
            double lowest = kInf;
            for (Index t = 0; t < q; ++t) lowest = std::min(lowest, f.s[f.index[t]]);
            if (lowest > 0) {
                for (Index j = 0; j < p; ++j) f.mu[j] = f.s[j];
                for (Index c = 0; c < d; ++c) r[c] = res[c];
                break;
            }
            double alpha = kInf;
            for (Index t = 0; t < q; ++t) {
                const Index j = f.index[t];
                if (!(f.s[j] <= 0)) continue;
                const double den = f.mu[j] - f.s[j];
                alpha = std::min(alpha, den > 0 ? f.mu[j] / den : 0.0);
            }
            if (alpha == kInf) alpha = 0.0;     // (a face solution of NaN: no step)
            for (Index j = 0; j < p; ++j) {
                f.mu[j] = f.mu[j] + alpha * (f.s[j] - f.mu[j]);
                if (f.passive[j] && !(f.mu[j] > tol)) f.passive[j] = 0;
                if (!f.passive[j]) f.mu[j] = 0.0;
            }
            for (Index c = 0; c < d; ++c) r[c] = y[c];
            for (Index j = 0; j < p; ++j)
                if (f.mu[j] != 0.0)
                    for (Index c = 0; c < d; ++c) r[c] -= M[j * mstride + c] * f.mu[j];
        }
        for (Index j = 0; j < p; ++j) f.w[j] = dot(M + j * mstride, r, d);
    }
    return robust_norm(r, d);
}

}  // namespace prioik::cert
