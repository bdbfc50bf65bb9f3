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
                 Index acc_stride, double* norms) {
    constexpr int kSweeps = 60;
    for (int sweep = 0; sweep < kSweeps; ++sweep) {
        // the rows' squared norms, measured at each sweep and carried through its
        // rotations (a rotation that zeroes γ moves t γ from one to the other)
        for (Index i = 0; i < count; ++i) norms[i] = dot(R + i * stride, R + i * stride, len);
        bool rotated = false;
        for (Index i = 0; i + 1 < count; ++i) {
            double* p = R + i * stride;
            for (Index j = i + 1; j < count; ++j) {
                const double alpha = norms[i], beta = norms[j];
                if (alpha == 0.0 || beta == 0.0) continue;
                double* q = R + j * stride;
                const double gamma = dot(p, q, len);
                if (!(std::fabs(gamma) > kEps * std::sqrt(alpha) * std::sqrt(beta))) continue;
                // the rotation that makes rows i and j orthogonal (Rutishauser's form)
                const double zeta = (beta - alpha) / (2.0 * gamma);
                const double t = (zeta >= 0 ? 1.0 : -1.0) /
                                 (std::fabs(zeta) + std::sqrt(1.0 + zeta * zeta));
                const double c = 1.0 / std::sqrt(1.0 + t * t), s = c * t;
                rotate(p, q, len, c, s);
                if (acc != nullptr) rotate(acc + i * acc_stride, acc + j * acc_stride, acc_len, c, s);
                norms[i] = alpha - t * gamma;
                norms[j] = beta + t * gamma;
                rotated = true;
            }
        }
        if (!rotated) return;
    }
}

void lq_rows(double* R, Index count, Index len, Index stride, double* house, double* norms,
             Index* perm) {
    const Index hs = len + 1;
    if (perm != nullptr)
        for (Index i = 0; i < count; ++i) perm[i] = i;
    for (Index k = 0; k < count; ++k) {
        Index pivot = k;
        double top = -1.0;
        for (Index i = k; i < count; ++i) {
            const double* row = R + i * stride + k;
            norms[i] = dot(row, row, len - k);
            if (norms[i] > top) { top = norms[i]; pivot = i; }
        }
        if (pivot != k) {
            for (Index c = 0; c < len; ++c) std::swap(R[k * stride + c], R[pivot * stride + c]);
            if (perm != nullptr) std::swap(perm[k], perm[pivot]);
        }
        double* row = R + k * stride;
        double* v = house + k * hs;
        for (Index c = 0; c < k; ++c) v[c] = 0.0;
        for (Index c = k; c < len; ++c) v[c] = row[c];
        const double norm = std::sqrt(top);
        const double alpha = v[k] >= 0 ? -norm : norm;
        v[k] -= alpha;
        const double vv = dot(v + k, v + k, len - k);
        v[len] = vv > 0 ? 2.0 / vv : 0.0;
        row[k] = alpha;
        for (Index c = k + 1; c < count; ++c) row[c] = 0.0;
        for (Index i = k + 1; i < count; ++i) {
            double* ri = R + i * stride + k;
            const double f = v[len] * dot(ri, v + k, len - k);
            for (Index c = 0; c < len - k; ++c) ri[c] -= f * v[k + c];
        }
    }
}

void reflect_row(const double* house, Index count, Index len, double* u) {
    const Index hs = len + 1;
    for (Index k = count - 1; k >= 0; --k) {
        const double* v = house + k * hs;
        const double f = v[len] * dot(u + k, v + k, len - k);
        for (Index c = k; c < len; ++c) u[c] -= f * v[c];
    }
}

void reflect_vector(const double* house, Index count, Index len, double* u) {
    const Index hs = len + 1;
    for (Index k = 0; k < count; ++k) {
        const double* v = house + k * hs;
        const double f = v[len] * dot(u + k, v + k, len - k);
        for (Index c = k; c < len; ++c) u[c] -= f * v[c];
    }
}

void reflect_rows(const double* house, Index count, Index len, double* Z, Index width,
                  Index stride, double* proj) {
    // two reflectors a pass over Z: H₂ H₁ Z = Z − β₁ v₁ p₁ᵀ − β₂ v₂ (p₂ − β₁ (v₂ᵀv₁) p₁)ᵀ
    // with p₁ = Zᵀ v₁, p₂ = Zᵀ v₂
    const Index hs = len + 1;
    double *p1 = proj, *p2 = proj + width;
    Index k = 0;
    for (; k + 1 < count; k += 2) {
        const double *v1 = house + k * hs, *v2 = v1 + hs;
        for (Index c = 0; c < width; ++c) p1[c] = p2[c] = 0.0;
        for (Index t = k; t < len; ++t) {
            const double f1 = v1[t], f2 = v2[t];
            const double* z = Z + t * stride;
            for (Index c = 0; c < width; ++c) {
                p1[c] += f1 * z[c];
                p2[c] += f2 * z[c];
            }
        }
        const double g = v1[len] * dot(v1 + k, v2 + k, len - k);
        for (Index c = 0; c < width; ++c) p2[c] -= g * p1[c];
        for (Index t = k; t < len; ++t) {
            const double f1 = v1[len] * v1[t], f2 = v2[len] * v2[t];
            double* z = Z + t * stride;
            for (Index c = 0; c < width; ++c) z[c] -= f1 * p1[c] + f2 * p2[c];
        }
    }
    for (; k < count; ++k) {
        const double* v = house + k * hs;
        for (Index c = 0; c < width; ++c) p1[c] = 0.0;
        for (Index t = k; t < len; ++t) {
            const double f = v[t];
            const double* z = Z + t * stride;
            for (Index c = 0; c < width; ++c) p1[c] += f * z[c];
        }
        for (Index t = k; t < len; ++t) {
            const double f = v[len] * v[t];
            double* z = Z + t * stride;
            for (Index c = 0; c < width; ++c) z[c] -= f * p1[c];
        }
    }
}

Index pivoted_least_squares(double* F, Index q, Index d, Index fs, const double* y,
                            double rel_tol, double abs_tol, double* s, double* res,
                            double* work, Index* perm) {
    double* z = work;              // d: Qᵀ y
    double* diag = work + d;       // q: R_kk
    double* beta = work + d + q;   // q: the reflectors' 2 / vᵀv
    for (Index j = 0; j < q; ++j) perm[j] = j;
    const Index steps = std::min(q, d);
    Index rank = 0;
    double first = 0.0;
    for (Index k = 0; k < steps; ++k) {
        Index pivot = k;
        double top = -1.0;
        for (Index j = k; j < q; ++j) {
            const double* col = F + j * fs;
            const double norm2 = dot(col + k, col + k, d - k);
            if (norm2 > top) { top = norm2; pivot = j; }
        }
        if (pivot != k) {
            for (Index c = 0; c < d; ++c) std::swap(F[k * fs + c], F[pivot * fs + c]);
            std::swap(perm[k], perm[pivot]);
        }
        const double norm = std::sqrt(top);
        if (k == 0) first = norm;
        if (!(norm > std::max(abs_tol, rel_tol * first))) break;
        double* v = F + k * fs + k;
        const double alpha = v[0] >= 0 ? -norm : norm;
        diag[k] = alpha;
        v[0] -= alpha;
        const double vv = dot(v, v, d - k);
        beta[k] = vv > 0 ? 2.0 / vv : 0.0;
        for (Index j = k + 1; j < q; ++j) {
            double* col = F + j * fs + k;
            const double f = beta[k] * dot(v, col, d - k);
            for (Index c = 0; c < d - k; ++c) col[c] -= f * v[c];
        }
        rank = k + 1;
    }
    for (Index c = 0; c < d; ++c) z[c] = y[c];
    for (Index k = 0; k < rank; ++k) {
        const double* v = F + k * fs + k;
        const double f = beta[k] * dot(v, z + k, d - k);
        for (Index c = 0; c < d - k; ++c) z[k + c] -= f * v[c];
    }
    if (s != nullptr) {
        for (Index j = 0; j < q; ++j) s[j] = 0.0;
        for (Index k = rank - 1; k >= 0; --k) {     // R s = z on the pivot columns
            double acc = z[k];
            for (Index j = k + 1; j < rank; ++j) acc -= F[j * fs + k] * s[perm[j]];
            s[perm[k]] = acc / diag[k];
        }
    }
    for (Index c = 0; c < d; ++c) res[c] = c < rank ? 0.0 : z[c];
    for (Index k = rank - 1; k >= 0; --k) {
        const double* v = F + k * fs + k;
        const double f = beta[k] * dot(v, res + k, d - k);
        for (Index c = 0; c < d - k; ++c) res[k + c] -= f * v[c];
    }
    return rank;
}

void face_solve(const double* M, Index mstride, Index d, const Index* cols, Index q,
                const double* y, FaceSpace& f) {
    for (Index t = 0; t < q; ++t) {
        const double* col = M + cols[t] * mstride;
        std::copy(col, col + d, f.face + t * f.fstride);
    }
    const double rel = kEps * static_cast<double>(std::max(d, q));
    pivoted_least_squares(f.face, q, d, f.fstride, y, rel, 0.0, f.tmp, f.res, f.work, f.perm);
    for (Index t = 0; t < q; ++t) f.s[cols[t]] = f.tmp[t];
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
