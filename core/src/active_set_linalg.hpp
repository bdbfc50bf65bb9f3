// The active set's views over its workspace and the constants of the shared rank rule;
// the Householder steps themselves are householder.hpp's and the nested QR nested_qr.hpp's
// (one implementation for the extended Jacobian and the active set).
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "prioik/householder.hpp"
#include "prioik/nested_qr.hpp"

namespace prioik::dense {

using index = std::int64_t;

constexpr double inf = std::numeric_limits<double>::infinity();

/// hierarchy.linalg's shared rank rule (kAmbiguity, kNearAmbiguity of nested_qr.hpp); x's
/// coordinates are known to X_PRECISION ‖x‖; beyond PRECISION_LIMIT_NORM float64 may
/// limit a level
constexpr double AMBIGUITY = kAmbiguity;
constexpr double NEAR_AMBIGUITY = kNearAmbiguity;
constexpr double X_PRECISION = 16.0 * std::numeric_limits<double>::epsilon();
constexpr double PRECISION_LIMIT_NORM = kPrecisionLimitNorm;

/// A row-major view by its leading dimension (element (i, j) at p[i * ld + j]); ref()
/// gives householder.hpp's MatrixRef of a given extent.
struct Mat {
    double* p = nullptr;
    index ld = 0;
    double* row(index i) const { return p + i * ld; }
    double& operator()(index i, index j) const { return p[i * ld + j]; }
    /// the view from row i, column j on (the same leading dimension)
    Mat at(index i, index j) const { return Mat{p + i * ld + j, ld}; }
    MatrixRef ref(index rows, index cols) const { return MatrixRef{p, rows, cols, ld}; }
};

/// The first nf reflectors of V (rows of n), beta, pos as householder.hpp's Reflectors.
inline Reflectors reflectors(Mat V, index n, double* beta, index* pos, index nf) {
    return Reflectors{V.ref(n, n), beta, pos, nf};
}

/// ‖A_i‖_F² beyond kScaleHigh², or below kScaleLow² with a non-zero entry: the caller
/// equilibrates the level.
inline bool level_extreme(Mat A, index n, double lev_sq, index s0, index s1) {
    constexpr double high = 1e100, low = 1e-100;
    if (!(lev_sq <= high * high)) return true;
    if (lev_sq < low * low)
        for (index i = s0; i < s1; ++i)
            for (index c = 0; c < n; ++c)
                if (A(i, c) != 0.0) return true;
    return false;
}

}  // namespace prioik::dense
